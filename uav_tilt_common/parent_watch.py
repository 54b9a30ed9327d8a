"""Nodes that scripts/launch.sh starts end with it, even when it is killed with SIGKILL.

launch.sh exports its pid as ``UAV_TILT_PARENT_PID``; a node that finds it asks the kernel
to send it SIGTERM when its parent exits (Linux ``prctl(PR_SET_PDEATHSIG)``), which rclpy
turns into a clean shutdown. Nodes started any other way (``ros2 run``, a terminal, nohup)
are left alone.
"""
import ctypes
import os
import signal
import sys

PARENT_ENV = 'UAV_TILT_PARENT_PID'
PR_SET_PDEATHSIG = 1


def die_with_parent():
    """Arm the parent-death signal when ``UAV_TILT_PARENT_PID`` is set; returns whether it
    was armed. Exits at once when that parent is already gone. The variable is removed, so
    that what this process starts does not take this process's parent for its own."""
    pid = os.environ.pop(PARENT_ENV, '')
    if not pid.isdigit() or not sys.platform.startswith('linux'):
        return False
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0) != 0:
        print(f'[parent_watch] prctl(PR_SET_PDEATHSIG) failed: '
              f'{os.strerror(ctypes.get_errno())}', file=sys.stderr, flush=True)
        return False
    if os.getppid() != int(pid):     # it died before the signal was armed
        sys.exit(128 + signal.SIGTERM)
    return True
