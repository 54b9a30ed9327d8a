"""`uav-tilt bench sim`: real-time factors of the plant (DESIGN section 7).

rtf_physics: the plant core's tick (physics substeps + sensors), no camera, no ROS.
rtf_camera: the same with the RGB-D camera rendered at its rate (30 Hz).
rtf_ros_lockstep: plant_node and a hover client in two processes, lockstep, no camera.
render_ms_p50: one RGB-D frame of the plant's renderer (GL); render_ms_p50_tinyrenderer:
the same views drawn by TinyRenderer, the two timed in turns in the same run;
render_ms_p50_structures (and _tinyrenderer): the same in the world of structures
(config/scenarios/structures.yaml: two pipes, a tank, a pillar, an I-beam mesh).
"""
import json
import os
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np

from uav_tilt_common.state import ActuatorCommand
from uav_tilt_sim import camera as cam_mod
from uav_tilt_sim.plant import Plant, PlantCoreConfig
from uav_tilt_sim.scenario import load_scenario

RENDER_ROUNDS = 5
STRUCTURES = 'config/scenarios/structures.yaml'


def _hover_plant(scenario_file: str | None = None) -> tuple[Plant, ActuatorCommand]:
    scenario = load_scenario(scenario_file)
    scenario.start_xyz_m = [0.0, 0.0, 1.5]
    plant = Plant(PlantCoreConfig(), scenario)
    hover = np.full(4, plant.mass_kg * 9.80665 / 4)
    plant.set_actuator_state(hover, 0.0, 0.0)
    return plant, ActuatorCommand(hover)


def core_rtf(seconds: float, camera: bool) -> float:
    """Simulated seconds per wall second of the in-process plant."""
    plant, command = _hover_plant()
    every = round(plant.config.control_hz / plant.config.camera.rate_hz)
    ticks = int(seconds * plant.config.control_hz)
    start = time.perf_counter()
    for tick in range(ticks):
        plant.step(command)
        plant.read_sensors()
        if camera and tick % every == 0:
            plant.render()
    wall = time.perf_counter() - start
    plant.close()
    return ticks * plant.dt_tick / wall


def render_ms(frames: int, scenario_file: str | None = None) -> tuple[float, float, str]:
    """(p50 of the plant's renderer, p50 of TinyRenderer) in ms over ``frames`` views of
    the vehicle drifting before the wall (the structures of ``scenario_file``), the two
    taking turns in blocks."""
    plant, command = _hover_plant(scenario_file)
    plant.external_force_map = np.array([0.3, 0.2, 0.0])
    tiny = cam_mod.TinyRenderer(plant.config.camera)
    plant.render()          # the renderer's start-up is not a frame
    name = plant.renderer_name
    times: dict[str, list[float]] = {'plant': [], 'tiny': []}
    try:
        for _ in range(RENDER_ROUNDS):
            for which, out in times.items():
                for _ in range(frames // RENDER_ROUNDS):
                    for _ in range(10):
                        plant.step(command)
                    start = time.perf_counter()
                    if which == 'plant':
                        plant.render()
                    else:
                        cam_mod.render_with(tiny, plant.scene, *plant.camera_pose())
                    out.append((time.perf_counter() - start) * 1e3)
    finally:
        plant.close()
    return float(np.median(times['plant'])), float(np.median(times['tiny'])), name


def ros_lockstep_rtf(ticks: int) -> float:
    """Real-time factor of plant_node + hover_driver in lockstep (separate processes)."""
    ros_args = ['--ros-args', '-r', '__ns:=/uav']
    with tempfile.TemporaryDirectory() as tmp:
        report = os.path.join(tmp, 'driver.json')
        plant = subprocess.Popen(
            [sys.executable, '-m', 'uav_tilt_sim.plant_node', *ros_args,
             '-p', 'camera_enabled:=false'],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            subprocess.run([sys.executable, '-m', 'uav_tilt_tools.graph.hover_driver',
                            '--ticks', str(ticks), '--out', report, *ros_args], check=True,
                           timeout=600)
            with open(report, encoding='utf-8') as stream:
                return json.load(stream)['rtf']
        finally:
            plant.terminate()
            plant.wait(timeout=10)


def bench_sim(seconds: float = 10.0) -> dict[str, Any]:
    """All three factors, plus the ROS overhead as a ratio to the core in the same run."""
    physics = core_rtf(seconds, camera=False)
    camera = core_rtf(seconds / 2, camera=True)
    ros = ros_lockstep_rtf(int(seconds * 300))
    frames = max(int(seconds * 10), RENDER_ROUNDS)
    render, tiny, renderer = render_ms(frames)
    structures, structures_tiny, _ = render_ms(frames, STRUCTURES)
    return {
        'rtf_physics': round(physics, 2),
        'rtf_camera': round(camera, 2),
        'rtf_ros_lockstep': round(ros, 2),
        'ros_lockstep_vs_physics': round(ros / physics, 3),
        'render_ms_p50': round(render, 2),
        'render_ms_p50_tinyrenderer': round(tiny, 2),
        'render_ms_p50_structures': round(structures, 2),
        'render_ms_p50_structures_tinyrenderer': round(structures_tiny, 2),
        'renderer': renderer,
        'sim_seconds': seconds,
    }
