"""The contract in code: names, frames, rotor geometry, config validation (DESIGN.md)."""
