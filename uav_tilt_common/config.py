"""Validated configuration dataclasses (DESIGN section 5), free of rclpy.

A config is a (possibly nested) dataclass whose fields are made with :func:`param`, which
records the allowed range or choices. :func:`from_dict` builds one from plain data (YAML,
ROS parameters flattened with dots) and validates it; every failure is one
:class:`ConfigError` line naming the parameter, its value and what is allowed.
"""
import dataclasses
import math

import yaml


class ConfigError(ValueError):
    """A parameter is missing, unknown, of the wrong type or out of range."""


def param(default, lo=None, hi=None, choices=None, length=None, items=None,
          item_length=None):
    """A config field with its allowed range [lo, hi], choices and fixed list length.

    ``items``: what every element of a list field is: a config dataclass, or ``float`` or
    ``str`` (which gives an empty default list its type); ``item_length``: every element
    is itself a list of that many numbers in [lo, hi] (points)."""
    meta = {'lo': lo, 'hi': hi, 'choices': choices, 'length': length, 'items': items,
            'item_length': item_length}
    if isinstance(default, (list, dict)):
        return dataclasses.field(default_factory=lambda: type(default)(default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def nested(cls):
    """A config field holding a nested config dataclass with its defaults."""
    return dataclasses.field(default_factory=cls)


def _check_scalar(name, value, default, meta):
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"parameter '{name}' = {value!r} must be true or false")
        return value
    if isinstance(default, (int, float)):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"parameter '{name}' = {value!r} must be a number")
        if isinstance(default, int) and not isinstance(default, bool):
            if float(value) != int(value):
                raise ConfigError(f"parameter '{name}' = {value!r} must be an integer")
            value = int(value)
        else:
            value = float(value)
        if not math.isfinite(value):
            raise ConfigError(f"parameter '{name}' = {value!r} must be finite")
        lo, hi = meta.get('lo'), meta.get('hi')
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise ConfigError(f"parameter '{name}' = {value!r} is out of range [{lo}, {hi}]")
        return value
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ConfigError(f"parameter '{name}' = {value!r} must be a string")
        choices = meta.get('choices')
        if choices is not None and value not in choices:
            allowed = ', '.join(repr(c) for c in choices)
            raise ConfigError(f"parameter '{name}' = {value!r} must be one of {allowed}")
        return value
    return value


def _check(name, value, default, meta):
    if isinstance(default, list):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"parameter '{name}' = {value!r} must be a list")
        length = meta.get('length')
        if length is not None and len(value) != length:
            raise ConfigError(
                f"parameter '{name}' = {list(value)!r} must have {length} elements")
        items = meta.get('items')
        if dataclasses.is_dataclass(items):
            return [v if isinstance(v, items) else
                    from_dict(items, v, f'{name}[{i}].') for i, v in enumerate(value)]
        if meta.get('item_length') is not None:
            point = {**meta, 'length': meta['item_length'], 'item_length': None,
                     'items': float}
            return [_check(f'{name}[{i}]', v, [], point) for i, v in enumerate(value)]
        item_default = default[0] if default else ('' if items is str else 0.0)
        return [_check_scalar(name, v, item_default, meta) for v in value]
    return _check_scalar(name, value, default, meta)


def from_dict(cls, data, prefix=''):
    """Build and validate config ``cls`` from nested dicts and/or dotted keys."""
    data = _unflatten(data or {})
    if not isinstance(data, dict):
        raise ConfigError(f"parameter '{prefix or cls.__name__}' = {data!r} must be a mapping")
    names = {f.name for f in dataclasses.fields(cls)}
    for key in data:
        if key not in names:
            raise ConfigError(f"unknown parameter '{prefix}{key}'")
    kwargs = {}
    for f in dataclasses.fields(cls):
        name = prefix + f.name
        default = _default_of(f)
        if dataclasses.is_dataclass(default):
            kwargs[f.name] = from_dict(type(default), data.get(f.name, {}), name + '.')
        elif f.name in data:
            kwargs[f.name] = _check(name, data[f.name], default, f.metadata)
        else:
            kwargs[f.name] = default
    return cls(**kwargs)


def to_flat(cfg, prefix=''):
    """Dotted-name -> value dict of a config (the ROS parameter view)."""
    out = {}
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if dataclasses.is_dataclass(value):
            out.update(to_flat(value, prefix + f.name + '.'))
        else:
            out[prefix + f.name] = value
    return out


def flat_fields(cls, prefix=''):
    """(dotted name, default, field metadata) of every leaf field of config ``cls``."""
    out = []
    for f in dataclasses.fields(cls):
        default = _default_of(f)
        if dataclasses.is_dataclass(default):
            out.extend(flat_fields(type(default), prefix + f.name + '.'))
        else:
            out.append((prefix + f.name, default, f.metadata))
    return out


def load_yaml(cls, path):
    """Load and validate config ``cls`` from a plain YAML file."""
    with open(path, encoding='utf-8') as stream:
        data = yaml.safe_load(stream)
    return from_dict(cls, data or {})


def _default_of(f):
    if f.default is not dataclasses.MISSING:
        return f.default
    return f.default_factory()


def _unflatten(data):
    if not isinstance(data, dict):
        return data
    out = {}
    for key, value in data.items():
        head, _, rest = str(key).partition('.')
        if rest:
            out.setdefault(head, {})
            if not isinstance(out[head], dict):
                raise ConfigError(f"parameter '{head}' is both a value and a group")
            out[head][rest] = value
        else:
            out[head] = value
    return {k: _unflatten(v) if isinstance(v, dict) else v for k, v in out.items()}
