"""The first-order low-pass every filter of the controller uses."""
import math


def lowpass_weight(dt_s: float, tau_s: float) -> float:
    """Share of the new sample in a first-order low-pass of time constant ``tau_s`` after
    ``dt_s`` (exact for a sample held over the step): ``y += w * (x - y)``; 1 (no filtering)
    for ``tau_s <= 0``."""
    return 1.0 if tau_s <= 0.0 else 1.0 - math.exp(-dt_s / tau_s)


def cutoff_tau_s(cutoff_hz: float) -> float:
    """The time constant of a first-order low-pass with a -3 dB cutoff of ``cutoff_hz``."""
    return 1.0 / (2.0 * math.pi * cutoff_hz)
