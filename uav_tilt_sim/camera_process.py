"""The plant's camera drawn in a process of its own, beside the physics.

A frame takes 2-3 ms to draw on a CPU, and the renderer holds the GIL while it draws: on
the plant node's thread it delayed every tick that had a frame (one in ten at 300 Hz and
30 fps) by as much, which is most of the control loop's period jitter in real time. A
:class:`CameraProcess` draws the same world (the scenario, its seed and so its textures and
depth noise) in a child process: the plant hands it the vehicle's pose and arm angles at
tick k (:meth:`Plant.render_state`, nine floats) and steps on; the frame of tick k comes back
through shared memory a few milliseconds later. No ROS here.

A request and its answer are a semaphore each (and the state and the frame in shared
memory), not pipe messages: the plant's side never blocks nor releases the GIL for them,
which, on a plant running far behind its clock, let rclpy's timer thread queue ticks
faster than they were served (its status came seconds late).
"""
import dataclasses
import multiprocessing
import os
import signal
import time
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from multiprocessing.shared_memory import SharedMemory
from multiprocessing.synchronize import Semaphore
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from uav_tilt_sim.camera import CameraConfig
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_sim.scenario import Scenario

START_TIMEOUT_S = 60.0
# How often the camera process checks that the plant is still there, and how long a frame
# may take before the plant checks that the camera process is.
ALIVE_CHECK_S = 0.5
# Under SCHED_FIFO (launch.sh --realtime) the camera runs as vision does, this far below the
# plant: a frame drawn late is a frame late, a tick stepped late delays the control loop.
PRIORITY_BELOW_PLANT = 10
STATE_FLOATS = 9        # Plant.render_state
_STOP = np.nan          # a state whose first float is this ends the camera process


def core_config(config: PlantCoreConfig) -> PlantCoreConfig:
    """The :class:`PlantCoreConfig` part of a config that extends it (the node's)."""
    return PlantCoreConfig(**{f.name: getattr(config, f.name)
                              for f in dataclasses.fields(PlantCoreConfig)})


def _buffers(shm: SharedMemory, cam: CameraConfig
             ) -> tuple[NDArray[np.float64], NDArray[np.uint8], NDArray[np.float32]]:
    """(state, rgb, depth) arrays laid out in ``shm``."""
    buf = shm.buf
    assert buf is not None      # None only once closed
    state = np.ndarray(STATE_FLOATS, np.float64, buf)
    shape = (cam.height, cam.width)
    rgb = np.ndarray((*shape, 3), np.uint8, buf, offset=state.nbytes)
    depth = np.ndarray(shape, np.float32, buf, offset=state.nbytes + rgb.nbytes)
    return state, rgb, depth


def _shared_bytes(cam: CameraConfig) -> int:
    return STATE_FLOATS * 8 + cam.height * cam.width * (3 + 4)


class CameraProcess:
    """Frames of a plant's camera, drawn one at a time by a child process.

    ``config`` (a :class:`PlantCoreConfig`) and ``scenario`` are the plant's. RuntimeError
    when the process does not come up; :meth:`frame` raises it when the process has ended.
    """

    def __init__(self, config: PlantCoreConfig, scenario: Scenario,
                 start_timeout_s: float = START_TIMEOUT_S) -> None:
        context = multiprocessing.get_context('spawn')   # the parent runs DDS threads
        self._shm = SharedMemory(create=True, size=_shared_bytes(config.camera))
        self._state, self._rgb, self._depth = _buffers(self._shm, config.camera)
        self._asked, self._drawn = context.Semaphore(0), context.Semaphore(0)
        conn, child = context.Pipe(duplex=False)
        self._process: BaseProcess | None = context.Process(
            target=_serve, args=(child, self._asked, self._drawn, core_config(config),
                                 scenario, self._shm.name, os.getpid()),
            name='uav_tilt camera', daemon=True)
        self._process.start()
        child.close()
        # (t_s, when asked) of the frame being drawn
        self._pending: tuple[float, float] | None = None
        try:
            if not conn.poll(start_timeout_s):
                raise RuntimeError(f'the camera process did not start within '
                                   f'{start_timeout_s:g} s')
            try:
                self.renderer_name, self.warnings = conn.recv()
            except (EOFError, OSError):
                raise RuntimeError(self._ended()) from None
        except RuntimeError:
            self.close()
            raise
        finally:
            conn.close()

    def _ended(self) -> str:
        exitcode = None if self._process is None else self._process.exitcode
        return f'the camera process ended (exit code {exitcode})'

    def request(self, t_s: float, render_state: Sequence[float]) -> bool:
        """Ask for the frame at ``render_state`` (:meth:`Plant.render_state`), stamped
        ``t_s``; False, and nothing asked, while the last frame is still being drawn."""
        if self._pending is not None:
            return False
        self._state[:] = render_state
        self._pending = (t_s, time.monotonic())
        self._asked.release()
        return True

    def frame(self) -> tuple[float, NDArray[np.uint8], NDArray[np.float32]] | None:
        """(t_s, rgb, depth) of the frame asked for, once drawn (copies), else None."""
        if self._pending is None:
            return None
        if not self._drawn.acquire(block=False):
            if (time.monotonic() - self._pending[1] > ALIVE_CHECK_S
                    and not (self._process is not None and self._process.is_alive())):
                raise RuntimeError(self._ended())
            return None
        t_s, self._pending = self._pending[0], None
        return t_s, self._rgb.copy(), self._depth.copy()

    def close(self) -> None:
        """End the process and release the shared memory."""
        if self._process is None:
            return
        self._state[0] = _STOP
        self._asked.release()
        self._process.join(timeout=5.0)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()
        self._process = None
        del self._state, self._rgb, self._depth  # views: the segment closes only without them
        self._shm.close()
        self._shm.unlink()


def _below_the_plant() -> None:
    """Lower a SCHED_FIFO priority inherited from the plant (see PRIORITY_BELOW_PLANT)."""
    try:
        if os.sched_getscheduler(0) == os.SCHED_FIFO:
            priority = os.sched_getparam(0).sched_priority
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(
                max(1, priority - PRIORITY_BELOW_PLANT)))
    except OSError:
        pass                        # left as it was: lowering is all this is for


def _serve(conn: Connection, asked: Semaphore, drawn: Semaphore, config: PlantCoreConfig,
           scenario: Scenario, shm_name: str, parent_pid: int) -> None:
    """The child: a plant of the same scenario that only renders, one frame a request, until
    the parent asks it to stop or is gone."""
    # the terminal's Ctrl-C reaches the whole process group: stopping is the parent's
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _below_the_plant()
    shm = SharedMemory(name=shm_name)     # the parent's resource tracker unlinks it
    state, rgb_out, depth_out = _buffers(shm, config.camera)
    warnings: list[str] = []
    plant = Plant(config, scenario, warn=warnings.append)
    try:
        plant.start_renderer()
        conn.send((plant.renderer_name, warnings))
        conn.close()
        while True:
            if not asked.acquire(timeout=ALIVE_CHECK_S):
                if os.getppid() != parent_pid:
                    break       # the plant is gone (killed): nobody to draw for
                continue
            if np.isnan(state[0]):
                break
            plant.set_render_state(state.tolist())
            rgb, depth, _ = plant.render()
            rgb_out[...] = rgb
            depth_out[...] = depth
            drawn.release()
    finally:
        plant.close()
        del state, rgb_out, depth_out
        shm.close()
