"""`uav-tilt campaign --out DIR`: one JSON line per finished run, an interrupted campaign
resumed with --resume finishes with every run once, --record keeps one MCAP per run."""
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest
from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader

from uav_tilt_common import names
from uav_tilt_common.config import ConfigError
from uav_tilt_sim import randomise
from uav_tilt_tools.bag import reader as recording
from uav_tilt_tools.bag.folder import METADATA_FILE, RECORDING_FILE
from uav_tilt_tools.campaign import run as cp
from uav_tilt_tools.campaign.store import RUNS_FILE, RESULT_FILE, run_dir
from uav_tilt_tools.metrics.mission import mode_samples

# Enough runs that some are still flying when the first is kept, however fast they fly
# (8 s of sim time takes 1-4 s here).
N, SEED, DURATION_S = 8, 7, 8.0


def _cli(*args):
    return [sys.executable, '-m', 'uav_tilt_tools.cli', 'campaign', '--n', str(N),
            '--seed', str(SEED), '--duration', str(DURATION_S), '--workers', '2', *args]


def _lines(out):
    with open(os.path.join(out, RUNS_FILE), encoding='utf-8') as stream:
        return [json.loads(line) for line in stream]


def test_interrupted_campaign_resumes_with_every_run_once(tmp_path):
    out = str(tmp_path / 'campaign')
    # Ctrl-C as a terminal sends it: to the process group, once the first run is kept
    # (a terminal's foreground job has SIGINT at its default even when these tests run as a
    # background job, which starts with it ignored)
    proc = subprocess.Popen(_cli('--out', out), process_group=0, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    runs_path = os.path.join(out, RUNS_FILE)
    deadline = time.monotonic() + 120.0
    while time.monotonic() < deadline and proc.poll() is None:
        if os.path.exists(runs_path) and os.path.getsize(runs_path):
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    kept = _lines(out)
    assert proc.returncode == 130, stderr
    assert 1 <= len(kept) < N and f'{len(kept)} of {N} runs' in stderr
    assert not stdout and not os.path.exists(os.path.join(out, RESULT_FILE))
    # a line cut short by a kill during its write is dropped on resume, not read
    with open(runs_path, 'a', encoding='utf-8') as stream:
        stream.write('{"index": 3, "se')
    done = subprocess.run(_cli('--out', out, '--resume'), capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    lines = _lines(out)
    assert sorted(r['index'] for r in lines) == list(range(N))
    assert [r['index'] for r in result['runs']] == list(range(N)) and result['n'] == N
    assert lines[:len(kept)] == kept             # what was kept is not flown again
    with open(os.path.join(out, RESULT_FILE), encoding='utf-8') as stream:
        assert json.load(stream) == result
    # a second campaign into the same folder is refused, not mixed in
    again = subprocess.run(_cli('--out', out), capture_output=True, text=True, timeout=120)
    assert again.returncode == 2 and '--resume' in again.stderr


def test_resume_refuses_another_campaign(tmp_path):
    cp.campaign(1, SEED, duration_s=0.1, progress=False, out=tmp_path)
    with pytest.raises(ConfigError):
        cp.campaign(1, SEED + 1, duration_s=0.1, progress=False, out=tmp_path, resume=True)


def test_a_plan_resumes_however_its_path_is_written(tmp_path):
    config = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                          'config')
    files = dict(plan_file=os.path.join(config, 'plans', 'inspection.yaml'),
                 scenario_file=os.path.join(config, 'scenarios', 'plan.yaml'))
    cp.campaign(1, SEED, duration_s=0.1, progress=False, out=tmp_path,
                **{k: v.replace(os.sep + 'config' + os.sep, os.sep + 'config' + os.sep + '.'
                                + os.sep) for k, v in files.items()})
    result = cp.campaign(1, SEED, duration_s=0.1, progress=False, out=tmp_path, resume=True,
                         **files)
    assert result['n'] == 1
    # relative to the working folder, as typed in the checkout
    relative = {k: os.path.relpath(v) for k, v in files.items()}
    assert not any(os.path.isabs(v) for v in relative.values())
    result = cp.campaign(1, SEED, duration_s=0.1, progress=False, out=tmp_path, resume=True,
                         **relative)
    assert result['n'] == 1


def test_a_resume_refuses_a_plan_or_scenario_edited_since_the_campaign_began(tmp_path):
    """The runs kept flew the files' earlier contents: resuming on edited ones would mix two
    campaigns under one result."""
    config = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                          'config')
    files = {}
    for key, source in (('plan_file', os.path.join(config, 'plans', 'inspection.yaml')),
                        ('scenario_file', os.path.join(config, 'scenarios', 'plan.yaml'))):
        files[key] = str(tmp_path / os.path.basename(source))
        shutil.copy(source, files[key])
    out = tmp_path / 'out'
    cp.campaign(1, SEED, duration_s=0.1, progress=False, out=out, **files)
    for path in files.values():
        with open(path, encoding='utf-8') as stream:
            original = stream.read()
        with open(path, 'a', encoding='utf-8') as stream:
            stream.write('# edited\n')
        with pytest.raises(ConfigError, match=f'{path} has changed since the campaign'):
            cp.campaign(1, SEED, duration_s=0.1, progress=False, out=out, resume=True, **files)
        with open(path, 'w', encoding='utf-8') as stream:
            stream.write(original)
    assert cp.campaign(1, SEED, duration_s=0.1, progress=False, out=out, resume=True,
                       **files)['n'] == 1
    # a store written before the digests were kept resumes as it did
    args_path = out / 'campaign_args.json'
    args = json.loads(args_path.read_text())
    assert {k for k in args if k.endswith('_sha256')} == {
        'plan_file_sha256', 'scenario_file_sha256'}
    args_path.write_text(json.dumps({k: v for k, v in args.items()
                                     if not k.endswith('_sha256')}))
    assert cp.campaign(1, SEED, duration_s=0.1, progress=False, out=out, resume=True,
                       **files)['n'] == 1


def test_a_damaged_store_is_refused_and_keeps_its_runs(tmp_path):
    out = tmp_path / 'store'
    cp.campaign(3, SEED, duration_s=0.1, progress=False, out=out)
    runs_path = out / RUNS_FILE
    lines = runs_path.read_text().splitlines(keepends=True)
    # an edit in the middle (not a kill's torn last line): refused, the runs after it kept
    runs_path.write_text(lines[0] + '{"index": 1, "se\n' + lines[2])
    damaged = runs_path.read_bytes()
    with pytest.raises(ConfigError, match='line 2 is no run'):
        cp.campaign(3, SEED, duration_s=0.1, progress=False, out=out, resume=True)
    assert runs_path.read_bytes() == damaged
    # arguments that are no JSON, or JSON but no mapping, an --out that is a file, a resume
    # with no folder
    (out / 'campaign_args.json').write_text('{"n": 3, "seed":')
    with pytest.raises(ConfigError, match='unreadable'):
        cp.campaign(3, SEED, duration_s=0.1, progress=False, out=out, resume=True)
    (out / 'campaign_args.json').write_text('[3, 7]')
    with pytest.raises(ConfigError, match=r'holds the campaign \[3, 7\], not'):
        cp.campaign(3, SEED, duration_s=0.1, progress=False, out=out, resume=True)
    (tmp_path / 'file').write_text('')
    with pytest.raises(ConfigError, match='cannot make the folder'):
        cp.campaign(1, SEED, duration_s=0.1, progress=False, out=tmp_path / 'file')
    with pytest.raises(ConfigError, match='--out'):
        cp.campaign(1, SEED, duration_s=0.1, progress=False, resume=True)


def test_corners_reach_every_run_and_a_resume_keeps_them(tmp_path):
    done = subprocess.run(_cli('--corners', '--n', '2', '--duration', '0.1', '--out',
                               str(tmp_path)), capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result['corners'] is True
    for run in result['runs']:
        for key, ends in (('wall_stiffness_n_per_m', randomise.STIFFNESS_N_PER_M),
                          ('wall_distance_m', randomise.WALL_DISTANCE_M)):
            assert min(abs(run[key] / end - 1.0) for end in ends) < 1e-9, (key, run[key])
    # the folder holds a corner campaign: resuming it as a uniform one is refused
    with pytest.raises(ConfigError):
        cp.campaign(2, SEED, duration_s=0.1, progress=False, out=tmp_path, resume=True)
    cp.campaign(2, SEED, duration_s=0.1, progress=False, out=tmp_path, resume=True,
                corners=True)


def test_record_keeps_one_mcap_per_run_that_the_report_reads(tmp_path):
    result = cp.campaign(2, SEED, workers=2, duration_s=4.0, progress=False, out=tmp_path,
                         record=True)
    for run in result['runs']:
        folder = run_dir(str(tmp_path), run['index'])
        assert sorted(os.listdir(folder)) == sorted([RECORDING_FILE, METADATA_FILE])
        rec = recording.load_recording(
            folder, topics=recording.REPORT_TOPICS + (names.ODOM, names.CLOCK))
        # every controller tick's sensors, as the plant node publishes them
        assert len(rec[names.ODOM]) == len(rec[names.CLOCK]) == run['ticks']
        # the folder is a rosbag2 bag, latched topics latched as the plant latches them
        with Reader(folder) as bag:
            connections = {c.topic: c for c in bag.connections}
            assert connections['/clock'].msgcount == run['ticks']
            assert connections['/uav/' + names.GROUND_TRUTH_TARGET].ext.offered_qos_profiles[
                0].durability == QosDurability.TRANSIENT_LOCAL
        modes = mode_samples(recording.statuses(rec, names.CONTROLLER_STATUS))
        assert modes[-1][1] == run['mode_history'][-1][1]
        assert recording.target_pose(rec) is not None
