"""Validation of actuator commands arriving from outside (DESIGN section 3, actuators/cmd)."""
from typing import Iterable, NamedTuple, Sequence

import numpy as np

from uav_tilt_common.names import ACTUATOR_NAMES
from uav_tilt_common.state import ActuatorCommand
from uav_tilt_common.vehicle import VehicleParams


class CheckResult(NamedTuple):
    """The command (None when rejected), the kind of problem ('' when none), its detail
    and whether a value was clamped into range."""

    command: ActuatorCommand | None
    kind: str
    detail: str
    clamped: bool


# Beyond this multiple of the physical range a value is garbage, not a saturated command.
REJECT_FACTOR = 1.5


def check_command(names: Iterable[str], efforts: Sequence[float], positions: Sequence[float],
                  vehicle: VehicleParams) -> CheckResult:
    """Map a JointState-like command to an ActuatorCommand.

    Returns CheckResult(command or None, kind of problem or '', detail, clamped): rejected
    when names are not exactly the six actuators, lengths differ, any used value is NaN/Inf,
    or far out of range; values slightly out of range are clamped to it.
    """
    names = list(names)
    if sorted(names) != sorted(ACTUATOR_NAMES):
        return CheckResult(None, 'names', f'wrong joint names {names}', False)
    if len(efforts) != len(names) or len(positions) != len(names):
        return CheckResult(None, 'length', f'{len(names)} names but {len(efforts)} efforts '
                           f'and {len(positions)} positions', False)
    index = {name: i for i, name in enumerate(names)}
    thrusts = np.array([efforts[index[n]] for n in ACTUATOR_NAMES[:4]], dtype=float)
    tilts = np.array([positions[index[n]] for n in ACTUATOR_NAMES[4:]], dtype=float)
    if not (np.all(np.isfinite(thrusts)) and np.all(np.isfinite(tilts))):
        return CheckResult(None, 'non_finite', 'NaN or Inf in the command', False)
    f_max, tilt_max = vehicle.f_max_n, vehicle.tilt_limit_rad
    if np.any(thrusts < -REJECT_FACTOR * f_max) or np.any(thrusts > REJECT_FACTOR * f_max):
        return CheckResult(None, 'range', f'thrust out of range: {thrusts.tolist()}', False)
    if np.any(np.abs(tilts) > REJECT_FACTOR * tilt_max):
        return CheckResult(None, 'range', f'tilt out of range: {tilts.tolist()}', False)
    clamped_thrusts = np.clip(thrusts, 0.0, f_max)
    clamped_tilts = np.clip(tilts, -tilt_max, tilt_max)
    clamped = bool(np.any(clamped_thrusts != thrusts) or np.any(clamped_tilts != tilts))
    command = ActuatorCommand(clamped_thrusts, float(clamped_tilts[0]), float(clamped_tilts[1]))
    return CheckResult(command, '', '', clamped)
