"""Value types of the `uav-tilt` options: a bad value is argparse's error line (exit 2)."""
import argparse
import math

# The exit code of a command stopped by Ctrl-C (128 + SIGINT, as a shell reports it).
INTERRUPTED = 130


def number(kind, text):
    """``kind(text)`` (int or float); argparse's error when it is none."""
    try:
        return kind(text)
    except ValueError:
        what = 'an integer' if kind is int else 'a number'
        raise argparse.ArgumentTypeError(f'{text!r} is not {what}') from None


def path(text):
    """A file or folder name: not empty (an empty one would fall back to a default)."""
    if not text.strip():
        raise argparse.ArgumentTypeError('an empty path')
    return text


def count(text):
    """An integer of at least 1 (runs, workers)."""
    value = number(int, text)
    if value < 1:
        raise argparse.ArgumentTypeError(f'{value} must be at least 1')
    return value


def seed(text):
    """A random generator's seed: an integer of at least 0."""
    value = number(int, text)
    if value < 0:
        raise argparse.ArgumentTypeError(f'{value} must be at least 0')
    return value


def duration_s(text):
    """A finite, positive time [s]."""
    value = number(float, text)
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f'{text!r} must be a finite number of seconds above 0')
    return value


def non_negative(text):
    """An integer of at least 0 (worker processes, threads: 0 for none or the default)."""
    return seed(text)


def _finite(text):
    value = number(float, text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'{text!r} is not a finite number')
    return value


def positive(text):
    """A finite number above 0 (a learning rate, a width multiplier, a distance)."""
    value = _finite(text)
    if value <= 0.0:
        raise argparse.ArgumentTypeError(f'{text!r} must be above 0')
    return value


def fraction(text):
    """A number from 0 to 1 (a jitter gain, a weight)."""
    value = _finite(text)
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f'{text!r} must be from 0 to 1')
    return value


def non_negative_number(text):
    """A finite number of at least 0 (a loss weight)."""
    value = _finite(text)
    if value < 0.0:
        raise argparse.ArgumentTypeError(f'{text!r} must be at least 0')
    return value


def ratio_up_to(high):
    """The type of a ratio r with 0 < r <= ``high``."""
    def ratio(text):
        value = _finite(text)
        if not 0.0 < value <= high:
            raise argparse.ArgumentTypeError(f'{text!r} must be above 0 and at most {high}')
        return value
    return ratio
