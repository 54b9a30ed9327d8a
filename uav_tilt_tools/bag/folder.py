"""Where a recording goes: a run's folder holds one recording, never overwritten nor mixed
with another (the recorder node, ``uav-tilt fly --record``, a campaign's ``--record``).

``python -m uav_tilt_tools.bag.folder DIR`` exits 2 with one line on stderr unless DIR can
take a new recording (scripts/launch.sh checks ``--record DIR`` before it starts anything).
"""
import errno
import os
import sys

from uav_tilt_common.config import ConfigError

RECORDING_FILE = 'recording.mcap'     # what a run's folder holds (recorder, fly, campaign)
METADATA_FILE = 'metadata.yaml'       # rosbag2's description of the bag in a folder


def recording_folder(folder: str) -> str:
    """The path of a new recording in ``folder``, made when missing: FileExistsError when
    it holds one already (an MCAP file, or a rosbag2 bag's metadata.yaml), which would be
    overwritten or mixed with the new one."""
    os.makedirs(folder, exist_ok=True)
    held = sorted(name for name in os.listdir(folder)
                  if name == METADATA_FILE or name.endswith('.mcap'))
    if held:
        raise FileExistsError(errno.EEXIST, 'holds a recording', os.path.join(folder, held[0]))
    if not os.access(folder, os.W_OK | os.X_OK):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), folder)
    return os.path.join(folder, RECORDING_FILE)


def check_recording_folder(named: str, folder: str) -> None:
    """ConfigError (one line, :func:`not_recordable`) unless ``folder`` can take a new
    recording (:func:`recording_folder`, which makes it when missing)."""
    try:
        recording_folder(folder)
    except OSError as err:
        raise not_recordable(named, err) from None


def not_recordable(named: str, err: OSError) -> ConfigError:
    """The ConfigError (one line) for the OSError ``err`` of making a new recording where
    ``named`` (the option or parameter and its value) says."""
    if isinstance(err, FileExistsError):
        return ConfigError(f'{named}: {err.filename} is there already (a recording is never '
                           f'overwritten, nor mixed with another)')
    return ConfigError(f'{named}: {err.strerror}')


def main(argv: list[str] | None = None) -> int:
    """Exit code 0 when the folder in ``argv`` can take a new recording, else 2 with one
    line on stderr (see the docstring)."""
    argv = sys.argv[1:] if argv is None else argv
    try:
        check_recording_folder(f'--record {argv[0]}', argv[0])
    except ConfigError as err:
        print(err, file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
