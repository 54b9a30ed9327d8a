"""The mission's reference: the working frame, its segment, the yaw and pitch it turns to at
their rates, and the setpoint the impedance law tracks.

Free flight works in map; near the wall in the target frame t (z_t the surface normal, its
origin the point of interest), built from a target estimate. The body's reference is frame
t's reference plus the tool shift (the body stands off the normal where the pitch limit
keeps the tool off it). Segments are uav_tilt_control.trajectory's, so that lambda_d,
dlambda_d and ddlambda_d stay continuous from one to the next.
"""
import dataclasses
import math
import typing

import numpy as np

from uav_tilt_common.geometry import matrix_to_euler_zyx
from uav_tilt_common.pose import Pose
from uav_tilt_common.state import VehicleState
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control import frames
from uav_tilt_control.mission.clock import Clock
from uav_tilt_control.mission.config import MissionConfig
from uav_tilt_control.target_estimator import TargetEstimate
from uav_tilt_control.trajectory import MinJerk, PolylineCruise, Ramp, smootherstep
from uav_tilt_control.types import ImpedanceSetpoint

Segment = MinJerk | Ramp | PolylineCruise
Sample = tuple[np.ndarray, np.ndarray, np.ndarray]


class TargetFrame(typing.NamedTuple):
    """The target frame t built from one target estimate (the estimate is its key)."""

    key: tuple[float, ...]
    frame: Pose             # frame t in map
    pitch_rad: float        # the body pitch that points the tool along -z_t, within limits
    # What the body's reference shifts in the wall's plane (frame t) so that the tool tip
    # still meets the target when the pitch limit keeps the tool off the normal (x_t, y_t, 0)
    tool_shift_t: np.ndarray


class Push:
    """The push along -z_t the setpoint asks of the impedance law over time (the law holds
    its reference push / K_z behind the surface, eq. (6) at rest): a ramp from one push to
    another (minimum jerk, quasi-static: its rate is not fed forward) or a creep (a steady
    rise, its rate fed forward), held at its end."""

    def __init__(self) -> None:
        self.t0_s = 0.0
        self.T = 0.0
        self._from_n = self._to_n = 0.0
        self._rate_n_s = 0.0        # a creep's; 0 for a ramp

    def ramp(self, t0_s: float, from_n: float, to_n: float, duration_s: float) -> None:
        self.t0_s, self.T = t0_s, duration_s
        self._from_n, self._to_n, self._rate_n_s = from_n, to_n, 0.0

    def creep(self, t0_s: float, to_n: float, rate_n_s: float) -> None:
        """From none at ``t0_s``, rising at ``rate_n_s`` to ``to_n``."""
        self.t0_s, self.T = t0_s, to_n / rate_n_s
        self._from_n, self._to_n, self._rate_n_s = 0.0, to_n, rate_n_s

    def hold(self, push_n: float) -> None:
        self.ramp(-math.inf, push_n, push_n, 0.0)

    def release(self, now_s: float, duration_s: float) -> None:
        """Let go of what is pushed now over ``duration_s`` (nothing when nothing is, or
        when it is already being let go)."""
        push_n = self.sample(now_s)[0]
        if push_n > 0.0 and not (self._to_n == 0.0 and self._rate_n_s == 0.0):
            self.ramp(now_s, push_n, 0.0, duration_s)

    def done(self, t_s: float) -> bool:
        return t_s >= self.t0_s + self.T

    def sample(self, t_s: float) -> tuple[float, float]:
        """(push, its rate fed forward) at ``t_s``."""
        if self.done(t_s):
            return self._to_n, 0.0
        t = max(t_s - self.t0_s, 0.0)
        if self._rate_n_s > 0.0:
            return self._rate_n_s * t, self._rate_n_s if t_s >= self.t0_s else 0.0
        rise, _ = smootherstep(t / self.T)
        return self._from_n + (self._to_n - self._from_n) * rise, 0.0


class Reference:
    """Where the mission wants the body, in its working frame, and how it turns."""

    def __init__(self, vehicle: VehicleParams, config: MissionConfig, clock: Clock) -> None:
        self.vehicle = vehicle
        self.config = config
        self.clock = clock
        self.frame = Pose.identity()        # the working frame: map, or t near the wall
        self.tool_shift_t = np.zeros(3)     # TargetFrame.tool_shift_t while t is worked in
        self.target_frame: TargetFrame | None = None    # of the last estimate used
        self.segment: Segment = MinJerk(0.0, np.zeros(3), np.zeros(3), 1.0)
        self.yaw_ref = self.yaw_goal = 0.0
        self.pitch_ref = self.pitch_goal = 0.0
        self.push = Push()

    # ---- where the reference is ----

    def sample(self) -> Sample:
        """(p, v, a) of the reference in the working frame now (the push apart)."""
        return self.segment.sample(self.clock.now_s)

    def in_frame(self) -> tuple[np.ndarray, np.ndarray]:
        """(p, v) of the reference in the working frame now."""
        p, v, _ = self.sample()
        return p, v

    def in_map(self) -> Sample:
        """(p, v, a) of the body's reference in map (the working frame's reference plus the
        tool shift)."""
        p, v, a = self.sample()
        R = self.frame.R
        return self.frame.p + R @ (p + self.tool_shift_t), R @ v, R @ a

    def to_frame(self, p_map: np.ndarray) -> np.ndarray:
        """A map point in the working frame."""
        return frames.to_frame(self.frame.R, self.frame.p, p_map)

    def tool_tip_map(self, state: VehicleState) -> np.ndarray:
        """The tool tip in map, as odometry (position and attitude) sees it."""
        x_tool_map = frames.quat_matrix(state.q_map_base)[:, 0]
        return np.asarray(state.p_map, dtype=float) + x_tool_map * self.vehicle.tool_tip_x_m

    def tool_tip_t(self, state: VehicleState) -> np.ndarray:
        """The tool tip in the working frame, as odometry sees it."""
        return self.to_frame(self.tool_tip_map(state))

    def standoff_t(self) -> np.ndarray:
        """The body's place at the standoff, in frame t."""
        return np.array([0.0, 0.0, self.config.contact.standoff_m + self.vehicle.tool_tip_x_m])

    # ---- new segments ----

    def to_map(self) -> None:
        """Re-express the current reference in map and make map the working frame; a push
        is let go as it was pressed (contact.press_time_s)."""
        p, v, a = self.in_map()
        self.frame = Pose.identity()
        self.tool_shift_t = np.zeros(3)
        self.segment = MinJerk(self.clock.now_s, p, p, 1.0, v, a)
        self.push.release(self.clock.now_s, self.config.contact.press_time_s)

    def plan(self, goal_map: np.ndarray, v_max: float) -> None:
        """New segment in map from the current reference (continuous position, speed and
        acceleration)."""
        self.to_map()
        p, v, a = self.sample()
        self.segment = MinJerk(self.clock.now_s, p, goal_map, v_max, v, a)

    def plan_map(self, goal_map: np.ndarray, v_max: float, ref_map: Sample) -> None:
        """New segment in map from ``ref_map`` = (p_map, v_map, a_map), the reference as it
        was before the frame changed; map becomes the working frame (the target frame is
        kept for later)."""
        self.frame = Pose.identity()
        self.tool_shift_t = np.zeros(3)
        p, v, a = ref_map
        self.segment = MinJerk(self.clock.now_s, p, goal_map, v_max, v, a)

    def standoff_map(self) -> np.ndarray:
        """The body's place at the standoff of the target frame, in map."""
        assert self.target_frame is not None
        frame = self.target_frame.frame
        return frame.p + frame.R @ (self.standoff_t() + self.target_frame.tool_shift_t)

    def plan_t(self, goal_t: np.ndarray, v_max: float, ref_map: Sample | None = None) -> None:
        """New segment in the working frame t from the current reference (``ref_map`` =
        (p_map, v_map, a_map) when the frame has just changed)."""
        p_map, v_map, a_map = ref_map or self.in_map()
        R = self.frame.R
        self.segment = MinJerk(self.clock.now_s, self.to_frame(p_map) - self.tool_shift_t,
                               goal_t, v_max, R.T @ v_map, R.T @ a_map)

    def follow(self, segment: Segment) -> None:
        """Follow ``segment`` (in the working frame) from here on."""
        self.segment = segment

    def set_target_frame(self, target: TargetEstimate) -> None:
        """Work in the target frame of ``target``, facing its normal (the frame is rebuilt
        only when the estimate moves)."""
        cfg = self.config.contact
        p_poi, n_map = target.p_poi_map, target.normal_map
        key = tuple(np.concatenate((p_poi, n_map)).tolist())
        self.yaw_goal = frames.yaw_facing(n_map, default_rad=self.yaw_ref)
        if self.target_frame is None or key != self.target_frame.key:
            pitch = frames.pitch_facing(n_map) if cfg.pitch_to_normal else 0.0
            pitch = min(max(pitch, -cfg.max_pitch_rad), cfg.max_pitch_rad)
            R_map_t, origin_map = frames.target_frame_from_normal(p_poi, n_map)
            # the tip is L x_FLU ahead of the body: where x_FLU is not -z_t, the body
            # stands off the normal by L times x_FLU's part in the wall's plane
            x_tool_t = R_map_t.T @ frames.tool_direction(self.yaw_goal, pitch)
            shift_t = -self.vehicle.tool_tip_x_m * np.array([x_tool_t[0], x_tool_t[1], 0.0])
            self.target_frame = TargetFrame(key, Pose(R_map_t, origin_map), pitch, shift_t)
        self.frame = self.target_frame.frame
        self.pitch_goal, self.tool_shift_t = self.target_frame.pitch_rad, \
            self.target_frame.tool_shift_t

    # ---- where the vehicle is against it ----

    def arrived(self, state: VehicleState, v_map: np.ndarray) -> bool:
        """Whether the segment is done and the body there, still."""
        cfg = self.config.flight
        if not self.segment.done(self.clock.now_s):
            return False
        p_t = self.to_frame(state.p_map)
        return bool(np.linalg.norm(p_t - self.tool_shift_t - self.segment.p1) < cfg.arrive_tol_m
                    and np.linalg.norm(v_map) < cfg.arrive_speed_m_s)

    def turned(self, state: VehicleState) -> bool:
        """Whether the body faces its yaw goal and the pitch reference has reached its goal."""
        yaw_err = frames.wrap_angle(self.yaw_goal - yaw_of(state))
        return max(abs(yaw_err), abs(self.pitch_goal - self.pitch_ref)) < (
            self.config.flight.arrive_yaw_tol_rad)

    def overdue(self) -> bool:
        """Whether the segment under way ended arrive_timeout_s ago (for a mode still
        waiting to arrive: something holds the vehicle)."""
        segment = self.segment
        return self.clock.now_s > segment.t0_s + segment.T + self.config.flight.arrive_timeout_s

    # ---- the setpoint ----

    def turn(self, dt_s: float) -> None:
        """Move the yaw and pitch references towards their goals at their rates."""
        cfg = self.config.flight
        err = frames.wrap_angle(self.yaw_goal - self.yaw_ref)
        step = cfg.yaw_rate_rad_s * dt_s
        self.yaw_ref = frames.wrap_angle(self.yaw_ref + min(max(err, -step), step))
        step = cfg.pitch_rate_rad_s * dt_s
        self.pitch_ref += min(max(self.pitch_goal - self.pitch_ref, -step), step)

    def setpoint(self, sample: 'SetpointSample', contact_gains: bool,
                 tangential_feedforward: bool, trim_push: bool,
                 airborne: bool) -> ImpedanceSetpoint:
        """The ImpedanceSetpoint of the reference ``sample`` (in the working frame)."""
        return ImpedanceSetpoint(
            R_map_t=self.frame.R.copy(), origin_map=self.frame.p.copy(),
            lambda_d_t=sample.p + self.tool_shift_t, dlambda_d_t=sample.v,
            ddlambda_d_t=sample.a, push_n=sample.push_n, dpush_n_s=sample.dpush_n_s,
            trim_push=trim_push, yaw_rad=self.yaw_ref, pitch_rad=self.pitch_ref,
            contact_gains=contact_gains, tangential_feedforward=tangential_feedforward,
            airborne=airborne)

    def setpoint_sample(self) -> 'SetpointSample':
        """The reference now, with the push, for the setpoint (the modes may shape it)."""
        p, v, a = self.sample()
        push_n, dpush_n_s = self.push.sample(self.clock.now_s)
        return SetpointSample(p, v, a, push_n, dpush_n_s)


@dataclasses.dataclass
class SetpointSample:
    """The reference in the working frame (p, v, a) and the push along -z_t with its rate
    fed forward, as the setpoint will carry them."""

    p: np.ndarray
    v: np.ndarray
    a: np.ndarray
    push_n: float
    dpush_n_s: float


def yaw_of(state: VehicleState) -> float:
    """The body's yaw: that of matrix_to_euler_zyx from the two matrix entries it needs
    (every tick)."""
    x, y, z, w = np.asarray(state.q_map_base, dtype=float).tolist()
    n2 = x * x + y * y + z * z + w * w
    m00, m10 = 1.0 - 2.0 * (y * y + z * z) / n2, 2.0 * (x * y + z * w) / n2
    if math.hypot(m00, m10) < 1e-12:
        return float(matrix_to_euler_zyx(frames.quat_matrix(state.q_map_base))[0])
    return math.atan2(m10, m00)
