"""A config dataclass (:mod:`uav_tilt_common.config`) as Markdown: one table row per key with
its type, default, unit, range or choices and doc, made from the fields themselves, so that
a page generated from it cannot drift from what the code takes.
"""
import dataclasses
import inspect
from typing import Any, Callable, Collection, Mapping, cast

from uav_tilt_common.config import unit_of

HEADER = ('| key | type | default | unit | range / choices | what it is |\n'
          '|---|---|---|---|---|---|')


def default_of(f: 'dataclasses.Field[Any]') -> Any:
    """The default value of field ``f`` (its factory's value for a list or a group)."""
    if f.default is not dataclasses.MISSING:
        return f.default
    return cast(Callable[[], Any], f.default_factory)()


def is_group(value: Any) -> bool:
    """Whether a default is a nested config (a dataclass instance)."""
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def entry_class(f: 'dataclasses.Field[Any]') -> type | None:
    """The config dataclass each entry of a list field is (``param(items=...)``), or None."""
    items = f.metadata.get('items')
    return items if isinstance(items, type) and dataclasses.is_dataclass(items) else None


def summary(cls: type) -> str:
    """The docstring of ``cls`` as one paragraph ('' without one)."""
    return ' '.join((inspect.getdoc(cls) or '').split())


def value_text(value: Any) -> str:
    """A value as a YAML file writes it."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, float):
        return f'{value:g}'
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(value_text(v) for v in value) + ']'
    return str(value)


def type_text(default: Any, meta: Mapping[str, Any]) -> str:
    """What a key takes, in words."""
    if isinstance(default, bool):
        return 'true/false'
    if isinstance(default, int):
        return 'integer'
    if isinstance(default, float):
        return 'number'
    if isinstance(default, str):
        return 'string'
    if isinstance(default, list):
        items = meta.get('items')
        if isinstance(items, type) and dataclasses.is_dataclass(items):
            return 'list of entries'
        if meta.get('item_length') is not None:
            return f"list of [{meta['item_length']} numbers]"
        if meta.get('length') is not None:
            return f"{meta['length']} numbers"
        return 'list of ' + ('strings' if items is str else 'integers' if items is int
                             else 'numbers')
    return type(default).__name__


def range_text(meta: Mapping[str, Any]) -> str:
    """The allowed range or choices of a key ('' when it has neither)."""
    lo, hi = meta.get('lo'), meta.get('hi')
    if meta.get('choices') is not None:
        return 'one of ' + ', '.join(f'`{c}`' for c in meta['choices'])
    if lo is not None and hi is not None:
        return f'[{value_text(lo)}, {value_text(hi)}]'
    if lo is not None:
        return f'>= {value_text(lo)}'
    if hi is not None:
        return f'<= {value_text(hi)}'
    return ''


def _cell(text: str) -> str:
    return text.replace('|', '\\|')


def rows(cls: type, prefix: str = '', required: Collection[str] = (),
         groups: bool = True) -> list[str]:
    """The table rows of config ``cls``'s keys, groups flattened to dotted names (``prefix``
    before each; left out with ``groups`` False); a list of entries is one row (its entries
    have a table of their own). ``required``: keys with no default, whose default column
    says so."""
    out = []
    for f in dataclasses.fields(cls):
        default, meta = default_of(f), f.metadata
        name = prefix + f.name
        if is_group(default):
            out += rows(type(default), name + '.', required) if groups else []
            continue
        shown = 'required' if name in required else f'`{value_text(default)}`'
        unit = unit_of(name, meta)
        cells = (f'`{name}`', type_text(default, meta), shown, unit, range_text(meta),
                 meta.get('doc') or '')
        out.append('| ' + ' | '.join(_cell(c) for c in cells) + ' |')
    return out


def table(cls: type, prefix: str = '', required: Collection[str] = (),
          groups: bool = True) -> str:
    """The Markdown table of config ``cls`` (see :func:`rows`)."""
    return '\n'.join([HEADER, *rows(cls, prefix, required, groups)])


def undocumented(cls: type, prefix: str = '') -> list[str]:
    """The dotted keys of ``cls`` (its groups' and list entries' included) without a doc."""
    out = []
    for f in dataclasses.fields(cls):
        default, name = default_of(f), prefix + f.name
        if is_group(default):
            out += undocumented(type(default), name + '.')
            continue
        if not f.metadata.get('doc'):
            out.append(name)
        entries = entry_class(f)
        if entries is not None:
            out += undocumented(entries, name + '[].')
    return out
