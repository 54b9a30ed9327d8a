"""ROS 2 message definitions as rosbag2 stores them in MCAP schemas (encoding ``ros2msg``).

The definition of a type is its .msg text followed by the text of every type it uses,
recursively, each preceded by a line of 80 '=' and ``MSG: pkg/msg/Type`` (rosbag2's
docs/message_definition_encoding.md). The .msg files come from the installed message
packages' share folders: AMENT_PREFIX_PATH on a ROS install, this interpreter's prefix for
the pip wheels.
"""
import functools
import os
import re
import struct
import sys

SEPARATOR = '=' * 80
PRIMITIVES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'))
TIME = 'builtin_interfaces/msg/Time'
# "TYPE NAME=VALUE" is a constant, "TYPE NAME [DEFAULT]" a field.
_CONSTANT = re.compile(r'^\S+\s+\w+\s*=')


def canonical(type_name: str, package: str = '') -> str:
    """``pkg/msg/Type`` of ``pkg/msg/Type``, ``pkg/Type`` or ``Type`` (inside ``package``)."""
    parts = type_name.split('/')
    if len(parts) == 1:
        # rosidl keeps the ROS 1 shorthand for the header.
        return 'std_msgs/msg/Header' if parts[0] == 'Header' else f'{package}/msg/{parts[0]}'
    return f'{parts[0]}/msg/{parts[-1]}'


def share_dirs() -> list[str]:
    """Folders searched for ``<pkg>/msg/<Type>.msg``, in order."""
    prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    return [os.path.join(p, 'share') for p in prefixes + [sys.prefix]]


@functools.lru_cache(maxsize=None)
def msg_text(type_name: str) -> str:
    """The .msg text of ``pkg/msg/Type``; LookupError when no package provides it."""
    package, _, name = canonical(type_name).split('/')
    for share in share_dirs():
        path = os.path.join(share, package, 'msg', name + '.msg')
        if os.path.isfile(path):
            with open(path, encoding='utf-8') as stream:
                return stream.read()
    raise LookupError(f'no {package}/msg/{name}.msg under {", ".join(share_dirs())}')


def fields(type_name: str) -> list[tuple[str, str]]:
    """(type, name) of each field of a message, constants left out; types canonical or
    primitive (array and bound suffixes removed)."""
    package = canonical(type_name).split('/')[0]
    result = []
    for line in msg_text(type_name).splitlines():
        line = line.split('#', 1)[0].strip()
        if not line or _CONSTANT.match(line):
            continue
        type_token, name = line.split()[:2]
        base = re.split(r'[\[<]', type_token)[0]
        result.append((base if base in PRIMITIVES else canonical(base, package), name))
    return result


def dependencies(type_name: str) -> list[str]:
    """Every non-primitive type ``type_name`` uses, recursively, depth first, once each."""
    seen: list[str] = []

    def visit(name: str) -> None:
        for field_type, _ in fields(name):
            if field_type not in PRIMITIVES and field_type not in seen:
                seen.append(field_type)
                visit(field_type)
    visit(canonical(type_name))
    return seen


@functools.lru_cache(maxsize=None)
def full_definition(type_name: str) -> str:
    """The complete ``ros2msg`` definition of ``type_name`` (LookupError if not installed)."""
    parts = [msg_text(type_name).rstrip()]
    for dep in dependencies(type_name):
        parts.append(f'{SEPARATOR}\nMSG: {dep}\n{msg_text(dep).rstrip()}')
    return '\n'.join(parts) + '\n'


@functools.lru_cache(maxsize=None)
def starts_with_time(type_name: str) -> bool:
    """Whether the first field, followed down nested types, is a builtin_interfaces/Time
    (a std_msgs/Header stamp, or /clock): its CDR then starts with the stamp."""
    name = canonical(type_name)
    while name != TIME:
        first = fields(name)
        if not first or first[0][0] in PRIMITIVES:
            return False
        name = first[0][0]
    return True


def cdr_stamp_ns(data: bytes) -> int:
    """The Time at the start of a serialized CDR message, in ns (bit 0 of the encapsulation
    id says little endian; the Time follows the 4-byte encapsulation header)."""
    order = '<' if data[1] & 1 else '>'
    sec, nanosec = struct.unpack_from(order + 'iI', data, 4)
    return sec * 1_000_000_000 + nanosec
