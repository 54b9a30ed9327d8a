"""Gymnasium environment ``uav_tilt/ContactInspection-v0``: learning the touch on a wall.

``import uav_tilt_tools.gym.env`` registers it, so that
``gymnasium.make('uav_tilt/ContactInspection-v0', **options)`` works;
``gymnasium.make('uav_tilt_tools.gym.env:uav_tilt/ContactInspection-v0')`` imports and
registers in one go (what vector environments in spawned processes need). Options are the
fields of :class:`ContactEnvConfig`.

The environment wraps the in-process plant and controller cores (:class:`Flight`, the same
as the nodes and ``uav-tilt fly``). Each reset draws a world of the campaign
(:func:`uav_tilt_sim.randomise.random_draw`, seeded from the environment's generator), or
with ``scenario`` (a scenario file, checked at make as ``uav-tilt fly`` checks it: it
designates a target, its start is clear of the wall) flies that world, its ``seed`` (the
gusts' and sensors' random streams, and the textures unless it sets ``texture_seed``) drawn
from the environment's generator; and lets the mission fly takeoff, search and approach by
itself; the episode starts when the mission reaches the wall (it enters CONTACT at the
stand-off, facing the target) and covers the touch: CONTACT (close in, creep until the tool
feels the wall, press) and HOLD. With ``start='takeoff'`` the episode is the whole mission
from the ground instead (the action acts near the wall only; a reset is then a fraction of
a second instead of the flight-in's tens of simulated seconds). ``vehicle``
(``vehicle.mass_kg=...``, the node parameters' names) is the vehicle flown and the
controller's model of it, as ``uav-tilt fly --set vehicle.*`` sets it.

``target_source`` is ``ground_truth`` by default, unlike ``fly`` and ``launch.sh``
(``vision``): the environment is for learning the touch at the wall, which the action acts
on, and vision in the loop renders and detects every camera frame of the flight in as well
(measured on 2 shared cores, world seed 3: a reset 17 s instead of 4 s, 69 steps a second
instead of 172). ``target_source='vision'`` flies it with the deployed detector.

**Action: an offset of the impedance law's setpoint, not its gains.** Box(-1, 1, (3,)):
a shift of the desired position lambda_d along the wall (x_t, y_t, up to ``max_offset_m``)
and a change of the push (``ImpedanceSetpoint.push_n``, up to ``max_force_offset_n``; the
law holds it as a depth along -z_t with its own K_z), added to the mission's setpoint in
the target frame at ``action_rate_hz`` and held over the 300 Hz control ticks in between.
Why the setpoint: with fixed gains the closed loop stays eq. (6), a passive
mass-spring-damper about the desired position, whatever the agent does, so a policy can
move where and how hard the tool pushes but cannot destabilise the contact (time-varying K
and C can pump energy into it); and a zero action is exactly the mission's own controller,
the baseline a policy learns a residual to. In HOLD the law's trim
(``flight.impedance.force_tau_s``) brings the measured push to the one asked for, the
agent's change included; set ``controller={'flight.impedance.force_tau_s': 0}`` to leave
the force regulation to the agent.

**Observation** (Dict, float32, what the vehicle measures): ``error_t`` (6,) the impedance
error e, e' of the noisy odometry against the reference the law tracks (the setpoint, the
push's depth behind it) in the target frame of the estimate; ``tip_t`` (3,) the tool tip
in that frame (x, y along the wall from the POI, z off the surface); ``wrench`` (6,) the
F/T reading (ee_link, N and N m); ``push_error_n`` (1,) the measured push along the normal
minus the setpoint; ``phase`` Discrete(5) (close,
touch (with CONTACT's ``align`` pauses), press, hold, other); with ``camera=True`` also
``image`` (H, W, 3) uint8, the eye-in-hand camera at the end of the step.
``render_mode='rgb_array'`` renders that camera. An action that is not three finite
numbers (an array of shape (3,), integer or float) is a ValueError (one beyond [-1, 1] is
clipped); a step after the episode ended is gymnasium's ResetNeeded.

**Reward** (from the simulator's truth): each control tick in HOLD earns
:func:`touch_reward` = 1 - ((push - F_d) / force_scale_n)^2 - poi_error / poi_scale_m
(push: the contact force along the normal; poi_error: the tip's distance from the POI
along the surface, as the mission's metrics measure both), and a step's reward is its
ticks' sum over ``ticks_per_step`` (their mean, but for a last step cut short); so an
episode's return is (HOLD ticks / ticks per step) times one minus
the mission's (force_rms_error_n / force_scale_n)^2 and poi_error_m / poi_scale_m.

**Termination**: the hold completed (every task of the plan ended; the one touch: its
hold), not the retreat and landing after it (the last step is the tick the hold ends on,
when the mission has begun its RETREAT: its phase is ``other``): success when it met the
inspection bar by the truth (:func:`uav_tilt_tools.metrics.tasks.missed_bar`), else a
failure, ``off_target`` or ``force_off_setpoint``; a failsafe of the mission (force limit,
no contact, target lost, stale odometry, upset), the contact lost in HOLD, a push above the
force limit, the vehicle below ``ground_clearance_m`` near the wall or tilted past
``max_tilt_deg``: each a failure, rewarded ``-failure_penalty``. Truncation after
``episode_s`` of simulated time at the wall (from the episode's start; with
``start='takeoff'`` from the mission's arrival at the wall, and before it after
``flight_in_s``). ``info`` has the world seed, the mode and phase, the push and POI error,
and at the end the ``outcome``. ``reset`` takes no options.
"""
import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np
import numpy.typing as npt
from gymnasium import spaces

from uav_tilt_common.config import ConfigError, from_dict, nested, param, to_flat
from uav_tilt_common.geometry import quat_to_matrix
from uav_tilt_common.resources import resolve
from uav_tilt_common.vehicle import VehicleParams, check_vehicle
from uav_tilt_control.controller_core import TARGET_SOURCES, ControllerConfig, plan_of
from uav_tilt_common.modes import Mode
from uav_tilt_control.mission import NEAR_WALL
from uav_tilt_sim.plant import PlantCoreConfig
from uav_tilt_sim.randomise import random_draw
from uav_tilt_sim.scenario import Scenario, check_target, load_scenario
from uav_tilt_tools.metrics.mission import poi_errors_m, push_along_normal
from uav_tilt_tools.metrics.tasks import first_missed_bar
from uav_tilt_tools.runner.fly import check_world
from uav_tilt_tools.runner.inprocess import Flight, mission_result
from uav_tilt_tools.runner.site_params import site_overrides

ENV_ID = 'uav_tilt/ContactInspection-v0'
PHASES = ('close', 'touch', 'press', 'hold', 'other')
STARTS = ('wall', 'takeoff')
ACTING = (Mode.CONTACT, Mode.HOLD, Mode.TARGET_LOST)   # modes the action offsets
LIMIT_M, LIMIT_M_S, LIMIT_N, LIMIT_NM = 20.0, 20.0, 200.0, 20.0   # observation bounds
ERROR_BOUND = np.array([LIMIT_M] * 3 + [LIMIT_M_S] * 3, dtype=np.float32)    # error_t
WRENCH_BOUND = np.array([LIMIT_N] * 3 + [LIMIT_NM] * 3, dtype=np.float32)    # wrench


@dataclasses.dataclass
class ContactEnvConfig:
    """Options of ContactInspection-v0 (``gymnasium.make(ENV_ID, **options)``)."""

    action_rate_hz: float = param(30.0, lo=1.0, hi=300.0,
                                  doc='the control rate (300 Hz) over a whole number of ticks')
    start: str = param('wall', choices=STARTS)          # where an episode begins
    camera: bool = param(False)                         # the camera image in the observation
    # ground_truth, not fly's vision: see the module docstring
    target_source: str = param('ground_truth', choices=TARGET_SOURCES)
    scenario: str = param('', doc="a scenario file to fly at every reset; '': the "
                                  "campaign's random worlds")
    model_path: str = param('')                         # vision: '' = the deployed detector
    detector_threads: int = param(1, lo=0, hi=256)      # 0: the libraries' defaults
    max_offset_m: float = param(0.1, lo=0.0, hi=1.0)    # along the wall
    max_force_offset_n: float = param(3.0, lo=0.0, hi=20.0)
    episode_s: float = param(40.0, lo=0.1, hi=600.0)    # at the wall
    flight_in_s: float = param(150.0, lo=1.0, hi=600.0)  # to reach the wall, else a redraw
    max_redraws: int = param(5, lo=0, hi=100)
    force_scale_n: float = param(5.0, lo=0.01, hi=100.0)
    poi_scale_m: float = param(0.05, lo=1e-4, hi=10.0)
    failure_penalty: float = param(100.0, lo=0.0, hi=1e6)
    ground_clearance_m: float = param(0.2, lo=0.0, hi=10.0)
    max_tilt_deg: float = param(60.0, lo=1.0, hi=180.0)
    # the controller's parameters (uav-tilt fly --set names); its target_source is the above
    # (given here too, it is refused)
    controller: ControllerConfig = nested(ControllerConfig)
    # the vehicle flown and the controller's model of it (fly's --set vehicle.*)
    vehicle: VehicleParams = nested(VehicleParams)


def touch_reward(push_n: npt.ArrayLike, poi_error_m: npt.ArrayLike, setpoint_n: float,
                 force_scale_n: float, poi_scale_m: float) -> np.ndarray | float:
    """The reward of a control tick in HOLD (arrays welcome)."""
    return 1.0 - ((np.asarray(push_n) - setpoint_n) / force_scale_n) ** 2 \
        - np.asarray(poi_error_m) / poi_scale_m


def _box(limit: float, n: int) -> spaces.Box:
    return spaces.Box(-limit, limit, (n,), dtype=np.float32)


class ContactInspectionEnv(gym.Env):
    """The touch task of the inspection mission; see the module docstring."""

    metadata = {'render_modes': ['rgb_array'], 'render_fps': 30}

    def __init__(self, render_mode: str | None = None, **options: Any) -> None:
        if render_mode is not None and render_mode not in self.metadata['render_modes']:
            raise ConfigError(f'render_mode {render_mode!r}: expected one of '
                              f'{self.metadata["render_modes"]} or None')
        self.render_mode = render_mode
        given = options.get('controller')
        if 'controller.target_source' in options or (
                isinstance(given, dict) and 'target_source' in given):
            raise ConfigError("parameter 'controller.target_source': the environment's own "
                              "'target_source' option sets it")
        self.cfg = cfg = from_dict(ContactEnvConfig, options)
        cfg.controller.target_source = cfg.target_source
        check_vehicle(cfg.vehicle)
        plan_of(cfg.controller, cfg.vehicle)    # the push and the plan, as the controller will
        if cfg.model_path:
            resolve(cfg.model_path, 'model_path')
        self.scenario: Scenario | None = None
        if cfg.scenario:
            self.scenario = load_scenario(cfg.scenario, 'scenario')
            check_target(self.scenario)
            check_world(self.scenario, cfg.vehicle)
        self.plant_config = PlantCoreConfig(vehicle=cfg.vehicle)
        control_hz = self.plant_config.control_hz
        self.ticks_per_step = max(1, int(round(control_hz / cfg.action_rate_hz)))
        if not math.isclose(self.ticks_per_step * cfg.action_rate_hz, control_hz):
            raise ConfigError(f"parameter 'action_rate_hz' = {cfg.action_rate_hz!r} must divide "
                              f"the control rate {control_hz:g} Hz into whole ticks")
        self.metadata = dict(self.metadata, render_fps=control_hz / self.ticks_per_step)
        self.action_space = spaces.Box(-1.0, 1.0, (3,), dtype=np.float32)
        obs = dict(error_t=spaces.Box(-ERROR_BOUND, ERROR_BOUND),
                   tip_t=_box(LIMIT_M, 3),
                   wrench=spaces.Box(-WRENCH_BOUND, WRENCH_BOUND),
                   push_error_n=_box(LIMIT_N, 1),
                   phase=spaces.Discrete(len(PHASES)))
        cam = self.plant_config.camera
        if cfg.camera:
            obs['image'] = spaces.Box(0, 255, (cam.height, cam.width, 3), dtype=np.uint8)
        self.observation_space = spaces.Dict(obs)
        self.flight: Flight | None = None
        self._offset_t = np.zeros(3)
        self._offset_push_n = 0.0
        self._setpoint: Any = None  # the controller's last setpoint (the action's offset in)
        self._frame: tuple[int, np.ndarray] | None = None   # (tick, rgb) of the last image
        self._info: dict[str, Any] = {}
        self._ended = False         # the episode terminated or was truncated

    # --- gymnasium API --------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Draw a world, fly the mission to the wall; the first observation there."""
        super().reset(seed=seed)
        if options:
            raise ValueError(f'reset options {options!r}: this environment takes none (its '
                             f'options are gymnasium.make keywords)')
        cfg = self.cfg
        for redraws in range(cfg.max_redraws + 1):
            world_seed = int(self.np_random.integers(0, 2**31 - 1))
            if self._fly_in(world_seed):
                break
        else:
            raise RuntimeError(f'the mission reached no wall in {cfg.max_redraws + 1} draws '
                               f'(last world seed {world_seed})')
        # the time at the wall counts from here; with start='takeoff' from the arrival
        flight_in_s = self._live.t_s
        self._t0_s = flight_in_s if cfg.start == 'wall' else None
        self._ended = False
        self._info = dict(world_seed=world_seed, redraws=redraws, flight_in_s=flight_in_s)
        return self._observation(), self._step_info()

    def step(self, action: Any) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        """Hold the setpoint offset of ``action`` over the ticks of one step."""
        if self.flight is None:
            raise gym.error.ResetNeeded('step() before reset() (or after close())')
        if self._ended:
            raise gym.error.ResetNeeded('step() after the episode ended: call reset()')
        a = np.asarray(action)
        if a.shape != (3,) or not (np.issubdtype(a.dtype, np.integer)
                                   or np.issubdtype(a.dtype, np.floating)):
            raise ValueError(f'action {action!r}: expected 3 numbers in [-1, 1]')
        a = a.astype(float)
        if not np.all(np.isfinite(a)):
            raise ValueError(f'action {a.tolist()} is not finite')
        a = np.clip(a, -1.0, 1.0)
        cfg, flight = self.cfg, self.flight
        self._offset_t = np.array([a[0] * cfg.max_offset_m, a[1] * cfg.max_offset_m, 0.0])
        self._offset_push_n = float(a[2] * cfg.max_force_offset_n)
        reward, outcome = 0.0, None
        for _ in range(self.ticks_per_step):
            flight.step()
            if self._t0_s is None and flight.core.mission.mode == Mode.CONTACT:
                self._t0_s = flight.t_s
            reward += self._tick_reward()
            outcome = self._outcome()
            if outcome is not None:
                break
        reward /= self.ticks_per_step
        terminated = outcome is not None
        if terminated and outcome != 'success':
            reward -= cfg.failure_penalty
        truncated = not terminated and (
            flight.t_s >= cfg.flight_in_s if self._t0_s is None
            else flight.t_s - self._t0_s >= cfg.episode_s)
        info = self._step_info()
        if terminated or truncated:
            info['outcome'] = outcome or 'time_limit'
            self._ended = True
        return self._observation(), float(reward), terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """The eye-in-hand camera (rgb_array), or None without a render mode."""
        if self.render_mode is None or self.flight is None:
            return None
        return self._image()

    def close(self) -> None:
        """Release the physics server."""
        if self.flight is not None:
            self.flight.close()
            self.flight = None

    # --- the episode ------------------------------------------------------------------
    @property
    def _live(self) -> Flight:
        """The episode's flight (there is one from the reset on)."""
        assert self.flight is not None, 'reset() first'
        return self.flight

    def _fly_in(self, world_seed: int) -> bool:
        """A new flight in world ``world_seed`` (flown to the wall unless it starts at the
        takeoff); False if it got none."""
        self.close()
        if self.scenario is None:
            scenario, hint = random_draw(world_seed)
        else:
            scenario, hint = dataclasses.replace(self.scenario, seed=world_seed), None
        config = self.cfg.controller
        if hint is not None:
            config = from_dict(ControllerConfig, {**to_flat(config),
                                                  **site_overrides(scenario, hint)})
        vision = None
        if self.cfg.target_source == 'vision':
            # the vision stack (torch) only for an environment that has vision in the loop
            from uav_tilt_tools.runner.camera_vision import camera_vision
            vision = camera_vision(self.plant_config, self.cfg.model_path,
                                   threads=self.cfg.detector_threads)
        self.flight = flight = Flight(scenario, config, self.cfg.vehicle,
                                      plant_config=self.plant_config, vision=vision)
        self._offset_t, self._offset_push_n = np.zeros(3), 0.0
        self._frame = self._setpoint = None
        flight.core.setpoint_hook = self._offset_setpoint
        flight.step()
        if not flight.core.inspect()[0]:
            return False
        if self.cfg.start == 'takeoff':      # once the controller has a setpoint
            return flight.run(1.0, until=lambda f: self._setpoint is not None)
        mission = flight.core.mission
        flight.run(self.cfg.flight_in_s, until=lambda f: mission.mode in (Mode.CONTACT,
                                                                          Mode.IDLE)
                   or bool(f.status.get('failsafe_reason')))
        return mission.mode == Mode.CONTACT and not flight.status.get('failsafe_reason')

    def _offset_setpoint(self, setpoint: Any) -> Any:
        """The controller's setpoint hook: the action's offset near the wall."""
        if setpoint.contact_gains and self._live.core.mission.mode in ACTING:
            setpoint = dataclasses.replace(setpoint,
                                           lambda_d_t=setpoint.lambda_d_t + self._offset_t,
                                           push_n=setpoint.push_n + self._offset_push_n)
        self._setpoint = setpoint
        return setpoint

    def _truth(self) -> tuple[float, float]:
        """(push [N], POI error along the surface [m]) of the last tick, as the mission's
        metrics measure them (:mod:`uav_tilt_tools.metrics.mission`): the F/T force along
        the true normal, the true tip's distance from the true POI."""
        flight = self._live
        entry = flight.log[-1]
        poi_map, R_map_target = flight.plant.world.truth_targets()['']
        push = push_along_normal(quat_to_matrix(entry['q_map_base']), entry['ft_force_ee_n'],
                                 R_map_target)
        poi = poi_errors_m(entry['tip_map'], poi_map, R_map_target[:, 2])
        return push, float(poi[0])

    def _tick_reward(self) -> float:
        if self._live.log[-1]['mode'] != Mode.HOLD.value:
            return 0.0
        push, poi = self._truth()
        cfg = self.cfg
        return float(touch_reward(push, poi, cfg.controller.contact_force, cfg.force_scale_n,
                                  cfg.poi_scale_m))

    def _outcome(self) -> str | None:
        """None while the touch goes on, else 'success' or what ended it."""
        flight, cfg = self._live, self.cfg
        status = flight.status
        if status.get('failsafe_reason'):
            return status['failsafe_reason']
        records = flight.core.mission.records
        if records and all(r.success is not None for r in records):
            # every task ended (the one touch: its hold), judged on the truth as the
            # campaign judges it
            failed = next((r.reason or 'task_failed' for r in records if not r.success), None)
            return failed or first_missed_bar(mission_result(flight)['tasks']) or 'success'
        if status.get('contact_lost'):
            return 'contact_lost'
        if flight.log[-1]['push_n'] > cfg.controller.mission.failsafe.force_limit_n:
            return 'force_limit'
        truth = flight.plant.state()
        near_wall = flight.core.mission.mode in NEAR_WALL   # (takeoff starts on the ground)
        if near_wall and truth.p_map[2] < cfg.controller.mission.land.ground_z_m \
                + cfg.ground_clearance_m:
            return 'ground'
        z_body = quat_to_matrix(truth.q_map_base)[:, 2]
        if math.degrees(math.acos(min(1.0, max(-1.0, z_body[2])))) > cfg.max_tilt_deg:
            return 'crash'
        return None

    def _observation(self) -> dict[str, Any]:
        flight, sp = self._live, self._setpoint
        sensors = flight.sensors
        assert sensors is not None      # the flight has stepped
        odom = sensors.odom
        R, origin = sp.R_map_t, sp.origin_map
        p_t = R.T @ (odom.p_map - origin)
        tip_t = R.T @ (odom.p_map + quat_to_matrix(odom.q_map_base)[:, 0]
                       * flight.vehicle.tool_tip_x_m - origin)
        # against the reference the law tracks: the push's depth behind the setpoint's
        law = flight.core.flight.impedance
        error = np.concatenate((p_t - law.lambda_d_t, R.T @ odom.v_map - law.dlambda_d_t))
        obs: dict[str, Any] = dict(
            error_t=np.clip(error, -ERROR_BOUND, ERROR_BOUND),
            tip_t=np.clip(tip_t, -LIMIT_M, LIMIT_M),
            wrench=np.clip(np.concatenate((sensors.ee_force_n, sensors.ee_torque_nm)),
                           -WRENCH_BOUND, WRENCH_BOUND),
            push_error_n=np.clip([flight.core.f_normal_n - self.cfg.controller.contact_force],
                                 -LIMIT_N, LIMIT_N))
        obs = {k: v.astype(np.float32) for k, v in obs.items()}
        obs['phase'] = self._phase()
        if self.cfg.camera:
            obs['image'] = self._image()
        return obs

    def _phase(self) -> int:
        mission = self._live.core.mission
        if mission.mode == Mode.HOLD:
            return PHASES.index('hold')
        # the creep's pause for the tool to come back over the target is part of the touch
        phase = 'touch' if mission.phase == 'align' else mission.phase
        if mission.mode == Mode.CONTACT and phase in PHASES:
            return PHASES.index(phase)
        return PHASES.index('other')

    def _image(self) -> np.ndarray:
        """The camera image of the current tick, rendered once."""
        plant = self._live.plant
        tick = plant.tick
        if self._frame is None or self._frame[0] != tick:
            self._frame = (tick, plant.render()[0])
        return self._frame[1].copy()

    def _step_info(self) -> dict[str, Any]:
        push, poi = self._truth()
        flight = self._live
        mission = flight.core.mission
        return dict(self._info, t_s=float(flight.t_s), mode=mission.mode.value,
                    phase=mission.phase, push_n=float(push), poi_error_m=poi)


if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point=f'{__name__}:ContactInspectionEnv')
