"""Actuator command validation: reject garbage, clamp small excursions, accept any order."""
import math

from uav_tilt_common.names import ACTUATOR_NAMES
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_sim.command_check import check_command

VEHICLE = VehicleParams()


def command(thrusts=(4.0, 4.0, 4.0, 4.0), tilts=(0.1, 0.2), names=ACTUATOR_NAMES):
    efforts = list(thrusts) + [0.0, 0.0]
    positions = [0.0] * 4 + list(tilts)
    return list(names), efforts, positions


def test_valid_command_in_any_name_order():
    names, efforts, positions = command(thrusts=(1.0, 2.0, 3.0, 4.0))
    order = [5, 3, 1, 0, 2, 4]
    result = check_command([names[i] for i in order], [efforts[i] for i in order],
                           [positions[i] for i in order], VEHICLE)
    assert result.kind == '' and not result.clamped
    assert list(result.command.thrusts_n) == [1.0, 2.0, 3.0, 4.0]
    assert (result.command.alpha_rad, result.command.beta_rad) == (0.1, 0.2)


def test_garbage_is_rejected_by_kind():
    cases = {
        'non_finite': command(thrusts=(math.nan, 1.0, 1.0, 1.0)),
        'names': command(names=['a', 'b', 'c', 'd', 'e', 'f']),
        'range': command(thrusts=(1e9, 1.0, 1.0, 1.0)),
    }
    for kind, args in cases.items():
        result = check_command(*args, VEHICLE)
        assert result.command is None and result.kind == kind
    names, efforts, positions = command()
    assert check_command(names, efforts[:5], positions, VEHICLE).kind == 'length'
    tilted = command(tilts=(0.0, 3.0))
    assert check_command(*tilted, VEHICLE).kind == 'range'


def test_small_excursions_are_clamped_to_the_physical_range():
    result = check_command(*command(thrusts=(-0.5, VEHICLE.f_max_n + 1.0, 1.0, 1.0),
                                    tilts=(VEHICLE.tilt_limit_rad + 0.1, 0.0)), VEHICLE)
    assert result.clamped
    assert result.command.thrusts_n[0] == 0.0
    assert result.command.thrusts_n[1] == VEHICLE.f_max_n
    assert result.command.alpha_rad == VEHICLE.tilt_limit_rad
