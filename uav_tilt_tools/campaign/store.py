"""The ``--out DIR`` of a campaign: what it is, and every run as it finishes.

- ``DIR/campaign_args.json``: n, seed, target_source, duration_s, the plan and scenario
  files and their contents' SHA-256 (a resume must match);
- ``DIR/runs.jsonl``: one JSON line per finished run (the run's dict of the campaign JSON),
  appended and synced to disk as each run finishes, so an interrupted campaign keeps them;
- ``DIR/run_NNNN/recording.mcap`` and rosbag2's ``metadata.yaml`` with ``--record``
  (written before the run's line, so a line means its recording is complete);
  ``uav-tilt report DIR/run_NNNN`` reads it, ``ros2 bag play DIR/run_NNNN`` plays it;
- ``DIR/campaign.json``: the campaign JSON once every run is in.
"""
import hashlib
import json
import os
from typing import Any

from uav_tilt_common.config import ConfigError
from uav_tilt_tools.bag.folder import RECORDING_FILE
from uav_tilt_tools.bag.writer import write_rosbag2_metadata
from uav_tilt_tools.campaign.jobs import Job
from uav_tilt_tools.runner.fly import jsonable

ARGS_FILE = 'campaign_args.json'
RUNS_FILE = 'runs.jsonl'
RESULT_FILE = 'campaign.json'
DIGEST = '_sha256'          # campaign_args.json: FILE_KEY + DIGEST is FILE_KEY's digest


def file_digests(**paths: str | None) -> dict[str, str]:
    """``{NAME_sha256: hex digest of the file's contents}`` for each NAME=path given (None:
    left out), so that a resume notices an edited file (ConfigError when one is
    unreadable)."""
    digests = {}
    for name, path in paths.items():
        if path is None:
            continue
        try:
            with open(path, 'rb') as stream:
                digests[name + DIGEST] = hashlib.sha256(stream.read()).hexdigest()
        except OSError as err:
            raise ConfigError(f'{path}: unreadable ({err.strerror})') from None
    return digests


def run_dir(out_dir: str, index: int) -> str:
    """The folder of run ``index``'s recording."""
    return os.path.join(out_dir, f'run_{index:04d}')


def _check_same_campaign(out_dir: str, found: Any, args: dict[str, Any]) -> None:
    """ConfigError unless the campaign ``found`` in ``out_dir`` is the one of ``args``. An
    edited file is named as such (the runs kept flew its earlier contents); a store from
    before the digests were kept has none to compare."""
    def without_digests(values: dict[str, Any]) -> dict[str, Any]:
        return {k: v for k, v in values.items() if not k.endswith(DIGEST)}

    if not isinstance(found, dict) or without_digests(found) != without_digests(args):
        raise ConfigError(f'{out_dir} holds the campaign '
                          f'{without_digests(found) if isinstance(found, dict) else found}, '
                          f'not {without_digests(args)}')
    for key, digest in args.items():
        if key.endswith(DIGEST) and found.get(key, digest) != digest:
            raise ConfigError(f'{args[key[:-len(DIGEST)]]} has changed since the campaign in '
                              f'{out_dir} began (its runs flew the earlier contents): put it '
                              f'back to resume, or start another campaign (--out)')


class RunStore:
    """Runs of one campaign in ``out_dir``; ``resume`` continues the campaign found there."""

    def __init__(self, out_dir: str | os.PathLike[str], args: dict[str, Any],
                 resume: bool = False) -> None:
        self.out_dir = str(out_dir)
        self.runs_path = os.path.join(self.out_dir, RUNS_FILE)
        args_path = os.path.join(self.out_dir, ARGS_FILE)
        try:
            os.makedirs(self.out_dir, exist_ok=True)
        except OSError as err:
            raise ConfigError(f'--out {self.out_dir}: cannot make the folder ({err})') from None
        if resume and os.path.exists(args_path):
            try:
                with open(args_path, encoding='utf-8') as stream:
                    found = json.load(stream)
            except (OSError, ValueError) as err:
                raise ConfigError(f'{args_path}: unreadable ({err}); not a campaign to '
                                  f'resume') from None
            _check_same_campaign(self.out_dir, found, args)
        elif os.path.exists(self.runs_path) and os.path.getsize(self.runs_path) and not resume:
            raise ConfigError(f'{self.runs_path} already holds runs: --resume continues that '
                              f'campaign, or choose another --out')
        with open(args_path, 'w', encoding='utf-8') as stream:
            json.dump(args, stream)
        self._lines: list[dict[str, Any]] = self._read() if resume else []
        if not resume:
            open(self.runs_path, 'w').close()

    def _read(self) -> list[dict[str, Any]]:
        """The runs of runs.jsonl; the last line, when a kill cut it short, is dropped from
        the file. Any other line that is no run is refused (ConfigError): the file was
        edited, and cutting it there would lose the runs after it."""
        if not os.path.exists(self.runs_path):
            return []
        with open(self.runs_path, 'rb') as stream:
            lines = stream.read().splitlines(keepends=True)
        runs, good_bytes = [], 0
        for number, line in enumerate(lines, 1):
            try:
                run = json.loads(line) if line.endswith(b'\n') else None
            except ValueError:
                run = None
            if not isinstance(run, dict):
                if number == len(lines) and not line.endswith(b'\n'):
                    break
                raise ConfigError(f'{self.runs_path}: line {number} is no run '
                                  f'({line[:40]!r}); mend or remove it to resume')
            runs.append(run)
            good_bytes += len(line)
        with open(self.runs_path, 'r+b') as stream:
            stream.truncate(good_bytes)
        return runs

    def runs_of(self, jobs: list[Job]) -> dict[int, dict[str, Any]]:
        """{index: run} of the stored runs that belong to ``jobs`` (each once)."""
        seeds = {job['index']: job['seed'] for job in jobs}
        runs: dict[int, dict[str, Any]] = {}
        for run in self._lines:
            index: Any = run.get('index')     # checked against the jobs' below
            if seeds.get(index) != run.get('seed'):
                raise ConfigError(f'{self.runs_path}: run {index} with seed {run.get("seed")} '
                                  f'is not one of this campaign')
            runs.setdefault(index, run)
        return runs

    def add(self, run: dict[str, Any], bag: bytes | None = None) -> None:
        """Keep one finished run (and its recording's bytes)."""
        if bag is not None:
            folder = run_dir(self.out_dir, run['index'])
            os.makedirs(folder, exist_ok=True)
            path = os.path.join(folder, RECORDING_FILE)
            with open(path + '.part', 'wb') as stream:
                stream.write(bag)
            os.replace(path + '.part', path)
            write_rosbag2_metadata(path)    # the run's folder opens as a rosbag2 bag
        line = json.dumps(run, default=jsonable) + '\n'
        with open(self.runs_path, 'a', encoding='utf-8') as stream:
            stream.write(line)
            stream.flush()
            os.fsync(stream.fileno())

    def finish(self, result: dict[str, Any]) -> None:
        """Write the campaign JSON beside its runs."""
        with open(os.path.join(self.out_dir, RESULT_FILE), 'w', encoding='utf-8') as stream:
            json.dump(result, stream, default=jsonable)
