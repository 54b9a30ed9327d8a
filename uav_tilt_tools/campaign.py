"""`uav-tilt campaign --n N --seed S`: the inspection mission over a randomised world.

Each run is ``uav-tilt fly`` (uav_tilt_tools.fly, the same cores as the nodes) on one draw
of :func:`random_draw`, spread over the CPU cores of this machine (``--backend local``, a
process pool) or over a Ray cluster (``--backend ray``, :mod:`uav_tilt_tools.campaign_ray`);
the JSON (DESIGN section 7) holds n, successes, success_rate, its 95% Wilson interval, the
failures by reason and one entry per run, the same from either backend. Targets come from
ground truth by default; ``--target-source vision`` renders the camera and runs the
deployed detector pipeline in each run. ``--out DIR`` keeps each run as it finishes
(:mod:`uav_tilt_tools.campaign_store`), so that ``--resume`` continues an interrupted
campaign.
With ``--plan FILE --scenario FILE`` each run flies the plan on the scenario's wall and
objects, the rest of the world (seed, wind, noise, model mismatch, the wall's stiffness and
friction) drawn as above.
"""
import collections
import dataclasses
import json
import math
import multiprocessing
import os
import signal
import sys
import tempfile

import numpy as np

from uav_tilt_common.cli_args import INTERRUPTED
from uav_tilt_common.config import ConfigError, from_dict
from uav_tilt_tools.fly import DURATION_S, jsonable
from uav_tilt_tools.mcap_bag import RECORDING_FILE
from uav_tilt_common.targets import OBJECT_CLASSES
from uav_tilt_control.site import HINT_ERROR_M
from uav_tilt_sim.scenario import Scenario, check_scenario, load_scenario
from uav_tilt_common import cli_args
from uav_tilt_tools.campaign_ray import CampaignError, ray_runs

BACKENDS = ('local', 'ray')

# The world a campaign draws from.
START_YAW_DEG = 180.0         # vehicle heading at takeoff, from the direction to the wall
WALL_DISTANCE_M = (2.0, 5.0)
WALL_YAW_DEG = 45.0           # the wall's normal off the line of sight
WALL_INCLINATION_DEG = 25.0
TARGET_HEIGHT_M = (0.8, 2.5)
TARGET_U_M = 1.5              # target within +-1.5 m of the wall's centre line
STIFFNESS_N_PER_M = (500.0, 50000.0)   # log-uniform
FRICTION = (0.2, 1.0)
MEAN_WIND_M_S = 2.0
GUST_PEAK_M_S = 3.0           # 3-sigma gust excursion
MASS_MISMATCH = 0.15
LOOKALIKE_PROB = 0.3          # a second bolt plate; the draw then has a hint (a plan)


def random_draw(seed, corners=False):
    """(scenario, hint) of one randomised world: the hint (u, v on the wall, within
    HINT_ERROR_M of the target) when the wall carries a look-alike of the target, else None.

    ``corners``: each range (distance, yaw and inclination of the wall, the target's place,
    stiffness, friction, wind, noise, mismatch, start yaw, the hint's error) is drawn at one
    of its two ends, where failures gather; directions (where the wall and the wind are)
    and the other objects stay uniform."""
    rng = np.random.default_rng(seed)
    draw = _range_ends(rng) if corners else rng.uniform
    distance = draw(*WALL_DISTANCE_M)
    bearing = rng.uniform(-np.pi, np.pi)           # where the wall is, seen from the start
    wall_yaw = np.degrees(bearing) + draw(-WALL_YAW_DEG, WALL_YAW_DEG)
    target_u, target_v = draw(-TARGET_U_M, TARGET_U_M), draw(*TARGET_HEIGHT_M)
    objects = [dict(cls='bolt_plate', u_m=target_u, v_m=target_v, target=True)]
    taken = [(target_u, target_v)]
    hint = None
    if rng.random() < LOOKALIKE_PROB:
        u, v = _free_spot(rng, taken, 0.8, 1.5)
        objects.append(dict(cls='bolt_plate', u_m=u, v_m=v))
        hint = [target_u + draw(-HINT_ERROR_M, HINT_ERROR_M),
                target_v + draw(-HINT_ERROR_M, HINT_ERROR_M)]
    others = [c for c in OBJECT_CLASSES if c != 'bolt_plate']
    for _ in range(int(rng.integers(1, 3))):
        u, v = _free_spot(rng, taken, 0.45, 1.0)
        objects.append(dict(cls=str(rng.choice(others)), u_m=u, v_m=v))
    gust_std = draw(0.0, GUST_PEAK_M_S / 3.0)
    heading = rng.uniform(0.0, 2 * np.pi)
    mean = draw(0.0, MEAN_WIND_M_S)
    data = dict(
        seed=int(seed),
        start_yaw_deg=float(_wrap_deg(np.degrees(bearing)
                                      + draw(-START_YAW_DEG, START_YAW_DEG))),
        wall=dict(position_m=[float(distance * np.cos(bearing)),
                              float(distance * np.sin(bearing))],
                  yaw_deg=float(_wrap_deg(wall_yaw)),
                  inclination_deg=float(draw(-WALL_INCLINATION_DEG, WALL_INCLINATION_DEG)),
                  width_m=6.0,
                  stiffness_n_per_m=_log_uniform(draw, *STIFFNESS_N_PER_M),
                  friction=float(draw(*FRICTION))),
        objects=objects,
        wind=dict(mean_m_s=[float(mean * np.cos(heading)), float(mean * np.sin(heading)), 0.0],
                  gust_std_m_s=float(gust_std), gust_tau_s=float(draw(0.5, 2.0))),
        noise=dict(imu_gyro_rad_s=float(draw(0, 0.005)),
                   imu_accel_m_s2=float(draw(0, 0.1)),
                   odom_pos_m=float(draw(0, 0.002)),
                   odom_att_rad=float(draw(0, 0.003)),
                   ft_force_n=float(draw(0, 0.1)),
                   depth_m=float(draw(0, 0.003))),
        mismatch=dict(mass_scale=float(draw(1 - MASS_MISMATCH, 1 + MASS_MISMATCH)),
                      inertia_scale=float(draw(0.85, 1.15))),
    )
    return check_scenario(from_dict(Scenario, data)), hint


def _range_ends(rng):
    """A stand-in for ``rng.uniform(lo, hi)`` that gives lo or hi, each half the time."""
    return lambda lo, hi: float(hi if rng.random() < 0.5 else lo)


def _log_uniform(draw, lo, hi):
    """Log-uniform in [lo, hi] with ``draw`` = ``rng.uniform``; exactly an end with
    ``_range_ends`` (exp(log(500)) is not 500)."""
    return float(lo * (hi / lo) ** draw(0.0, 1.0))


def _free_spot(rng, taken, min_gap_m, spread_m):
    """(u, v) on the wall at least ``min_gap_m`` (in u or v) from every taken spot, near the
    first one; appended to ``taken``."""
    u0, v0 = taken[0]
    while True:
        u = u0 + rng.uniform(-spread_m, spread_m)
        v = float(np.clip(v0 + rng.uniform(-0.6, 0.6), 0.5, 2.9))
        if all(max(abs(u - a), abs(v - b)) >= min_gap_m for a, b in taken):
            taken.append((u, v))
            return float(u), v


def _wrap_deg(angle):
    return (angle + 180.0) % 360.0 - 180.0


def with_conditions(scenario, drawn):
    """``scenario``'s wall and objects under the seed, wind, noise, mismatch and wall
    contact of the drawn scenario ``drawn`` (a plan's campaign)."""
    wall = dataclasses.replace(scenario.wall, stiffness_n_per_m=drawn.wall.stiffness_n_per_m,
                               friction=drawn.wall.friction)
    return dataclasses.replace(scenario, seed=drawn.seed, wall=wall, wind=drawn.wind,
                               noise=drawn.noise, mismatch=drawn.mismatch)


def run_one(job):
    """One campaign run (top level so that worker processes can pickle it): (the run's
    dict, the bytes of its MCAP recording when ``job['record']``, else None)."""
    # Imported here so that each worker process builds its own physics server.
    from uav_tilt_tools.fly import fly, site_overrides
    scenario, hint = random_draw(job['seed'], job['corners'])
    overrides = site_overrides(scenario, hint) if hint is not None else {}
    with tempfile.TemporaryDirectory(prefix='uav_tilt_run_') as tmp:
        if job['plan_file']:
            scenario = with_conditions(load_scenario(job['scenario_file']), scenario)
            hint, overrides = None, {**site_overrides(scenario), 'plan_file': job['plan_file']}
        result = fly(scenario, job['target_source'], overrides, job['duration_s'],
                     threads=job['threads'], record=tmp if job['record'] else None)
        bag = None
        if job['record']:
            with open(os.path.join(tmp, RECORDING_FILE), 'rb') as stream:
                bag = stream.read()
    result.update(index=job['index'], seed=job['seed'], hint_uv_m=hint,
                  wall_distance_m=float(np.hypot(*scenario.wall.position_m)),
                  wall_yaw_deg=scenario.wall.yaw_deg,
                  wall_inclination_deg=scenario.wall.inclination_deg,
                  wall_stiffness_n_per_m=scenario.wall.stiffness_n_per_m,
                  mass_scale=scenario.mismatch.mass_scale)
    return result, bag


def wilson_interval(successes, n, z=1.96):
    """95% Wilson score interval (low, high) of a success rate."""
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    centre = p + z * z / (2 * n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    # all or none: the bound on that side is exactly 1 or 0 (rounding would put the rate
    # itself outside its interval)
    low = 0.0 if successes == 0 else (centre - half) / (1 + z * z / n)
    high = 1.0 if successes == n else (centre + half) / (1 + z * z / n)
    return low, high


def jobs_of(n, seed, target_source='ground_truth', duration_s=None, threads=0,
            record=False, plan_file=None, scenario_file=None, corners=False):
    """The ``n`` runs of campaign ``seed``: one world seed each, by run index."""
    seeds = np.random.default_rng(seed).integers(0, 2**31 - 1, size=n)
    return [dict(index=i, seed=int(s), target_source=target_source, duration_s=duration_s,
                 threads=threads, record=record, plan_file=plan_file,
                 scenario_file=scenario_file, corners=corners) for i, s in enumerate(seeds)]


def campaign(n, seed, workers=None, target_source='ground_truth', duration_s=None,
             progress=True, backend='local', address=None, out=None, resume=False,
             record=False, plan_file=None, scenario_file=None, corners=False):
    """Run ``n`` randomised missions (of the plan ``plan_file`` on ``scenario_file``'s
    wall when given; ``duration_s`` None: the plan's (:func:`fly.default_duration_s`);
    ``corners``: worlds at the ends of every range, :func:`random_draw`); returns the
    DESIGN section 7 JSON dict.

    ``backend``: 'local' (a process pool of ``workers``, default one per core) or 'ray'
    (one Ray task per run on a local Ray of ``workers`` CPUs, or on the cluster at
    ``address``). ``out``: a folder that gets one JSON line per finished run
    (:mod:`uav_tilt_tools.campaign_store`; with ``record``, an MCAP per run);
    ``resume`` skips the runs it already holds. Runs are counted once each, by index.
    Ctrl-C raises :class:`Interrupted` after keeping what finished.
    """
    if backend not in BACKENDS:
        raise ConfigError(f'backend {backend!r}: expected one of {BACKENDS}')
    if record and out is None:
        raise ConfigError('recording needs an output folder (--out DIR)')
    if resume and out is None:
        raise ConfigError('resuming needs the campaign\'s output folder (--out DIR)')
    if address is not None and backend != 'ray':
        raise ConfigError('an address (--address) needs the ray backend (--backend ray)')
    cpus = os.cpu_count() or 1
    if backend == 'ray':
        runner = ray_runs
        threads = 1                     # each task gets one CPU
    else:
        runner = _local_runs
        workers = workers or min(n, cpus)
        threads = max(1, cpus // max(workers, 1))
    jobs = jobs_of(n, seed, target_source, duration_s, threads, record, plan_file,
                   scenario_file, corners)
    store = None
    if out is not None:
        from uav_tilt_tools.campaign_store import RunStore, file_digests
        # files as the same path however written ('./a.yaml', 'a.yaml', absolute), and what
        # they hold, for the resume
        args = dict(n=n, seed=seed, target_source=target_source, duration_s=duration_s,
                    plan_file=plan_file and os.path.realpath(plan_file),
                    scenario_file=scenario_file and os.path.realpath(scenario_file),
                    **file_digests(plan_file=plan_file, scenario_file=scenario_file))
        if corners:     # only then, so that folders of earlier campaigns still resume
            args['corners'] = True
        store = RunStore(out, args, resume)
    done = store.runs_of(jobs) if store is not None else {}
    todo = [job for job in jobs if job['index'] not in done]
    bar = None
    if progress:
        from tqdm import tqdm
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
    result = summarize(n, seed, target_source, [done[i] for i in sorted(done)], corners)
    if store is not None:
        store.finish(result)
    return result


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a campaign: ``kept`` of ``n`` runs finished (in ``runs_path``)."""

    def __init__(self, kept, n, runs_path):
        super().__init__(kept, n, runs_path)
        self.kept, self.n, self.runs_path = kept, n, runs_path

    def __str__(self):
        where = f' in {self.runs_path} (--resume continues)' if self.runs_path else ''
        return f'interrupted: {self.kept} of {self.n} runs finished{where}'


def summarize(n, seed, target_source, runs, corners=False):
    """The campaign JSON of its ``runs`` (by index): a success is a run that met the
    inspection bar (no ``failure``)."""
    successes = sum(r['failure'] is None for r in runs)
    low, high = wilson_interval(successes, n)
    failures = collections.Counter(f"{r['failure']['reason']} in {r['failure']['mode']}"
                                   for r in runs if r['failure'] is not None)
    return dict(n=n, seed=seed, target_source=target_source, corners=corners,
                successes=successes,
                success_rate=successes / n if n else 0.0, success_rate_ci95=[low, high],
                failures=dict(failures), runs=runs)


def _local_runs(run_one, jobs, workers, address=None):
    """``run_one(job)`` of each job as it finishes, from a spawn process pool."""
    if not jobs:
        return
    with multiprocessing.get_context('spawn').Pool(workers, initializer=_ignore_sigint) as pool:
        yield from pool.imap_unordered(run_one, jobs)
        # every run is in: the workers end on their own. The pool's terminate would send
        # SIGTERM to workers already in their interpreter's exit, where the SystemExit it
        # raises is a traceback from an exit hook (torch's, with vision).
        pool.close()
        pool.join()


def _ignore_sigint():
    # Ctrl-C reaches the whole process group: the parent keeps what finished and
    # terminates the pool, instead of every worker printing a traceback. The pool ends a
    # worker with SIGTERM: leaving by SystemExit, it removes its run's temporary folder.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _leave)


def _leave(signum, frame):
    raise SystemExit(128 + signum)


def register(sub):
    """Add the `campaign` sub-command."""
    parser = sub.add_parser('campaign', help='the mission over randomised scenarios (JSON)')
    parser.add_argument('--n', type=cli_args.count, default=20)
    parser.add_argument('--seed', type=cli_args.seed, default=0)
    parser.add_argument('--workers', type=cli_args.count, default=None,
                        help='runs at once (local) or CPUs of the local Ray; default: cores')
    parser.add_argument('--backend', choices=BACKENDS, default='local',
                        help='ray: one Ray task per run (pip install uav_tilt[ray])')
    parser.add_argument('--address', default=None,
                        help="with --backend ray: join this cluster ('auto', HOST:6379)")
    parser.add_argument('--out', default=None, metavar='DIR',
                        help='write one JSON line per finished run to DIR/runs.jsonl')
    parser.add_argument('--resume', action='store_true',
                        help='skip the runs DIR/runs.jsonl already holds')
    parser.add_argument('--record', action='store_true',
                        help='one MCAP per run: DIR/run_NNNN/recording.mcap')
    parser.add_argument('--duration', type=cli_args.duration_s, default=None,
                        help=f'simulated seconds allowed per mission (default {DURATION_S:.0f}'
                             f' per task and the time it pushes beyond the default hold)')
    parser.add_argument('--plan', type=cli_args.path, default=None, metavar='FILE',
                        help='fly this inspection plan (needs --scenario) in every run')
    parser.add_argument('--scenario', type=cli_args.path, default=None, metavar='FILE',
                        help="with --plan: the scenario whose wall and objects it names")
    parser.add_argument('--target-source', choices=('ground_truth', 'vision'),
                        default='ground_truth',
                        help='vision: render the camera and run the deployed detector')
    parser.add_argument('--corners', action='store_true',
                        help='draw every range of the world at one of its ends')
    parser.set_defaults(func=_run)


def _run(args):
    if bool(args.plan) != bool(args.scenario):
        print('uav-tilt campaign: --plan and --scenario go together', file=sys.stderr)
        return 2
    if args.plan:
        from uav_tilt_tools.fly import check_plan, check_world
        try:
            scenario = load_scenario(args.scenario)
            check_plan(scenario, args.plan)
            check_world(scenario)
        except (OSError, ConfigError) as err:
            print(f'uav-tilt campaign: {err}', file=sys.stderr)
            return 2
    try:
        result = campaign(args.n, args.seed, args.workers, args.target_source, args.duration,
                          backend=args.backend, address=args.address, out=args.out,
                          resume=args.resume, record=args.record, plan_file=args.plan,
                          scenario_file=args.scenario, corners=args.corners)
    except ConfigError as err:
        print(f'uav-tilt campaign: {err}', file=sys.stderr)
        return 2
    except CampaignError as err:
        print(f'uav-tilt campaign: {err}', file=sys.stderr)
        return 1
    except Interrupted as err:
        print(f'uav-tilt campaign: {err}', file=sys.stderr)
        return INTERRUPTED
    print(json.dumps(result, default=jsonable))
    return 0 if result['n'] else 1
