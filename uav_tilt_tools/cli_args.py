"""Value types of the `uav-tilt` options: a bad value is argparse's error line (exit 2)."""
import argparse
import math

from uav_tilt_common.config import ConfigError, check_value
from uav_tilt_sim.scenario import Scenario


def _number(kind, text):
    try:
        return kind(text)
    except ValueError:
        what = 'an integer' if kind is int else 'a number'
        raise argparse.ArgumentTypeError(f'{text!r} is not {what}') from None


def count(text):
    """An integer of at least 1 (runs, workers)."""
    value = _number(int, text)
    if value < 1:
        raise argparse.ArgumentTypeError(f'{value} must be at least 1')
    return value


def seed(text):
    """A random generator's seed: an integer of at least 0."""
    value = _number(int, text)
    if value < 0:
        raise argparse.ArgumentTypeError(f'{value} must be at least 0')
    return value


def scenario_seed(text):
    """A seed in the range of a scenario's ``seed``."""
    try:
        return check_value(Scenario, 'seed', _number(int, text))
    except ConfigError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def duration_s(text):
    """A finite, positive time [s]."""
    value = _number(float, text)
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f'{text!r} must be a finite number of seconds above 0')
    return value
