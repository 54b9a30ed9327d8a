"""A campaign: the inspection mission over ``n`` randomised worlds (:mod:`.jobs`), spread over
the CPU cores of this machine (``backend='local'``, :mod:`.local_backend`) or over a Ray
cluster (``backend='ray'``, :mod:`.ray_backend`), each run kept as it finishes when the
campaign has an output folder (:mod:`.store`), so that a resume continues an interrupted
campaign; the result is the campaign JSON (:mod:`.summary`). Targets come from ground truth
by default; ``target_source='vision'`` renders the camera and runs the deployed detector
pipeline in each run. With a plan and its scenario each run flies the plan on the
scenario's wall and objects, the rest of the world (seed, wind, noise, model mismatch, the
wall's stiffness and friction) drawn as for the others.
"""
import os
from typing import Any

from tqdm import tqdm

from uav_tilt_common.config import ConfigError
from uav_tilt_tools.campaign.jobs import jobs_of, run_one
from uav_tilt_tools.campaign.local_backend import local_runs
from uav_tilt_tools.campaign.ray_backend import ray_runs
from uav_tilt_tools.campaign.store import RunStore, file_digests
from uav_tilt_tools.campaign.summary import summarize

BACKENDS = ('local', 'ray')


def campaign(n: int, seed: int, workers: int | None = None, target_source: str = 'ground_truth',
             duration_s: float | None = None, progress: bool = True, backend: str = 'local',
             address: str | None = None, out: str | os.PathLike[str] | None = None,
             resume: bool = False, record: bool = False, plan_file: str | None = None,
             scenario_file: str | None = None, corners: bool = False,
             settings: dict[str, Any] | None = None, structures: bool = False
             ) -> dict[str, Any]:
    """Run ``n`` randomised missions (of the plan ``plan_file`` on ``scenario_file``'s
    wall when given; ``settings``: the controller's and vehicle's parameters of every run,
    as ``uav-tilt fly --set`` takes them; ``duration_s`` None: the plan's
    (:func:`uav_tilt_tools.runner.fly.default_duration_s`); ``corners``: worlds at the ends
    of every range, :func:`uav_tilt_sim.randomise.random_draw`; ``structures``: worlds of
    structure kinds, :func:`uav_tilt_sim.randomise_structures.structure_draw`); returns the
    DESIGN section 7 JSON dict.

    ``backend``: 'local' (a process pool of ``workers``, default one per core) or 'ray'
    (one Ray task per run on a local Ray of ``workers`` CPUs, or on the cluster at
    ``address``). ``out``: a folder that gets one JSON line per finished run
    (:mod:`uav_tilt_tools.campaign.store`; with ``record``, an MCAP per run);
    ``resume`` skips the runs it already holds. Runs are counted once each, by index.
    Ctrl-C raises :class:`Interrupted` after keeping what finished.
    """
    if backend not in BACKENDS:
        raise ConfigError(f'backend {backend!r}: expected one of {BACKENDS}')
    if record and out is None:
        raise ConfigError('recording needs an output folder (--out DIR)')
    if resume and out is None:
        raise ConfigError('resuming needs the campaign\'s output folder (--out DIR)')
    if structures and (corners or plan_file):
        raise ConfigError('structure worlds (--structures) are drawn whole: not with '
                          '--corners or --plan')
    if address is not None and backend != 'ray':
        raise ConfigError('an address (--address) needs the ray backend (--backend ray)')
    cpus = os.cpu_count() or 1
    if backend == 'ray':
        runner = ray_runs
        threads = 1                     # each task gets one CPU
    else:
        runner = local_runs
        workers = workers or min(n, cpus)
        threads = max(1, cpus // max(workers, 1))
    jobs = jobs_of(n, seed, target_source, duration_s, threads, record, plan_file,
                   scenario_file, corners, settings, structures)
    store = None
    if out is not None:
        # files as the same path however written ('./a.yaml', 'a.yaml', absolute), and what
        # they hold, for the resume
        args: dict[str, Any] = dict(n=n, seed=seed, target_source=target_source,
                                    duration_s=duration_s,
                                    plan_file=plan_file and os.path.realpath(plan_file),
                                    scenario_file=scenario_file
                                    and os.path.realpath(scenario_file),
                                    **file_digests(plan_file=plan_file,
                                                   scenario_file=scenario_file))
        if corners:     # only then, so that folders of earlier campaigns still resume
            args['corners'] = True
        if settings:    # the same
            args['settings'] = settings
        if structures:
            args['structures'] = True
        store = RunStore(out, args, resume)
    done = store.runs_of(jobs) if store is not None else {}
    todo = [job for job in jobs if job['index'] not in done]
    bar = None
    if progress:
        bar = tqdm(total=n, initial=len(done), desc='campaign', unit='run')
    results = runner(run_one, todo, workers, address)
    try:
        for run, bag in results:
            if run['index'] in done:        # a run is counted once, whatever comes back
                continue
            done[run['index']] = run
            if store is not None:
                store.add(run, bag)
            if bar is not None:
                bar.update()
    except KeyboardInterrupt:
        raise Interrupted(len(done), n, store.runs_path if store is not None else None) \
            from None
    finally:
        results.close()
        if bar is not None:
            bar.close()
    result = summarize(n, seed, target_source, [done[i] for i in sorted(done)], corners,
                       structures)
    if store is not None:
        store.finish(result)
    return result


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a campaign: ``kept`` of ``n`` runs finished (in ``runs_path``)."""

    def __init__(self, kept: int, n: int, runs_path: str | None) -> None:
        super().__init__(kept, n, runs_path)
        self.kept, self.n, self.runs_path = kept, n, runs_path

    def __str__(self) -> str:
        where = f' in {self.runs_path} (--resume continues)' if self.runs_path else ''
        return f'interrupted: {self.kept} of {self.n} runs finished{where}'
