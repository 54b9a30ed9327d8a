"""The campaign JSON (DESIGN section 7): n, successes, the success rate with its 95% Wilson
interval, the failures by reason (and of structure worlds, both by structure kind) and one
entry per run, the same from either backend."""
import collections
import math
from typing import Any


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95% Wilson score interval (low, high) of a success rate."""
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    centre = p + z * z / (2 * n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    # all or none: the bound on that side is exactly 1 or 0 (rounding would put the rate
    # itself outside its interval)
    low = 0.0 if successes == 0 else (centre - half) / (1 + z * z / n)
    high = 1.0 if successes == n else (centre + half) / (1 + z * z / n)
    return low, high


def summarize(n: int, seed: int, target_source: str, runs: list[dict[str, Any]],
              corners: bool = False, structures: bool = False) -> dict[str, Any]:
    """The campaign JSON of its ``runs`` (by index): a success is a run that met the
    inspection bar (no ``failure``)."""
    successes = sum(r['failure'] is None for r in runs)
    low, high = wilson_interval(successes, n)
    out = dict(n=n, seed=seed, target_source=target_source, corners=corners,
               successes=successes,
               success_rate=successes / n if n else 0.0, success_rate_ci95=[low, high],
               failures=_failures(runs), runs=runs)
    if structures:
        by_structure = {}
        for kind in sorted({r['structure'] for r in runs}):
            of_kind = [r for r in runs if r['structure'] == kind]
            by_structure[kind] = dict(n=len(of_kind),
                                      successes=sum(r['failure'] is None for r in of_kind),
                                      failures=_failures(of_kind))
        out.update(structures=True, by_structure=by_structure)
    return out


def _failures(runs: list[dict[str, Any]]) -> dict[str, int]:
    """'<reason> in <mode>' -> how many of ``runs`` failed so."""
    return dict(collections.Counter(f"{r['failure']['reason']} in {r['failure']['mode']}"
                                    for r in runs if r['failure'] is not None))
