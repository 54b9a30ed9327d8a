"""Where the package's files are: config/, config/scenarios/ and models/ (DESIGN section 1).

Installed (colcon, pip), they are in ``share/uav_tilt`` of the install prefix, found through
the ament index; run from a source checkout (editable install, PYTHONPATH), they are in the
checkout. A relative path a user gives is taken from the working directory when it names a
file there, else from these folders, so ``config/scenarios/windy.yaml`` works from anywhere.
"""
import os
import pathlib

from uav_tilt_common.config import ConfigError

PACKAGE = 'uav_tilt'
_HERE = pathlib.Path(__file__).resolve().parent


def source_root() -> pathlib.Path | None:
    """The source checkout this module runs from, or None when it runs installed."""
    root = _HERE.parent
    return root if (root / 'package.xml').is_file() and (root / 'setup.py').is_file() \
        else None


def share_dir() -> pathlib.Path:
    """The folder holding config/ and models/: the source checkout, else share/uav_tilt
    from the ament index, else share/uav_tilt of the prefix this module is installed in."""
    root = source_root()
    if root is not None:
        return root
    try:
        from ament_index_python.packages import PackageNotFoundError, \
            get_package_share_directory
        try:
            return pathlib.Path(get_package_share_directory(PACKAGE))
        except (PackageNotFoundError, OSError):     # not indexed, or no AMENT_PREFIX_PATH
            pass
    except ImportError:
        pass
    # <prefix>/lib/pythonX.Y/site-packages/uav_tilt_common/resources.py
    return _HERE.parents[3] / 'share' / PACKAGE


def candidates(path: str | os.PathLike[str]) -> list[pathlib.Path]:
    """Where ``path`` may be: itself when absolute, else in the working directory, then in
    :func:`share_dir`."""
    path = pathlib.Path(os.path.expanduser(str(path)))
    if path.is_absolute():
        return [path]
    # run from the checkout, the working directory is the share folder: one place
    return list(dict.fromkeys([pathlib.Path.cwd() / path, share_dir() / path]))


def locate(path: str | os.PathLike[str]) -> pathlib.Path:
    """The first of :func:`candidates` that is a file, else the last one (which is missing)."""
    found = candidates(path)
    return next((c for c in found if c.is_file()), found[-1])


def resolve(path: str | os.PathLike[str], parameter: str) -> pathlib.Path:
    """The file ``path`` (the value of parameter ``parameter``); ConfigError, one line,
    when none of :func:`candidates` is a file."""
    found = candidates(path)
    for candidate in found:
        if candidate.is_file():
            return candidate
    folder = next((c for c in found if c.is_dir()), None)
    if folder is not None:
        raise ConfigError(f"parameter '{parameter}' = {str(path)!r}: {folder} is a folder, "
                          f"not a file")
    looked = ' or '.join(str(c) for c in found)
    raise ConfigError(f"parameter '{parameter}' = {str(path)!r}: no such file ({looked})")


def default_path(relative: str | os.PathLike[str]) -> pathlib.Path:
    """A file the package ships, e.g. ``models/detector_int8.onnx`` (may not exist)."""
    return share_dir() / relative
