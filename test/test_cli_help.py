"""Help that teaches: every option of every `uav-tilt` command, and of scripts/launch.sh, has
help text, and an option's help says its default."""
import argparse
import os
import re
import subprocess

import pytest

from ros_graph import REPO
from uav_tilt_tools.cli import build_parser


def parsers(parser, path=('uav-tilt',)):
    """(command path, parser) of ``parser`` and every sub-parser under it, recursively; a
    command that parses its own arguments (``full_parser``) with the parser it uses."""
    yield path, parser
    full = parser.get_default('full_parser')
    if full is not None:
        yield from parsers(full(), path)
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from parsers(sub, path + (name,))


ALL = list(parsers(build_parser()))


def options():
    """pytest params (parser, action) of every option and positional but -h."""
    return [pytest.param(parser, action, id=' '.join(path) + ' '
                         + (action.option_strings[-1] if action.option_strings else action.dest))
            for path, parser in ALL for action in parser._actions
            if not isinstance(action, (argparse._HelpAction, argparse._SubParsersAction))]


def default_words(default):
    """What the help must show of a default: the value, or each value of a list."""
    if isinstance(default, (list, tuple)):
        return [str(v) for v in default]
    return [str(default)]


def test_every_command_is_walked():
    commands = {' '.join(path) for path, _ in ALL}
    for command in ('uav-tilt fly', 'uav-tilt campaign', 'uav-tilt report', 'uav-tilt bench',
                    'uav-tilt topic list', 'uav-tilt topic echo', 'uav-tilt topic hz',
                    'uav-tilt vision train', 'uav-tilt vision dataset'):
        assert command in commands, commands


@pytest.mark.parametrize('parser, action', options())
def test_every_option_has_help_that_says_its_default(parser, action):
    assert action.help and action.help is not argparse.SUPPRESS and action.help.strip()
    text = parser._get_formatter()._expand_help(action)
    # a flag's default is its absence; None is no default
    if action.nargs != 0 and action.default not in (None, argparse.SUPPRESS):
        for word in default_words(action.default):
            assert word in text, (text, action.default)


@pytest.mark.parametrize('path, parser', ALL, ids=[' '.join(p) for p, _ in ALL])
def test_every_command_lists_its_sub_commands_with_help(path, parser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for choice in action._choices_actions:
                assert choice.help and choice.help.strip(), (path, choice.dest)
    parser.format_help()        # a help text that does not format would fail --help


def test_the_defaults_named_in_the_first_hour_show():
    """campaign --n and --seed, fly --target-source: their defaults in --help."""
    helps = {' '.join(path): parser.format_help() for path, parser in ALL}
    assert re.search(r'--n N\s+runs.*\(default: 20\)', helps['uav-tilt campaign'], re.S)
    assert re.search(r'--seed SEED\s+campaign seed.*\(default: 0\)',
                     helps['uav-tilt campaign'], re.S)
    assert '(default: vision)' in helps['uav-tilt fly']
    assert 'first message' in helps['uav-tilt topic echo']
    assert 'discovery at most' in helps['uav-tilt topic list']


def launch_options():
    """The options scripts/launch.sh takes: the patterns of its argument loop."""
    with open(os.path.join(REPO, 'scripts', 'launch.sh'), encoding='utf-8') as stream:
        loop = stream.read().split('while (($#)); do', 1)[1].split('done', 1)[0]
    return sorted({option for pattern in re.findall(r'^\s+(-[-\w |]+)\)', loop, re.M)
                   for option in re.split(r'\s*\|\s*', pattern.strip())})


def test_launch_help_names_every_option_on_a_line_of_its_own():
    result = subprocess.run([os.path.join(REPO, 'scripts', 'launch.sh'), '--help'],
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith('usage: scripts/launch.sh')
    options = launch_options()
    assert {'--scenario', '--param', '--mission', '--help'} <= set(options), options
    for option in options:
        # "  --scenario FILE   what it does", or "  -h, --help   ...": one line each
        described = [line for line in lines
                     if re.match(rf' +(-\w, )?{re.escape(option)}(, --\S+)?( \S+)? {{2,}}\S',
                                 line)]
        assert described, (option, result.stdout)
    options_part = result.stdout.split('\noptions:\n', 1)[1]
    assert all(re.match(r'  -', line) for line in options_part.splitlines()), options_part
