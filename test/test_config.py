"""Validated configuration: one clear line naming the parameter, its value and the range."""
import dataclasses

import pytest

from uav_tilt_common.config import (ConfigError, from_dict, load_yaml, nested, param,
                                    read_yaml, to_flat)


@dataclasses.dataclass
class Inner:
    gain: float = param(1.0, lo=0.0, hi=10.0)
    xyz: list = param([0.0, 0.0, 0.0], lo=-1.0, hi=1.0, length=3)


@dataclasses.dataclass
class Outer:
    mode: str = param('lockstep', choices=('lockstep', 'realtime'))
    count: int = param(3, lo=1, hi=5)
    flag: bool = param(False)
    inner: Inner = nested(Inner)


def test_defaults_and_nested_dotted_keys():
    cfg = from_dict(Outer, {'inner.gain': 2, 'count': 4.0})
    assert cfg.inner.gain == 2.0 and isinstance(cfg.inner.gain, float)
    assert cfg.count == 4 and isinstance(cfg.count, int)
    assert to_flat(cfg)['inner.xyz'] == [0.0, 0.0, 0.0]


@pytest.mark.parametrize('data, words', [
    ({'inner': {'gain': 11.0}}, ["'inner.gain'", '11.0', '[0.0, 10.0]']),
    ({'mode': 'fast'}, ["'mode'", "'fast'", "'lockstep'"]),
    ({'count': 2.5}, ["'count'", 'integer']),
    ({'flag': 'yes'}, ["'flag'"]),
    ({'inner.xyz': [0.0, 0.0]}, ["'inner.xyz'", '3 elements']),
    ({'inner.gain': float('nan')}, ["'inner.gain'", 'finite']),
    ({'bogus': 1}, ["unknown parameter 'bogus'"]),
    # an integer's finiteness is checked before it is made an int (no OverflowError)
    ({'count': float('inf')}, ["'count'", 'finite']),
    ({'count': float('nan')}, ["'count'", 'finite']),
    # YAML reads an integer of any size; one beyond a float's range is no OverflowError
    ({'inner.gain': 10 ** 400}, ["'inner.gain'", '401 digits', 'too large']),
    ({'count': -10 ** 400}, ["'count'", 'too large']),
    ({'inner.xyz': [0.0, 10 ** 309, 0.0]}, ["'inner.xyz'", 'too large']),
    # a group is a mapping: 0, [] or '' do not stand for its defaults
    ({'inner': 0}, ["'inner'", 'mapping']),
    ({'inner': []}, ["'inner'", 'mapping']),
    ({'inner': ''}, ["'inner'", 'mapping']),
    ({'inner': False}, ["'inner'", 'mapping']),
])
def test_bad_values_raise_one_clear_line(data, words):
    with pytest.raises(ConfigError) as err:
        from_dict(Outer, data)
    message = str(err.value)
    assert '\n' not in message
    for word in words:
        assert word in message


def test_a_group_left_empty_takes_its_defaults():
    # YAML `inner:` with nothing under it
    assert from_dict(Outer, {'inner': None}) == Outer()


def test_a_key_given_twice_in_a_file_is_refused_with_both_lines(tmp_path):
    path = tmp_path / 'twice.yaml'
    path.write_text('mode: realtime\ninner:\n  gain: 2.0\n  xyz: [0, 0, 0]\n  gain: 9.0\n')
    with pytest.raises(ConfigError) as err:
        load_yaml(Outer, path, 'params_file')
    text = str(err.value)
    assert '\n' not in text and "'params_file'" in text
    assert "key 'gain' a second time" in text and 'line 3' in text and 'line 5' in text
    # YAML's merge key still overrides what it merges
    path.write_text('base: &b {gain: 1.0, count: 2}\nother:\n  <<: *b\n  gain: 3.0\n')
    assert read_yaml(path)['other'] == {'gain': 3.0, 'count': 2}


def _moved_cases():
    """Every parameter of the mission's old flat group, and where it went."""
    from uav_tilt_control.mission import MissionConfig

    return sorted(MissionConfig.MOVED.items())


@pytest.mark.parametrize('old, new', _moved_cases())
def test_a_mission_parameter_by_its_old_flat_name_is_refused_naming_its_new_place(old, new):
    from uav_tilt_control.controller_core import ControllerConfig

    new_name = new[1:] if new.startswith('/') else 'mission.' + new
    assert new_name in to_flat(ControllerConfig())       # the new place exists
    for data in ({'mission.' + old: 1.0}, {'mission': {old: 1.0}}):
        with pytest.raises(ConfigError) as err:
            from_dict(ControllerConfig, data)
        assert str(err.value) == (f"parameter 'mission.{old}' has moved: it is now "
                                  f"'{new_name}'")
