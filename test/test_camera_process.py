"""The camera drawn in a process of its own (uav_tilt_sim.camera_process): the frames the
plant draws itself, one at a time, and a process that ends with its parent."""
import os
import signal
import subprocess
import sys
import textwrap
import time
from multiprocessing.shared_memory import SharedMemory

import numpy as np
import pytest

from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_sim.camera_process import CameraProcess
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_sim.scenario import load_scenario


def _drawn(camera, timeout_s=30.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        frame = camera.frame()
        if frame is not None:
            return frame
        time.sleep(0.001)
    raise AssertionError('no frame from the camera process')


def test_the_process_draws_the_frames_the_plant_draws_itself():
    scenario = load_scenario()
    scenario.noise.depth_m = 0.01        # the depth noise comes from the scenario's seed too
    config = PlantCoreConfig()
    plant = Plant(config, scenario)
    camera = CameraProcess(config, scenario)
    try:
        assert camera.renderer_name == 'gl' and camera.warnings == []
        # climb, the arms tilted unevenly (the body turns): the frames differ from the start's
        plant.set_actuator_state(np.array([1.3, 1.2, 1.3, 1.2]) * VehicleParams().hover_thrust_n,
                                 0.3, -0.2)
        plant.step()
        frames = []
        for _ in range(3):
            for _ in range(30):
                plant.step()
            assert camera.request(plant.t_s, plant.render_state())
            # one frame at a time: asked again before it is drawn, nothing is asked
            assert not camera.request(plant.t_s, plant.render_state())
            t_s, rgb, depth = _drawn(camera)
            own_rgb, own_depth, _ = plant.render()
            assert t_s == plant.t_s
            np.testing.assert_array_equal(rgb, own_rgb)
            np.testing.assert_array_equal(depth, own_depth)
            frames.append(rgb)
        assert camera.frame() is None           # nothing more was asked
        assert not np.array_equal(frames[0], frames[-1])
    finally:
        camera.close()
        plant.close()
    with pytest.raises(FileNotFoundError):     # the shared frame is gone with it
        SharedMemory(name=camera._shm.name)


CHILD = textwrap.dedent('''
    import sys
    from uav_tilt_sim.camera_process import CameraProcess
    from uav_tilt_sim.plant import PlantCoreConfig
    from uav_tilt_sim.scenario import load_scenario
    camera = CameraProcess(PlantCoreConfig(), load_scenario())
    print(camera._process.pid, flush=True)
    sys.stdin.read()
''')


def _alive(pid):
    try:
        with open(f'/proc/{pid}/stat', encoding='ascii') as stream:
            return stream.read().rsplit(')', 1)[1].split()[0] != 'Z'
    except FileNotFoundError:
        return False


@pytest.mark.parametrize('how', ['sigkill', 'sigint'])
def test_the_camera_process_ends_with_its_parent(how):
    """A parent killed outright, or a terminal's Ctrl-C to the group: the camera process
    ends too (its pipe closes), without a traceback of its own."""
    # SIGINT as a terminal delivers it: a shell's background jobs (CI) start with it ignored
    parent = subprocess.Popen([sys.executable, '-c', CHILD], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              start_new_session=True,
                              preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        pid = int(parent.stdout.readline())
        assert _alive(pid)
        if how == 'sigkill':
            parent.kill()
        else:
            os.killpg(parent.pid, signal.SIGINT)
        parent.wait(timeout=30)
        deadline = time.monotonic() + 10.0
        while _alive(pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _alive(pid)
        stderr = parent.stderr.read()
        assert stderr.count('Traceback') == (how == 'sigint'), stderr   # the parent's own
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()
