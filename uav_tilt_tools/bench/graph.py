"""``uav-tilt bench graph``: the node graph of the inspection mission, timed.

The graph is what ``scripts/launch.sh --mission inspect`` starts (plant, controller, vision,
the mission watcher; no recorder), with vision in the loop: the camera at its default 30 Hz
and 320x240, the controller's target from vision. First in lockstep, then with
``--realtime`` (real-time scheduling included where permitted), each for ``sim_s`` of
simulated time measured once a second is simulated and vision has processed frames
(start-up, discovery and the detector's loading excluded). Rates
are per second of wall time; ``cpu_s_per_sim_s`` is each node's CPU time (user + system,
all threads, from /proc/<pid>/stat, the processes it started included) per simulated
second; the loop's period jitter is the median of the controller's p99 over the statuses
of the window. The realtime run is made
again with the camera drawn on the plant's tick (``camera_process`` off, the ``*_on_tick``
keys), the reference the camera's own process is measured against, in the same run.
"""
import functools
import os
import signal
import subprocess
import time
from typing import Any, Callable, Iterable

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped

from uav_tilt_common import names, ros_msgs, ros_qos

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LAUNCH = os.path.join(REPO, 'scripts', 'launch.sh')
# node -> what its command line contains (console script or python -m module)
NODES = {'plant': 'plant_node', 'controller': 'controller_node', 'vision': 'vision_node'}
# Simulated seconds before the measurement starts, and the wall-clock limit of each part.
WARM_UP_S = 1.0
START_TIMEOUT_S = 120.0


def cpu_s(pid: int) -> float:
    """CPU seconds (user + system, all threads) of a process so far."""
    with open(f'/proc/{pid}/stat', encoding='ascii') as stream:
        fields = stream.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def children(parent: int) -> dict[int, str]:
    """{pid: command line} of the processes whose parent is ``parent``."""
    found = {}
    for entry in os.listdir('/proc'):
        try:
            with open(f'/proc/{entry}/stat', encoding='ascii') as stream:
                ppid = int(stream.read().rsplit(')', 1)[1].split()[1])
            if ppid != parent:
                continue
            with open(f'/proc/{entry}/cmdline', 'rb') as stream:
                found[int(entry)] = stream.read().decode(errors='replace')
        except (OSError, ValueError, IndexError):
            continue        # not a process, or gone already
    return found


def node_pids(parent: int) -> dict[str, int]:
    """{node: pid} of the graph's nodes among the children of ``parent``."""
    return {name: pid for pid, cmdline in children(parent).items()
            for name, key in NODES.items() if key in cmdline}


def node_cpu_s(pid: int) -> float:
    """CPU seconds of a node and of the processes it started (the plant's camera)."""
    return cpu_s(pid) + sum(cpu_s(child) for child in children(pid))


def run_graph(mode: str, sim_s: float, extra: Iterable[str] = ()) -> dict[str, Any]:
    """One run in ``mode`` (lockstep | realtime), ``extra`` launch.sh arguments: the
    statistics of the measured window."""
    args = ([LAUNCH, '--mission', 'inspect'] + (['--realtime'] if mode == 'realtime' else [])
            + list(extra))
    launch = subprocess.Popen(args, cwd=REPO, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    rclpy.init()
    node = rclpy.create_node('bench_graph', namespace='/uav')
    latest: dict[str, dict[str, Any]] = {
        names.PLANT_STATUS: {}, names.CONTROLLER_STATUS: {}, names.VISION_STATUS: {}}
    jitters: list[float] = []   # the controller's p99 of each status in the window
    procs: dict[str, int] = {}  # the nodes' pids, once the window starts

    def on_status(msg: Any, values: dict[str, Any]) -> None:
        values.update(ros_msgs.diagnostics_values(msg))
        if procs and 'loop_jitter_ms_p99' in values:
            jitters.append(float(values.pop('loop_jitter_ms_p99')))

    for topic, values in latest.items():
        node.create_subscription(DiagnosticArray, topic,
                                 functools.partial(on_status, values=values), ros_qos.STATUS)
    plant_status, controller, vision = (latest[t] for t in (
        names.PLANT_STATUS, names.CONTROLLER_STATUS, names.VISION_STATUS))
    # vision publishes one target/pose per processed frame
    poses = [0]
    node.create_subscription(PoseWithCovarianceStamped, names.TARGET_POSE,
                             lambda _: poses.__setitem__(0, poses[0] + 1), ros_qos.CONTROL)

    def snapshot() -> dict[str, Any]:
        return dict(wall=time.monotonic(), sim=float(plant_status['sim_time_s']),
                    ticks=int(controller.get('ticks', 0)),
                    frames=poses[0],
                    late=int(plant_status.get('late_commands', 0)),
                    cpu={name: node_cpu_s(pid) for name, pid in procs.items()})

    def spin_until(predicate: Callable[[], bool], timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                raise RuntimeError(f'bench graph ({mode}): timed out')
            rclpy.spin_once(node, timeout_sec=0.02)

    try:
        # up: a second simulated, and vision through its first frames (its model loads
        # while the plant and controller fly already)
        spin_until(lambda: float(plant_status.get('sim_time_s', 0.0)) >= WARM_UP_S
                   and poses[0] > 0 and 'latency_ms_p95' in vision, START_TIMEOUT_S)
        procs.update(node_pids(launch.pid))
        if set(procs) != set(NODES):
            raise RuntimeError(f'bench graph ({mode}): nodes {sorted(procs)} found')
        first = snapshot()
        jitters.clear()
        spin_until(lambda: float(plant_status['sim_time_s']) >= first['sim'] + sim_s,
                   START_TIMEOUT_S + 20.0 * sim_s)
        last = snapshot()
        # vision's latency statistic covers its last frames, ending with the window
        latency = vision.get('latency_ms_p95')
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        launch.send_signal(signal.SIGINT)      # launch.sh stops every node
        try:
            launch.wait(timeout=30.0)
        except subprocess.TimeoutExpired:
            launch.kill()
            launch.wait()
    wall, sim = last['wall'] - first['wall'], last['sim'] - first['sim']
    return dict(rtf=sim / wall, controller_rate_hz=(last['ticks'] - first['ticks']) / wall,
                vision_fps=(last['frames'] - first['frames']) / wall,
                vision_latency_ms_p95=None if latency is None else float(latency),
                jitter_ms_p99=float(np.median(jitters)) if jitters else None,
                late_commands=last['late'] - first['late'],
                cpu_s_per_sim_s={name: (last['cpu'][name] - first['cpu'][name]) / sim
                                 for name in first['cpu']})


def bench_graph(sim_s: float = 20.0) -> dict[str, Any]:
    """The lockstep keys, then the realtime ones (``realtime_*``)."""
    lockstep = run_graph('lockstep', sim_s)
    realtime = run_graph('realtime', sim_s)
    on_tick = run_graph('realtime', sim_s, ('--param', 'plant.camera_process:=false'))
    result = {key: lockstep[key] for key in ('rtf', 'controller_rate_hz', 'vision_fps',
                                             'vision_latency_ms_p95', 'cpu_s_per_sim_s')}
    result.update(realtime_rtf=realtime['rtf'],
                  realtime_controller_rate_hz=realtime['controller_rate_hz'],
                  realtime_jitter_ms_p99=realtime['jitter_ms_p99'],
                  realtime_late_commands=realtime['late_commands'],
                  realtime_vision_fps=realtime['vision_fps'],
                  realtime_cpu_s_per_sim_s=realtime['cpu_s_per_sim_s'],
                  realtime_jitter_ms_p99_on_tick=on_tick['jitter_ms_p99'],
                  realtime_late_commands_on_tick=on_tick['late_commands'],
                  sim_seconds=sim_s)
    return result
