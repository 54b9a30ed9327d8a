"""Validated configuration dataclasses (DESIGN section 5), free of rclpy.

A config is a (possibly nested) dataclass whose fields are made with :func:`param`, which
records the allowed range or choices. :func:`from_dict` builds one from plain data (YAML,
ROS parameters flattened with dots) and validates it; every failure is one
:class:`ConfigError` line naming the parameter, its value and what is allowed.
"""
import dataclasses
import difflib
import math
import os
from typing import TYPE_CHECKING, Any, Callable, Iterable, Mapping, TypeGuard, TypeVar, cast

import yaml

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

# a config dataclass: from_dict, load_yaml and declare_config return one of the class given
ConfigT = TypeVar('ConfigT', bound='DataclassInstance')


class ConfigError(ValueError):
    """A parameter is missing, unknown, of the wrong type or out of range."""


# Units named by a field's suffix (REP-103 names), longest first; ``param(unit=...)`` wins.
UNIT_SUFFIXES = (
    ('_n_s2_per_m2', 'N s^2/m^2'), ('_n_s_per_m', 'N s/m'), ('_m_sqrt_s', 'm/sqrt(s)'),
    ('_n_per_m', 'N/m'), ('_n_s_m', 'N s/m'), ('_kgm2', 'kg m^2'), ('_mps2', 'm/s^2'),
    ('_m_s2', 'm/s^2'), ('_rad_s', 'rad/s'), ('_m_s', 'm/s'), ('_n_m', 'N/m'), ('_nm', 'N m'),
    ('_hz', 'Hz'), ('_deg', 'deg'), ('_rad', 'rad'), ('_kg', 'kg'), ('_px', 'px'),
    ('_ms', 'ms'), ('_s', 's'), ('_m', 'm'), ('_n', 'N'))


def param(default: Any, lo: float | None = None, hi: float | None = None,
          choices: list[Any] | tuple[Any, ...] | None = None, length: int | None = None,
          items: type | None = None, doc: str | None = None, unit: str | None = None,
          item_length: int | None = None) -> Any:
    """A config field with its allowed range [lo, hi], choices, fixed list length, or the
    config dataclass (or, for a list that may be empty, the scalar type: float, int, str)
    ``items`` that every element of a list field must be; ``item_length``: every element is
    itself a list of that many numbers in [lo, hi] (points); ``doc`` says what it is and
    ``unit`` its unit when the name's suffix does not (see :func:`description`)."""
    meta = {'lo': lo, 'hi': hi, 'choices': choices, 'length': length, 'items': items,
            'doc': doc, 'unit': unit, 'item_length': item_length}
    if isinstance(default, (list, dict)):
        return dataclasses.field(default_factory=lambda: type(default)(default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def nested(cls: type) -> Any:
    """A config field holding a nested config dataclass with its defaults."""
    return dataclasses.field(default_factory=cls)


def _check_scalar(name: str, value: Any, default: Any, meta: Mapping[str, Any]) -> Any:
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"parameter '{name}' = {value!r} must be true or false")
        return value
    if isinstance(default, (int, float)):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"parameter '{name}' = {value!r} must be a number")
        try:
            as_float = float(value)
        except OverflowError:   # an integer of more than ~308 digits (YAML reads any size)
            digits = int(int(value).bit_length() * math.log10(2.0)) + 1
            raise ConfigError(f"parameter '{name}' = an integer of about {digits} digits is "
                              f"too large for a number") from None
        if not math.isfinite(as_float):
            raise ConfigError(f"parameter '{name}' = {value!r} must be finite")
        if isinstance(default, int) and not isinstance(default, bool):
            if as_float != int(value):
                raise ConfigError(f"parameter '{name}' = {value!r} must be an integer")
            value = int(value)
        else:
            value = as_float
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


def check_field(name: str, value: Any, default: Any, meta: Mapping[str, Any]) -> Any:
    """``value`` checked against a field's ``default`` (its type) and metadata."""
    if isinstance(default, list):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"parameter '{name}' = {value!r} must be a list")
        length = meta.get('length')
        if length is not None and len(value) != length:
            raise ConfigError(
                f"parameter '{name}' = {list(value)!r} must have {length} elements")
        items = meta.get('items')
        if isinstance(items, type) and dataclasses.is_dataclass(items):
            return [v if isinstance(v, items) else
                    from_dict(items, v, f'{name}[{i}].') for i, v in enumerate(value)]
        if meta.get('item_length') is not None:
            point = {**meta, 'length': meta['item_length'], 'item_length': None,
                     'items': float}
            return [check_field(f'{name}[{i}]', v, [], point) for i, v in enumerate(value)]
        item_default = default[0] if default else (items() if items else 0.0)
        return [_check_scalar(name, v, item_default, meta) for v in value]
    return _check_scalar(name, value, default, meta)


def from_dict(cls: type[ConfigT], data: Mapping[str, Any] | None, prefix: str = '') -> ConfigT:
    """Build and validate config ``cls`` from nested dicts and/or dotted keys; a group may
    also be given as an instance of its config class (checked like the others)."""
    # None is a group left empty (YAML `wall:`); 0, [] or '' are not groups
    if isinstance(data, cls):
        data = to_flat(data)
    data = _unflatten({} if data is None else data)
    if not isinstance(data, dict):
        raise ConfigError(f"parameter '{prefix.rstrip('.') or cls.__name__}' = {data!r} "
                          f"must be a mapping")
    names = {f.name for f in dataclasses.fields(cls)}
    for key in data:
        if key not in names:
            raise ConfigError(unknown_message(cls, key, prefix, _first_path(key, data[key])))
    kwargs = {}
    for f in dataclasses.fields(cls):
        name = prefix + f.name
        default = _default_of(f)
        if _is_config(default):
            kwargs[f.name] = from_dict(type(default), data.get(f.name, {}), name + '.')
        elif f.name in data:
            kwargs[f.name] = check_field(name, data[f.name], default, f.metadata)
        else:
            kwargs[f.name] = default
    return cls(**kwargs)


def moved_to(cls: type, name: str) -> tuple[str, bool] | None:
    """Where the dotted parameter ``name`` of config ``cls`` lives now, if it moved, and
    whether that name is from the top-level config: a config class lists its renamed
    parameters in a class attribute ``MOVED`` (old dotted name relative to the class -> the
    new one, relative to the class or, after a '/', from the top-level config)."""
    moved = getattr(cls, 'MOVED', {})
    if name in moved:
        new = moved[name]
        return (new[1:], True) if new.startswith('/') else (new, False)
    head, _, rest = name.partition('.')
    group = next((_default_of(f) for f in dataclasses.fields(cls) if f.name == head), None) \
        if rest and dataclasses.is_dataclass(cls) else None
    inner = moved_to(type(group), rest) if _is_config(group) else None
    if inner is None or inner[1]:
        return inner
    return head + '.' + inner[0], False


def unknown_message(cls: type, name: str, prefix: str = '', given: str | None = None) -> str:
    """The one line for a parameter ``prefix + name`` that config ``cls`` does not have:
    where it lives now when it moved, else the close match of :func:`close_match` among the
    class's dotted names, if any. ``given``: the dotted name as written, when ``name`` is
    only its first part (a group the class lacks: ``mision.contact.hold_time_s``)."""
    moved = moved_to(cls, name)
    if moved is None:
        for written in dict.fromkeys((given or name, name)):
            close = close_match(written, dotted_names(cls))
            if close is not None:
                return f"unknown parameter '{prefix}{written}' (did you mean '{prefix}{close}'?)"
        return f"unknown parameter '{prefix}{given or name}'"
    new, absolute = moved
    return f"parameter '{prefix}{name}' has moved: it is now '{new if absolute else prefix + new}'"


def close_match(name: str, candidates: Iterable[str]) -> str | None:
    """The candidate that ``name`` is most likely a misspelling of (difflib, as for a node's
    parameters, ``ros_params.check_overrides``), by the whole dotted name, else by its last
    part when exactly one candidate's last part is close (``hold_time_s`` for
    ``mission.contact.hold_time_s``); None when none is close."""
    candidates = list(candidates)
    found = difflib.get_close_matches(name, candidates, n=1)
    if found:
        return found[0]
    by_leaf: dict[str, list[str]] = {}
    for candidate in candidates:
        by_leaf.setdefault(candidate.rsplit('.', 1)[-1], []).append(candidate)
    leaf = difflib.get_close_matches(name.rsplit('.', 1)[-1], list(by_leaf), n=1, cutoff=0.8)
    return by_leaf[leaf[0]][0] if leaf and len(by_leaf[leaf[0]]) == 1 else None


def dotted_names(cls: type, prefix: str = '') -> list[str]:
    """The dotted name of every field of config ``cls``, groups and leaves."""
    out = []
    for f in dataclasses.fields(cls):
        out.append(prefix + f.name)
        default = _default_of(f)
        if _is_config(default):
            out.extend(dotted_names(type(default), prefix + f.name + '.'))
    return out


def _first_path(key: str, value: Any) -> str:
    """``key`` and, when ``value`` is a mapping (a group), the dotted path of its first leaf."""
    while isinstance(value, dict) and len(value) == 1:
        inner, value = next(iter(value.items()))
        key = f'{key}.{inner}'
    return key


def unit_of(name: str, meta: Mapping[str, Any]) -> str:
    """The unit of field ``name``: ``param(unit=...)``, else its suffix's, else ''."""
    if meta.get('unit') is not None:
        return meta['unit']
    leaf = name.rsplit('.', 1)[-1]
    return next((unit for suffix, unit in UNIT_SUFFIXES if leaf.endswith(suffix)), '')


def description(name: str, meta: Mapping[str, Any]) -> str:
    """One line for a parameter's ROS descriptor: its doc, then range and unit or choices."""
    parts = [meta['doc']] if meta.get('doc') else []
    unit = unit_of(name, meta)
    lo, hi = meta.get('lo'), meta.get('hi')
    if lo is not None or hi is not None:
        bounds = f"[{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}]"
        parts.append(f'range {bounds}{" " + unit if unit else ""}')
    elif unit:
        parts.append(unit)
    if meta.get('choices') is not None:
        parts.append('one of ' + ', '.join(repr(c) for c in meta['choices']))
    if meta.get('length') is not None:
        parts.append(f"{meta['length']} elements")
    return '; '.join(parts)


def fields_flat(cls: 'type[DataclassInstance]', prefix: str = ''
                ) -> dict[str, tuple[Any, dict[str, Any]]]:
    """Dotted-name -> (default, metadata) of every leaf field of config ``cls``."""
    out = {}
    for f in dataclasses.fields(cls):
        default = _default_of(f)
        if _is_config(default):
            out.update(fields_flat(type(default), prefix + f.name + '.'))
        else:
            out[prefix + f.name] = (default, dict(f.metadata))
    return out


def to_flat(cfg: 'DataclassInstance', prefix: str = '') -> dict[str, Any]:
    """Dotted-name -> value dict of a config (the ROS parameter view)."""
    out = {}
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if _is_config(value):
            out.update(to_flat(value, prefix + f.name + '.'))
        else:
            out[prefix + f.name] = value
    return out


def check_value(cls: 'type[DataclassInstance]', name: str, value: Any) -> Any:
    """``value`` checked as field ``name`` (dotted) of config ``cls``; ConfigError if bad."""
    default, meta = fields_flat(cls)[name]
    return check_field(name, value, default, meta)


def replace_flat(cfg: Any, values: Mapping[str, Any]) -> None:
    """Set dotted-name fields of ``cfg`` in place to already checked ``values``."""
    for name, value in values.items():
        *path, leaf = name.split('.')
        target = cfg
        for part in path:
            target = getattr(target, part)
        setattr(target, leaf, value)


def load_yaml(cls: type[ConfigT], path: str | os.PathLike[str],
              parameter: str = 'file') -> ConfigT:
    """Load and validate config ``cls`` from a plain YAML file; a file that cannot be read
    or parsed, is empty or holds no mapping is one ConfigError line naming ``parameter``."""
    try:
        data = read_yaml(path)
        if data is None:        # all defaults: more likely a file not written yet
            raise ConfigError('the file is empty')
        if not isinstance(data, dict):
            raise ConfigError(f'the file holds a {type(data).__name__}, not a mapping of '
                              f'parameters')
    except ConfigError as err:
        raise ConfigError(f"parameter '{parameter}' = {str(path)!r}: {err}") from None
    return from_dict(cls, data)


BOOL_TAG = 'tag:yaml.org,2002:bool'


class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing a key given twice in one mapping (it would keep the
    last silently: a value written twice is a mistake the file's author wants to hear of),
    and reading a key as written unless it is true or false: `on: pipe_1` is the key 'on',
    as in YAML 1.2 (YAML 1.1 reads on, off, yes and no as booleans)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> Any:
        seen = set()
        for key_node, _ in node.value:
            if (key_node.tag == BOOL_TAG and isinstance(key_node.value, str)
                    and key_node.value.lower() not in ('true', 'false')):
                key_node.tag = 'tag:yaml.org,2002:str'
            if key_node.tag == 'tag:yaml.org,2002:merge':   # '<<': merged keys may be redone
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in seen
            except TypeError:       # unhashable: the base class says so
                continue
            if duplicate:
                raise yaml.constructor.ConstructorError(
                    'while reading a mapping', node.start_mark,
                    f'found the key {key!r} a second time', key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep)


def read_yaml(path: str | os.PathLike[str]) -> Any:
    """The data of YAML file ``path`` (None when empty); a file that cannot be read,
    decoded as UTF-8 or parsed, or that gives a key twice, is a ConfigError of one line
    saying why."""
    try:
        with open(path, encoding='utf-8') as stream:
            return yaml.load(stream, Loader=_UniqueKeyLoader)
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        raise ConfigError(' '.join(str(err).split())) from None


def _is_config(value: Any) -> 'TypeGuard[DataclassInstance]':
    """A config dataclass instance (a nested group), not a dataclass type."""
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def _default_of(f: dataclasses.Field[Any]) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    return cast(Callable[[], Any], f.default_factory)()


def _unflatten(data: Any) -> Any:
    if not isinstance(data, dict):
        return data
    out: dict[str, Any] = {}
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
