"""The plant core: PyBullet physics of vehicle and world, actuators, disturbances, sensors.

No ROS here. :class:`Plant` steps one 300 Hz control tick (4 physics substeps at 1200 Hz)
for a given :class:`ActuatorCommand` and exposes truth, noisy sensors and the camera.
"""
import dataclasses
import math

import numpy as np

from uav_tilt_common.config import ConfigError, nested, param
from uav_tilt_common.geometry import cross3, quat_to_matrix, rotor_wrench_matrix
from uav_tilt_common.pose import Pose
from uav_tilt_common.state import ActuatorCommand, VehicleState
from uav_tilt_common.vehicle import GRAVITY, VehicleParams
from uav_tilt_sim import camera as cam_mod
from uav_tilt_sim import vehicle_body
from uav_tilt_sim.actuators import RotorBank, Servo
from uav_tilt_sim.bullet import pybullet as p
from uav_tilt_sim.sensors import SensorModel
from uav_tilt_sim.visuals import Scene
from uav_tilt_sim.world import build_world

GRAVITY_MAP = np.array([0.0, 0.0, -GRAVITY])
SERVO_TORQUE_NM = 5.0
# Random stream of the gusts, beside the sensors' (uav_tilt_sim.sensors.RNG_STREAMS).
RNG_WIND = 0
# PyBullet's position control of the two arm joints
_SERVO_FORCES = [SERVO_TORQUE_NM] * 2
_SERVO_KP = [0.8] * 2
_SERVO_KD = [1.0] * 2


@dataclasses.dataclass
class PlantCoreConfig:
    """Physics and sensor rates of the plant."""

    physics_hz: float = param(1200.0, lo=100.0, hi=10000.0)
    substeps: int = param(4, lo=1, hi=20)          # physics steps per control tick
    solver_iterations: int = param(30, lo=1, hi=500)
    vehicle: VehicleParams = nested(VehicleParams)
    camera: cam_mod.CameraConfig = nested(cam_mod.CameraConfig)

    @property
    def control_hz(self):
        """Control tick rate (sensor publication rate)."""
        return self.physics_hz / self.substeps


@dataclasses.dataclass
class TickSensors:
    """Everything the plant measures at one control tick."""

    t_s: float
    gyro_rad_s: np.ndarray         # base_link
    accel_m_s2: np.ndarray         # specific force, base_link
    q_imu: np.ndarray              # attitude (x, y, z, w), base_link -> map
    odom: VehicleState             # noisy, mocap-like
    ee_force_n: np.ndarray         # contact force on the tool, ee_link frame
    ee_torque_nm: np.ndarray       # contact torque about the tool tip, ee_link frame
    thrusts_n: np.ndarray          # measured rotor thrusts
    tilts_rad: np.ndarray          # measured (alpha, beta)
    in_contact: bool


class Plant:
    """One simulated world; deterministic for a given scenario (seed included)."""

    def __init__(self, config, scenario, warn=None):
        """``warn``: where the one line about a renderer fallback goes (default stderr); the
        renderer is made on the first :meth:`render`."""
        self.config = config
        self.scenario = scenario
        self.vehicle = config.vehicle
        self.dt_physics = 1.0 / config.physics_hz
        self.dt_tick = config.substeps * self.dt_physics
        self.client = p.connect(p.DIRECT)
        p.setGravity(*GRAVITY_MAP, physicsClientId=self.client)
        p.setPhysicsEngineParameter(fixedTimeStep=self.dt_physics,
                                    numSolverIterations=config.solver_iterations,
                                    physicsClientId=self.client)
        self.scene = Scene(self.client)
        self.world = build_world(self.client, scenario, scene=self.scene)
        start = np.asarray(scenario.start_xyz_m, dtype=float)
        mm = scenario.mismatch
        ids = vehicle_body.create_vehicle(self.client, self.vehicle, [0, 0, 0],
                                          np.radians(scenario.start_yaw_deg),
                                          mm.mass_scale, mm.inertia_scale, self.scene)
        self._warn = warn
        self.renderer: cam_mod.Renderer | None = None   # made on the first render
        self.body = ids.body
        self.mass_kg = self.vehicle.mass_kg * mm.mass_scale
        # Resting on its skid when the start height is at or below the ground.
        start[2] = max(start[2], -ids.bottom_z_m + 0.002)
        q0 = p.getQuaternionFromEuler([0, 0, np.radians(scenario.start_yaw_deg)])
        # PyBullet places a base by its centre of mass, which the counterweight offsets.
        R0 = np.array(p.getMatrixFromQuaternion(q0)).reshape(3, 3)
        p.resetBasePositionAndOrientation(self.body, (start + R0 @ ids.base_com_offset_m)
                                          .tolist(), q0, physicsClientId=self.client)
        self._com_offset = ids.base_com_offset_m
        if self._starts_in_wall(start + R0[:, 0] * self.vehicle.tool_tip_x_m):
            self.close()
            raise ConfigError(
                f"parameter 'start_xyz_m' = {scenario.start_xyz_m} with start_yaw_deg "
                f"{scenario.start_yaw_deg:g} puts the vehicle in the wall (its hub, or its "
                f"tool, which reaches {self.vehicle.tool_tip_x_m:g} m ahead): start farther "
                f"from the wall, or turned away from it")
        self._arm_joints = [vehicle_body.ARM_FRONT, vehicle_body.ARM_REAR]
        v = self.vehicle
        self.rotors = RotorBank(v.thrust_tau_s, v.f_max_n, self.dt_physics)
        self.servos = [Servo(v.servo_bandwidth_hz, v.servo_rate_rad_s, v.tilt_limit_rad,
                             self.dt_physics) for _ in range(2)]
        # One stream per source of randomness, so that one's draws never shift another's:
        # the same seed gives the same wind whether the camera renders or not.
        self._wind_rng = np.random.default_rng([scenario.seed, RNG_WIND])
        self.sensors = SensorModel(scenario.noise, scenario.seed)
        self._sensed = None         # (tick, TickSensors) of the last read
        # the gust is first-order Gauss-Markov: decay and innovation gain per physics step
        self._gust = np.zeros(3)
        self._gust_decay = np.exp(-self.dt_physics / scenario.wind.gust_tau_s)
        self._gust_gain = scenario.wind.gust_std_m_s * np.sqrt(1 - self._gust_decay ** 2)
        self._wind_mean_map = np.asarray(scenario.wind.mean_m_s, dtype=float)
        self.tick = 0
        self._prev_v_map = np.zeros(3)
        self._contact_force_map = np.zeros(3)
        self._contact_torque_map = np.zeros(3)
        self.command = ActuatorCommand(np.zeros(4))
        # Extra force [N, map] on base_link's origin while set: a test/disturbance hook.
        self.external_force_map = np.zeros(3)
        self._truth = None

    @property
    def t_s(self):
        """Simulated time of the current tick."""
        return self.tick * self.dt_tick

    @property
    def renderer_name(self):
        """'gl' or 'tiny' once a frame was rendered, else None."""
        return None if self.renderer is None else self.renderer.name

    def _starts_in_wall(self, tip_map):
        """Whether the vehicle where it starts (its tool's tip at ``tip_map``) is in a
        structure or an object on one, or its tool reaches through a wall's face: PyBullet
        would throw it out, or it could not take off."""
        bodies = [s.body for s in self.world.structures] + [o.body for o in self.world.objects]
        if any(p.getClosestPoints(self.body, body, 0.0, physicsClientId=self.client)
               for body in bodies):
            return True
        return self.world.reaches_into(tip_map)

    def close(self):
        """Release the renderer and the physics server."""
        if self.renderer is not None:
            self.renderer.close()
            self.renderer = None
        if self.client is not None:
            p.disconnect(self.client)
            self.client = None

    def step(self, command=None):
        """Advance one control tick applying ``command`` (or the last one)."""
        if command is not None:
            self.command = command
        c = self.command
        v = self.vehicle
        client, body = self.client, self.body
        # Thrust directions follow the arms; over one 3.3 ms tick they move < 0.02 rad.
        A = rotor_wrench_matrix(*self._tilts(), v.l1_m, v.l2_m, v.k_m)
        cx, cy, cz = self._com_offset.tolist()
        for _ in range(self.config.substeps):
            fx, fy, fz, tx, ty, tz = (A @ self.rotors.step(c.thrusts_n)).tolist()
            (a_ref, a_rate), (b_ref, b_rate) = (self.servos[0].step(c.alpha_rad),
                                                self.servos[1].step(c.beta_rad))
            p.setJointMotorControlArray(
                body, self._arm_joints, p.POSITION_CONTROL, targetPositions=[a_ref, b_ref],
                targetVelocities=[a_rate, b_rate], forces=_SERVO_FORCES,
                positionGains=_SERVO_KP, velocityGains=_SERVO_KD, physicsClientId=client)
            pos, quat = p.getBasePositionAndOrientation(body, physicsClientId=client)
            vel, _ = p.getBaseVelocity(body, physicsClientId=client)
            # plain floats for the 3-vectors: numpy's per-call cost is most of this loop
            (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = quat_to_matrix(quat).tolist()
            ax, ay, az = (self._air_force(np.asarray(vel)) + self.external_force_map).tolist()
            force_map = [r00 * fx + r01 * fy + r02 * fz + ax, r10 * fx + r11 * fy + r12 * fz + ay,
                         r20 * fx + r21 * fy + r22 * fz + az]
            # base_link's origin is the rotor centroid; PyBullet's base frame is the hub CoM.
            origin_map = [pos[0] - (r00 * cx + r01 * cy + r02 * cz),
                          pos[1] - (r10 * cx + r11 * cy + r12 * cz),
                          pos[2] - (r20 * cx + r21 * cy + r22 * cz)]
            p.applyExternalForce(body, -1, force_map, origin_map, p.WORLD_FRAME,
                                 physicsClientId=client)
            p.applyExternalTorque(body, -1, [r00 * tx + r01 * ty + r02 * tz,
                                             r10 * tx + r11 * ty + r12 * tz,
                                             r20 * tx + r21 * ty + r22 * tz], p.WORLD_FRAME,
                                  physicsClientId=client)
            p.stepSimulation(physicsClientId=client)
        self.tick += 1
        self._truth = None

    def set_actuator_state(self, thrusts_n, alpha_rad, beta_rad):
        """Start the actuators at a state (e.g. hovering, arms tilted), joints included."""
        self.rotors.thrusts_n[:] = np.clip(thrusts_n, 0.0, self.vehicle.f_max_n)
        self.command = ActuatorCommand(self.rotors.thrusts_n.copy(), alpha_rad, beta_rad)
        for joint, servo, angle in zip(self._arm_joints, self.servos, (alpha_rad, beta_rad)):
            servo.angle_rad, servo.rate_rad_s = angle, 0.0
            p.resetJointState(self.body, joint, angle, 0.0, physicsClientId=self.client)
        self._truth = None
        self._sensed = None

    def _air_force(self, vel_map):
        """Quadratic drag against the air moving at mean wind + gust."""
        if self._gust_gain > 0.0:
            self._gust = (self._gust_decay * self._gust
                          + self._gust_gain * self._wind_rng.standard_normal(3))
        rel = self._wind_mean_map + self._gust - vel_map
        return self.scenario.wind.drag_n_s2_per_m2 * math.sqrt(rel @ rel) * rel

    def _tilts(self) -> tuple[float, float]:
        states = p.getJointStates(self.body, self._arm_joints, physicsClientId=self.client)
        return states[0][0], states[1][0]

    def state(self):
        """True state of base_link (origin at the rotor centroid) at the current tick."""
        if self._truth is None:
            self._truth = self._read_truth()
        return self._truth

    def _read_truth(self):
        pos, quat = p.getBasePositionAndOrientation(self.body, physicsClientId=self.client)
        lin, ang = p.getBaseVelocity(self.body, physicsClientId=self.client)
        R = quat_to_matrix(quat)
        w_map = np.asarray(ang)
        # Velocity of the base_link origin (rigid body: v_com + w x r).
        r = -R @ self._com_offset
        v_map = np.asarray(lin) + cross3(w_map, r)
        return VehicleState(self.t_s, np.asarray(pos) + r, np.asarray(quat), v_map,
                            R.T @ w_map)

    def tool_tip_map(self):
        """Position of ee_link (front of the tool's spherical tip) in map."""
        s = self.state()
        return s.p_map + quat_to_matrix(s.q_map_base) @ np.array([self.vehicle.tool_tip_x_m, 0, 0])

    def contact_wrench_ee(self):
        """Contact force and torque (about the tip) on the tool, in ee_link (FLU axes)."""
        force = np.zeros(3)
        torque = np.zeros(3)
        contacts = p.getContactPoints(bodyA=self.body, linkIndexA=vehicle_body.TOOL,
                                      physicsClientId=self.client)
        if not contacts:
            return force, torque
        tip = self.tool_tip_map()
        for c in contacts:
            normal, dir1, dir2 = np.asarray(c[7]), np.asarray(c[11]), np.asarray(c[13])
            # The normal is reported on bodyA (the tool); the lateral friction along
            # directions built on the pair's own normal, which is this one or its opposite
            # depending on the pair: the triad's handedness gives the friction's sign on the
            # tool (checked against the tool joint's reaction in test_plant).
            hand = float(np.sign(cross3(dir1, dir2) @ normal))
            f = c[9] * normal + hand * (c[10] * dir1 + c[12] * dir2)
            force += f
            torque += cross3(np.asarray(c[5]) - tip, f)
        R = quat_to_matrix(self.state().q_map_base)
        return R.T @ force, R.T @ torque

    def read_sensors(self):
        """Noisy sensor set of the current tick (IMU, odometry, F/T, actuators); reading
        again in the same tick gives the same set (a sensor samples once a tick)."""
        if self._sensed is not None and self._sensed[0] == self.tick:
            return self._sensed[1]
        self._sensed = (self.tick, self._sample_sensors())
        return self._sensed[1]

    def _sample_sensors(self):
        truth = self.state()
        accel_map = (truth.v_map - self._prev_v_map) / self.dt_tick
        self._prev_v_map = truth.v_map.copy()
        R = quat_to_matrix(truth.q_map_base)
        specific = R.T @ (accel_map - GRAVITY_MAP)
        force, torque = self.contact_wrench_ee()
        n = self.sensors
        return TickSensors(
            t_s=truth.t_s,
            gyro_rad_s=n.gyro(truth.w_base),
            accel_m_s2=n.accel(specific),
            q_imu=truth.q_map_base.copy(),
            odom=n.odometry(truth),
            ee_force_n=n.force(force),
            ee_torque_nm=n.torque(torque),
            thrusts_n=self.rotors.thrusts_n.copy(),
            tilts_rad=np.array(self._tilts()),
            in_contact=bool(np.linalg.norm(force) > 1e-6),
        )

    def camera_pose(self):
        """(p_cam_map, R_map_cam) of the optical frame (z forward, x right, y down)."""
        s = self.state()
        R_map_base = quat_to_matrix(s.q_map_base)
        map_cam = Pose(R_map_base, s.p_map) @ self.vehicle.camera_in_base()
        return map_cam.p, map_cam.R

    def render_state(self):
        """What a frame of this tick depends on: PyBullet's base pose of the vehicle (its
        centre of mass) and the arm angles, nine floats (for :mod:`camera_process`)."""
        pos, quat = p.getBasePositionAndOrientation(self.body, physicsClientId=self.client)
        return (*pos, *quat, *self._tilts())

    def set_render_state(self, state):
        """Put the vehicle where :meth:`render_state` of a plant of the same scenario had it:
        a plant that only renders."""
        pos, quat, tilts = state[:3], state[3:7], state[7:]
        p.resetBasePositionAndOrientation(self.body, pos, quat, physicsClientId=self.client)
        for joint, angle in zip(self._arm_joints, tilts):
            p.resetJointState(self.body, joint, angle, 0.0, physicsClientId=self.client)
        self._truth = None

    def start_renderer(self) -> cam_mod.Renderer:
        """Make the renderer (a GL context) now rather than at the first frame."""
        if self.renderer is None:
            self.renderer = cam_mod.make_renderer(self.config.camera, self._warn)
        return self.renderer

    def render(self, lighting=None, segmentation=False):
        """Render the eye-in-hand camera: (rgb, depth_m, seg)."""
        renderer = self.start_renderer()
        p_cam, R_map_cam = self.camera_pose()
        rgb, depth, seg = cam_mod.render_with(renderer, self.scene, p_cam, R_map_cam,
                                              lighting, segmentation)
        return rgb, self.sensors.depth(depth), seg

    def skip_frame(self):
        """A frame not drawn (no one takes it): the depth noise draws what the frame would
        have drawn, so that the frames drawn afterwards carry the noise they would have."""
        cam = self.config.camera
        self.sensors.skip_depth((cam.height, cam.width))
