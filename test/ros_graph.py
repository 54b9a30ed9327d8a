"""Helpers for ROS graph tests: node processes in namespace /uav, and an in-process probe."""
import os
import signal
import subprocess
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def start(module, *args, params=None, log_path=None):
    """Start ``python -m module`` as a node in /uav with ``params`` (name -> value)."""
    cmd = [sys.executable, '-m', module, *args, '--ros-args', '-r', '__ns:=/uav']
    for name, value in (params or {}).items():
        cmd += ['-p', f'{name}:={value}']
    log = open(log_path, 'w') if log_path else subprocess.DEVNULL
    return subprocess.Popen(cmd, cwd=REPO, stdout=log, stderr=subprocess.STDOUT,
                            env=dict(os.environ, PYTHONUNBUFFERED='1'))


def alive(pid):
    """Whether ``pid`` runs (a zombie waiting for its new parent to reap it does not)."""
    try:
        with open(f'/proc/{pid}/stat') as stream:
            return stream.read().rsplit(')', 1)[1].split()[0] != 'Z'
    except (OSError, IndexError):
        return False


def children(pid):
    """pid -> command line of the processes whose parent is ``pid``."""
    found = {}
    for entry in os.listdir('/proc'):
        try:
            with open(f'/proc/{entry}/stat') as stream:
                ppid = int(stream.read().rsplit(')', 1)[1].split()[1])
            if ppid == pid:
                with open(f'/proc/{entry}/cmdline', 'rb') as stream:
                    found[int(entry)] = stream.read().replace(b'\0', b' ').decode()
        except (OSError, ValueError, IndexError):
            continue        # not a process, or it is gone already
    return found


def stop(proc, timeout_s=5.0):
    """SIGINT a process and return (exit code, seconds it took); kill it if it hangs."""
    if proc.poll() is not None:
        return proc.returncode, 0.0
    start_time = time.monotonic()
    proc.send_signal(signal.SIGINT)
    try:
        code = proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        code = None
    return code, time.monotonic() - start_time


class Probe:
    """An in-process node that records messages of the /uav topics it is asked for."""

    def __init__(self, name='probe'):
        rclpy.init()
        self.node = rclpy.create_node(name, namespace='/uav')
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.messages = {}

    def record(self, topic, msg_type, qos):
        self.messages[topic] = []
        self.node.create_subscription(msg_type, topic, self.messages[topic].append, qos)

    def spin_until(self, predicate, timeout_s):
        """Spin until predicate() is true; returns whether it became true in time."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.05)
        return predicate()

    def latest_status(self, topic):
        """key -> value of the newest DiagnosticArray recorded on ``topic`` ({} if none)."""
        msgs = self.messages.get(topic)
        return status_values(msgs[-1]) if msgs else {}

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown()


def status_values(msg):
    """key -> value of the first status of a DiagnosticArray."""
    return {kv.key: kv.value for kv in msg.status[0].values}
