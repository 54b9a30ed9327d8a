"""``uav-tilt bench graph``: the node graph of the inspection mission, timed.

plant, controller and vision run as processes (as scripts/launch.sh starts them, with the
config/ parameter files; no recorder) with vision in the loop: the camera at its default
30 Hz and 320x240, the controller's target from vision, the mission started at once.
First in lockstep, then in realtime, each for ``sim_s`` of simulated time measured after
the first second (start-up and discovery excluded). Rates are per second of wall time;
``cpu_s_per_sim_s`` is each process's CPU time (user + system, all threads, from
/proc/<pid>/stat) per simulated second.
"""
import os
import signal
import subprocess
import sys
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NODES = {'plant': 'uav_tilt_sim.plant_node', 'controller': 'uav_tilt_control.controller_node',
         'vision': 'uav_tilt_vision.vision_node'}
# Simulated seconds before the measurement starts, and the wall-clock limit of each part.
WARM_UP_S = 1.0
START_TIMEOUT_S = 120.0


def cpu_s(pid):
    """CPU seconds (user + system, all threads) of a process so far."""
    with open(f'/proc/{pid}/stat', encoding='ascii') as stream:
        fields = stream.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def _start(name, params):
    cmd = [sys.executable, '-m', NODES[name], '--ros-args', '-r', '__ns:=/uav',
           '--params-file', os.path.join(REPO, 'config', f'{name}.yaml')]
    if name != 'plant':
        cmd += ['-p', 'use_sim_time:=true']
    for key, value in params.items():
        cmd += ['-p', f'{key}:={value}']
    return subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)


def _stop(procs):
    for proc in procs.values():
        proc.send_signal(signal.SIGINT)
    for proc in procs.values():
        try:
            proc.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def run_graph(mode, sim_s):
    """One run in ``mode`` (lockstep | realtime): the statistics of the measured window."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray

    from uav_tilt_common import names, ros_qos

    # the controller and vision are listening before the plant starts the clock
    procs = {'vision': _start('vision', {}),
             'controller': _start('controller', {'autostart': 'inspect'})}
    rclpy.init()
    node = rclpy.create_node('bench_graph', namespace='/uav')
    latest = {names.PLANT_STATUS: {}, names.CONTROLLER_STATUS: {}, names.VISION_STATUS: {}}
    for topic, values in latest.items():
        node.create_subscription(
            DiagnosticArray, topic,
            lambda msg, values=values: values.update(
                {kv.key: kv.value for kv in msg.status[0].values}), ros_qos.STATUS)
    plant_status, controller, vision = (latest[t] for t in (
        names.PLANT_STATUS, names.CONTROLLER_STATUS, names.VISION_STATUS))

    def snapshot():
        return dict(wall=time.monotonic(), sim=float(plant_status['sim_time_s']),
                    ticks=int(controller.get('ticks', 0)),
                    frames=int(vision.get('frames_processed', 0)),
                    late=int(plant_status.get('late_commands', 0)),
                    cpu={name: cpu_s(proc.pid) for name, proc in procs.items()})

    def spin_until(predicate, timeout_s):
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                raise RuntimeError(f'bench graph ({mode}): timed out')
            rclpy.spin_once(node, timeout_sec=0.02)

    try:
        spin_until(lambda: 'backend' in vision and 'mode' in controller, START_TIMEOUT_S)
        procs['plant'] = _start('plant', {'mode': mode, 'status_rate_hz': 10.0})
        spin_until(lambda: float(plant_status.get('sim_time_s', 0.0)) >= WARM_UP_S,
                   START_TIMEOUT_S)
        first = snapshot()
        spin_until(lambda: float(plant_status['sim_time_s']) >= first['sim'] + sim_s,
                   START_TIMEOUT_S + 20.0 * sim_s)
        last = snapshot()
        # vision's latency statistic covers its last frames, ending with the window
        latency = vision.get('latency_ms_p95')
        jitter = controller.get('loop_jitter_ms_p99')
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        _stop(procs)
    wall, sim = last['wall'] - first['wall'], last['sim'] - first['sim']
    return dict(rtf=sim / wall, controller_rate_hz=(last['ticks'] - first['ticks']) / wall,
                vision_fps=(last['frames'] - first['frames']) / wall,
                vision_latency_ms_p95=None if latency is None else float(latency),
                jitter_ms_p99=None if jitter is None else float(jitter),
                late_commands=last['late'] - first['late'],
                cpu_s_per_sim_s={name: (last['cpu'][name] - first['cpu'][name]) / sim
                                 for name in first['cpu']})


def bench_graph(sim_s=20.0):
    """The lockstep keys, then the realtime ones (``realtime_*``)."""
    lockstep = run_graph('lockstep', sim_s)
    realtime = run_graph('realtime', sim_s)
    result = {key: lockstep[key] for key in ('rtf', 'controller_rate_hz', 'vision_fps',
                                             'vision_latency_ms_p95', 'cpu_s_per_sim_s')}
    result.update(realtime_rtf=realtime['rtf'],
                  realtime_controller_rate_hz=realtime['controller_rate_hz'],
                  realtime_jitter_ms_p99=realtime['jitter_ms_p99'],
                  realtime_late_commands=realtime['late_commands'],
                  realtime_vision_fps=realtime['vision_fps'],
                  realtime_cpu_s_per_sim_s=realtime['cpu_s_per_sim_s'],
                  sim_seconds=sim_s)
    return result
