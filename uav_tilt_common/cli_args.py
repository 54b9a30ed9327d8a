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


def default_text(default: object) -> str:
    """How an option's default reads in its help: a list as its values, space-separated."""
    if isinstance(default, (list, tuple)):
        return ' '.join(str(v) for v in default)
    return str(default)


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Help of the `uav-tilt` commands: each option's help ends with its default, where it
    has one (not the absent ones: None, a flag's False) and the help does not say it itself
    (``%(default)s``); a description is printed as written."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ''
        default = action.default
        if (default is None or default is False or default is argparse.SUPPRESS
                or action.nargs == 0 or '%(default)' in text):
            return action.help
        return f"{text} (default: {default_text(default).replace('%', '%%')})"


def add_command(sub: 'argparse._SubParsersAction[argparse.ArgumentParser]', name: str,
                help: str, description: str | None = None) -> argparse.ArgumentParser:
    """A sub-command's parser with :class:`HelpFormatter`: its ``help`` (one line in the
    parent's list) is its description too unless one is given."""
    return sub.add_parser(name, help=help, description=description or help,
                          formatter_class=HelpFormatter)
