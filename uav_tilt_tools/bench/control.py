"""``uav-tilt bench control``: controller tick cost in-process, and the loop in real time.

tick_us_*: wall time of ControllerCore.tick over a real in-process flight (takeoff, hover,
approach). realtime_*: plant_node (realtime, no camera) and controller_node as processes;
the controller's own loop statistics (IMU callback period in wall time) from its status.
"""
import os
import signal
import subprocess
import sys
import time
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray

from uav_tilt_common import names, ros_qos
from uav_tilt_control.controller_core import ControllerConfig
from uav_tilt_sim.scenario import load_scenario
from uav_tilt_tools.runner.inprocess import Flight

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def bench_tick(ticks: int = 4000) -> tuple[float, float]:
    """(p50, p99) of ControllerCore.tick in microseconds over ``ticks`` ticks of flight."""
    flight = Flight(load_scenario(), ControllerConfig(target_source='ground_truth'))
    try:
        flight.step()
        flight.core.inspect()
        for _ in range(ticks):
            flight.step()
        tick_us = np.asarray(flight.tick_s[1:]) * 1e6
    finally:
        flight.close()
    return float(np.percentile(tick_us, 50)), float(np.percentile(tick_us, 99))


def _start(module: str, params: dict[str, str]) -> subprocess.Popen[bytes]:
    cmd = [sys.executable, '-m', module, '--ros-args', '-r', '__ns:=/uav']
    for name, value in params.items():
        cmd += ['-p', f'{name}:={value}']
    return subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)


def _stop(proc: subprocess.Popen[bytes]) -> None:
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=10.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def bench_realtime(duration_s: float = 30.0) -> tuple[float | None, float | None]:
    """(loop rate Hz, period jitter p99 ms) of controller_node beside a realtime plant."""
    procs = [_start('uav_tilt_sim.plant_node', {'mode': 'realtime', 'camera_enabled': 'false'}),
             _start('uav_tilt_control.controller_node', {'target_source': 'ground_truth',
                                                         'autostart': 'inspect'})]
    rclpy.init()
    node = rclpy.create_node('bench_control', namespace='/uav')
    latest: dict[str, Any] = {}

    def on_status(msg: Any) -> None:
        latest.update({kv.key: kv.value for kv in msg.status[0].values})

    node.create_subscription(DiagnosticArray, names.CONTROLLER_STATUS, on_status,
                             ros_qos.STATUS)
    try:
        # the statistics window starts once the loop runs
        deadline = time.monotonic() + 60.0
        while 'loop_rate_hz' not in latest and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
        end = time.monotonic() + duration_s
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.1)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        for proc in procs:
            _stop(proc)
    if 'loop_rate_hz' not in latest:
        return None, None
    return float(latest['loop_rate_hz']), float(latest['loop_jitter_ms_p99'])


def bench_control(realtime: bool = True, duration_s: float = 30.0) -> dict[str, Any]:
    """DESIGN section 7 keys: tick_us_p50, tick_us_p99, realtime_rate_hz,
    realtime_jitter_ms_p99 (None when ``realtime`` is False or the loop never ran)."""
    p50, p99 = bench_tick()
    rate, jitter = bench_realtime(duration_s) if realtime else (None, None)
    return dict(tick_us_p50=p50, tick_us_p99=p99, realtime_rate_hz=rate,
                realtime_jitter_ms_p99=jitter)
