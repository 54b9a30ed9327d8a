"""Nodes that scripts/launch.sh starts end with it, even when it is killed with SIGKILL.

launch.sh exports its pid as ``UAV_TILT_PARENT_PID``; a node that finds it asks the kernel
to send it SIGTERM when its parent exits (Linux ``prctl(PR_SET_PDEATHSIG)``), which rclpy
turns into a clean shutdown. Should that shutdown hang, the node ends itself after
``UAV_TILT_GRACE_S`` (5 s), printing every thread's stack: what launch.sh's own SIGKILL
would have done after the same grace, had it been alive. Nodes started any other way
(``ros2 run``, a terminal, nohup) are left alone.
"""
import ctypes
import faulthandler
import os
import select
import signal
import sys
import threading

PARENT_ENV = 'UAV_TILT_PARENT_PID'
GRACE_ENV = 'UAV_TILT_GRACE_S'
GRACE_S = 5.0
PR_SET_PDEATHSIG = 1


def die_with_parent() -> bool:
    """Arm the parent-death signal when ``UAV_TILT_PARENT_PID`` is set; returns whether it
    was armed. Exits at once when that parent is already gone. The variable is removed, so
    that what this process starts does not take this process's parent for its own."""
    pid = os.environ.pop(PARENT_ENV, '')
    if not pid.isdigit() or not sys.platform.startswith('linux'):
        return False
    parent = int(pid)
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0) != 0:
        print(f'[parent_watch] prctl(PR_SET_PDEATHSIG) failed: '
              f'{os.strerror(ctypes.get_errno())}', file=sys.stderr, flush=True)
        return False
    if os.getppid() != parent:     # it died before the signal was armed
        sys.exit(128 + signal.SIGTERM)
    try:
        parent_fd = os.pidfd_open(parent)
    except ProcessLookupError:     # it died (and was reaped) since
        sys.exit(128 + signal.SIGTERM)
    except OSError:                # no pidfd (Linux < 5.3): the signal alone, no backstop
        return True
    threading.Thread(target=_end_after_grace, args=(parent_fd, parent, _grace_s()),
                     daemon=True, name='parent_watch').start()
    return True


def _grace_s() -> float:
    """launch.sh's grace (``UAV_TILT_GRACE_S``), the default when unset or not a number."""
    try:
        grace = float(os.environ.get(GRACE_ENV, GRACE_S))
    except ValueError:
        return GRACE_S
    return grace if grace > 0.0 else GRACE_S


def _end_after_grace(parent_fd: int, parent_pid: int, grace_s: float) -> None:
    """Block until the parent has exited (its pidfd turns readable), then leave the clean
    shutdown ``grace_s``: faulthandler's watchdog, a C thread that needs no GIL, dumps the
    stacks and exits should the process still run then. A clean exit ends it first."""
    select.select([parent_fd], [], [])
    print(f'[parent_watch] parent (pid {parent_pid}) is gone: stopping, or ending in '
          f'{grace_s:g} s should the shutdown hang', file=sys.stderr, flush=True)
    faulthandler.dump_traceback_later(grace_s, exit=True)
