"""Target (point of interest) estimate in map from latency-stamped camera measurements.

The vision pose arrives in ``camera_color_optical_frame`` stamped with the image time, tens
of ms in the past. It is moved to map with the vehicle pose interpolated at that stamp from
a short state history, gated against the current estimate, and filtered: a Kalman filter on
the position of a static point and an exponential average on the normal.
"""
import bisect
import collections
import dataclasses
import math
import typing
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_common.config import param
from uav_tilt_common.geometry import quat_slerp, quat_to_matrix
from uav_tilt_common.pose import Pose
from uav_tilt_common.state import VehicleState
from uav_tilt_common.targets import is_no_target
from uav_tilt_control import frames
from uav_tilt_control.lowpass import lowpass_weight
from uav_tilt_common.targets import HINT_ERROR_M

# The first fix near a hint is taken within the hint's error on the diagonal plus this: the
# vision estimate's own error (a few cm) and the POI's offset within the hinted object.
HINT_MARGIN_M = 0.03
# Vision's error grows with range (depth noise along the ray, a pixel's size on the wall),
# and measurements from one place share it, so an estimate averaged from far looks is surer
# of itself than it should be and gates out the nearer looks that would correct it. A run
# of rejections taken from this fraction of the nearest range the estimate was measured
# from, or nearer, within gate_distance_m of it (no other object fits there), is a better
# look at the same object: it refines even a locked estimate.
REFINE_RANGE_RATIO = 0.5

# A recorded vehicle state: (t_s, p_map, unit q_map_base)
_State = tuple[float, NDArray[np.float64], NDArray[np.float64]]


@dataclasses.dataclass
class TargetEstimatorConfig:
    """Gates, filter and history of :class:`TargetEstimator`."""

    history_size: int = param(300, lo=2, hi=10000)          # states kept (1 s at 300 Hz)
    max_extrapolation_s: float = param(0.02, lo=0.0, hi=0.5)  # stamp newer than last state
    meas_std_m: float = param(0.01, lo=1e-4, hi=1.0)        # used when no covariance given
    process_std_m_sqrt_s: float = param(0.003, lo=0.0, hi=1.0)  # drift of the estimate
    normal_tau_s: float = param(0.3, lo=0.0, hi=10.0)       # normal averaging time constant
    gate_distance_m: float = param(0.2, lo=0.001, hi=10.0)
    gate_chi2: float = param(16.27, lo=1.0, hi=1000.0)      # chi2(3 dof) at 99.9 %
    gate_angle_rad: float = param(0.5, lo=0.01, hi=3.2)
    reacquire_n: int = param(10, lo=1, hi=1000, unit='',
                             doc='consistent rejections that reset the estimate')
    valid_age_s: float = param(0.5, lo=0.01, hi=10.0)       # estimate older than this: invalid
    # first fix this near a hint: 0.45 m, so that a look-alike is told apart when it is
    # over 0.75 m (0.45 + HINT_ERROR_M) from the target along either of the wall's axes
    hint_radius_m: float = param(round(math.sqrt(2.0) * HINT_ERROR_M + HINT_MARGIN_M, 2),
                                 lo=0.01, hi=5.0)


class TargetEstimate(typing.NamedTuple):
    """What the mission consumes."""

    p_poi_map: np.ndarray
    normal_map: np.ndarray
    age_s: float
    valid: bool


class TargetEstimator:
    """Latency-compensated, gated and filtered POI position and surface normal in map."""

    def __init__(self, config: TargetEstimatorConfig | None = None,
                 camera_in_base: Pose | None = None) -> None:
        """``camera_in_base``: the camera optical frame's :class:`Pose` in base_link
        (:meth:`VehicleParams.camera_in_base`; identity if None)."""
        self.config = config or TargetEstimatorConfig()
        self._camera_in_base = camera_in_base or Pose.identity()
        self._history: collections.deque[_State] = collections.deque(
            maxlen=self.config.history_size)
        self._p_map: NDArray[np.float64] | None = None
        self._P: NDArray[np.float64] | None = None  # position covariance of the estimate, m^2
        self._n_map: NDArray[np.float64] | None = None
        self._stamp_s: float | None = None  # stamp of the last accepted measurement
        # the nearest range it was measured from (0: truth)
        self._range_m: float | None = None
        # consecutive gated-out measurements: (p_map, range_m)
        self._rejected_run: list[tuple[NDArray[np.float64], float]] = []
        # Set by the mission: a locked target is never swapped for another object (a look-
        # alike); the first fix is taken near the hint (map) when there is one.
        self.locked = False
        self.hint_map: NDArray[np.float64] | None = None
        self.counters = dict(accepted=0, rejected_gate=0, rejected_nonfinite=0,
                             rejected_no_pose=0, rejected_hint=0, no_target=0, reacquired=0,
                             refined=0, switch_refused=0)

    def reset(self) -> None:
        """Forget the target estimate (a candidate the mission did not confirm)."""
        self._p_map = self._P = self._n_map = self._stamp_s = self._range_m = None
        self._rejected_run = []

    def aim(self, hint_map: ArrayLike | None) -> None:
        """Look for the target near ``hint_map`` (map; None: wherever vision sees one): the
        estimate is kept only when it is within ``hint_radius_m`` of the new hint, else the
        next fix is taken near it (a plan's next target)."""
        self.hint_map = None if hint_map is None else np.asarray(hint_map, dtype=float).copy()
        if self.hint_map is not None and self._p_map is not None and np.linalg.norm(
                self._p_map - self.hint_map) > self.config.hint_radius_m:
            self.reset()

    def add_state(self, state: VehicleState) -> None:
        """Record a vehicle state; out-of-order or non-finite states are ignored."""
        if self._history and state.t_s <= self._history[-1][0]:
            return
        p_map = np.array(state.p_map, dtype=float)
        q = np.asarray(state.q_map_base, dtype=float)
        if not all(map(math.isfinite, p_map.tolist() + q.tolist())):
            return
        # a unit quaternion: scipy's from_quat normalised it, the slerp needs it
        self._history.append((float(state.t_s), p_map, frames.unit(q)))

    def pose_at(self, t_s: float) -> Pose | None:
        """Vehicle :class:`Pose` in map at ``t_s``: linear position and slerp attitude
        between the bracketing states, or None outside the history."""
        if not self._history:
            return None
        t_last, p_last, q_last = self._history[-1]
        if t_s >= t_last:
            if t_s - t_last > self.config.max_extrapolation_s:
                return None
            # a frame slightly newer than the last odometry: the last pose is closest
            return Pose(quat_to_matrix(q_last), p_last)
        i = bisect.bisect_right(self._history, t_s, key=lambda s: s[0])
        if i == 0:
            return None
        t0, p0, q0 = self._history[i - 1]
        t1, p1, q1 = self._history[i]
        u = (t_s - t0) / (t1 - t0)
        return Pose(quat_to_matrix(quat_slerp(q0, q1, u)), p0 + u * (p1 - p0))

    def add_measurement(self, stamp_s: float, p_cam: ArrayLike, n_cam_or_R_cam_t: ArrayLike,
                        covariance: ArrayLike | None = None) -> bool:
        """Add a vision measurement in the camera optical frame, stamped with the image time.

        ``n_cam_or_R_cam_t`` is the surface normal (3,) or the target orientation (3x3,
        z_t = normal). ``covariance``: 3x3 position or 6x6 pose covariance (row-major
        flat allowed) in the camera frame, or None; covariance[0] == -1 means
        "no target in this frame" (DESIGN section 3). Returns True when accepted.
        """
        if covariance is not None and is_no_target(covariance):
            self.counters['no_target'] += 1
            return False
        n_cam = np.asarray(n_cam_or_R_cam_t, dtype=float)
        if n_cam.shape == (3, 3):
            n_cam = n_cam[:, 2]
        return self.add_candidates(stamp_s, [(p_cam, n_cam, covariance)])

    def add_candidates(self, stamp_s: float,
                       candidates: Sequence[tuple[ArrayLike, ArrayLike, ArrayLike | None]]
                       ) -> bool:
        """All target candidates of one frame, ``(p_cam, n_cam, covariance or None)`` each
        in the camera optical frame, vision's tracked one first; returns True when one was
        accepted.

        The one nearest the hint is taken until the mission locks the target (the first fix
        only within ``hint_radius_m`` of it; another object nearer the hint than the
        estimate replaces it), then the one nearest the estimate; without a hint, the one
        nearest the estimate, or before the first fix vision's first.
        """
        if not candidates:
            self.counters['no_target'] += 1
            return False
        checked = [c for c in candidates if self._finite(stamp_s, *c)]
        if not checked:
            self.counters['rejected_nonfinite'] += 1
            return False
        pose = self.pose_at(stamp_s)
        if pose is None:
            self.counters['rejected_no_pose'] += 1
            return False
        map_cam = pose @ self._camera_in_base
        in_map = [map_cam.apply(c[0]) for c in checked]
        # Unlocked, the hint decides: the candidate nearest it is taken
        reference = self._p_map
        if self.hint_map is not None and (reference is None or not self.locked):
            reference = self.hint_map
        k = 0
        if reference is not None:
            k = int(np.argmin([np.linalg.norm(p - reference) for p in in_map]))
            if self._p_map is None and np.linalg.norm(in_map[k] - reference) \
                    > self.config.hint_radius_m:
                self.counters['rejected_hint'] += 1
                return False
        p_cam, n_cam, cov = checked[k]
        n_map = frames.unit(map_cam.rotate(n_cam))
        cov = None if cov is None else np.asarray(cov, dtype=float).ravel()
        R_meas, range_m = self._meas_cov_map(cov, map_cam.R), float(np.linalg.norm(p_cam))
        if self._nearer_the_hint(in_map[k]):
            # A look-alike fixed first (the target missed in that frame, both within the
            # radius) gives way at once: vision tracks the first and sends the others only
            # in its detector frames, so no run of rejections would ever build up.
            self._reset(stamp_s, in_map[k], n_map, R_meas, range_m)
            self.counters['reacquired'] += 1
            return True
        return self._update(stamp_s, in_map[k], n_map, R_meas, range_m)

    def _nearer_the_hint(self, p_map: NDArray[np.float64]) -> bool:
        """Whether ``p_map``, unlocked, is another object than the estimate's (outside the
        gate), within the hint's radius and nearer the hint than the estimate by more than
        vision's error (HINT_MARGIN_M)."""
        if self.locked or self.hint_map is None or self._p_map is None:
            return False
        cfg, hint = self.config, self.hint_map
        distance_m = np.linalg.norm(p_map - hint)
        return bool(np.linalg.norm(p_map - self._p_map) > cfg.gate_distance_m
                    and distance_m <= cfg.hint_radius_m
                    and distance_m < np.linalg.norm(self._p_map - hint) - HINT_MARGIN_M)

    @staticmethod
    def _finite(stamp_s: float, p_cam: ArrayLike, n_cam: ArrayLike,
                cov: ArrayLike | None) -> bool:
        values = [np.asarray(p_cam, dtype=float), np.asarray(n_cam, dtype=float)]
        if cov is not None:
            values.append(np.asarray(cov, dtype=float).ravel())
        return bool(np.isfinite(stamp_s) and all(np.all(np.isfinite(v)) for v in values)
                    and np.linalg.norm(values[1]) > 1e-9)

    def add_ground_truth(self, stamp_s: float, p_poi_map: ArrayLike,
                         n_map_or_R_map_t: ArrayLike) -> bool:
        """Evaluation mode: take a ground-truth target pose in map as the estimate."""
        n_map = np.asarray(n_map_or_R_map_t, dtype=float)
        if n_map.shape == (3, 3):
            n_map = n_map[:, 2]
        p_map = np.asarray(p_poi_map, dtype=float)
        # called every tick in this mode: plain-float checks (numpy's cost more per call)
        n = n_map.tolist()
        if not (all(map(math.isfinite, [stamp_s, *p_map.tolist(), *n]))
                and math.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) > 1e-9):
            self.counters['rejected_nonfinite'] += 1
            return False
        self._reset(stamp_s, p_map, frames.unit(n_map), np.zeros((3, 3)), 0.0)
        self.counters['accepted'] += 1
        return True

    def estimate(self, now_s: float | None = None) -> TargetEstimate | None:
        """TargetEstimate(p_poi_map, normal_map, age_s, valid) or None before the first fix.

        ``age_s`` is measured from the last accepted stamp to ``now_s`` (default: the newest
        vehicle state); valid means younger than ``valid_age_s``.
        """
        if self._p_map is None:
            return None
        # _reset sets the estimate's parts together
        assert self._n_map is not None and self._stamp_s is not None
        if now_s is None:
            now_s = self._history[-1][0] if self._history else self._stamp_s
        age_s = max(0.0, now_s - self._stamp_s)
        return TargetEstimate(self._p_map.copy(), self._n_map.copy(), age_s,
                              age_s <= self.config.valid_age_s)

    def time_since_last_s(self, now_s: float) -> float:
        """Seconds since the last accepted measurement (inf before the first)."""
        return np.inf if self._stamp_s is None else now_s - self._stamp_s

    def _meas_cov_map(self, cov: NDArray[np.float64] | None,
                      R_map_cam: NDArray[np.float64]) -> NDArray[np.float64]:
        if cov is None:
            return np.eye(3) * self.config.meas_std_m ** 2
        if cov.size == 36:
            cov_cam = cov.reshape(6, 6)[:3, :3]
        elif cov.size == 9:
            cov_cam = cov.reshape(3, 3)
        else:
            raise ValueError(f'covariance must have 9 or 36 elements, not {cov.size}')
        # a zero (unknown) covariance from the publisher must not make the gate infinitely
        # tight, so the configured noise is a floor
        floor = np.eye(3) * self.config.meas_std_m ** 2
        return R_map_cam @ cov_cam @ R_map_cam.T + floor

    def _update(self, stamp_s: float, p_map: NDArray[np.float64], n_map: NDArray[np.float64],
                R_meas: NDArray[np.float64], range_m: float) -> bool:
        cfg = self.config
        if self._p_map is None:
            self._reset(stamp_s, p_map, n_map, R_meas, range_m)
            self.counters['accepted'] += 1
            return True
        # _reset sets the estimate's parts together
        assert (self._P is not None and self._n_map is not None and self._stamp_s is not None
                and self._range_m is not None)
        dt = max(0.0, stamp_s - self._stamp_s)
        P = self._P + np.eye(3) * cfg.process_std_m_sqrt_s ** 2 * dt
        r = p_map - self._p_map
        S = P + R_meas
        angle = np.arccos(np.clip(n_map @ self._n_map, -1.0, 1.0))
        if (np.linalg.norm(r) > cfg.gate_distance_m or r @ np.linalg.solve(S, r) > cfg.gate_chi2
                or angle > cfg.gate_angle_rad):
            self.counters['rejected_gate'] += 1
            self._maybe_reacquire(stamp_s, p_map, n_map, R_meas, range_m)
            return False
        self._rejected_run = []
        self._range_m = min(self._range_m, range_m)
        K = P @ np.linalg.inv(S)
        self._p_map = self._p_map + K @ r
        self._P = (np.eye(3) - K) @ P
        w = lowpass_weight(dt, cfg.normal_tau_s)
        self._n_map = frames.unit(self._n_map + w * (n_map - self._n_map))
        self._stamp_s = max(self._stamp_s, stamp_s)
        self.counters['accepted'] += 1
        return True

    def _maybe_reacquire(self, stamp_s: float, p_map: NDArray[np.float64],
                         n_map: NDArray[np.float64], R_meas: NDArray[np.float64],
                         range_m: float) -> None:
        # a run of rejected measurements that agree with each other means the estimate is
        # the outlier (wrong first lock, the target moved, or far looks): restart from them
        cfg, run = self.config, self._rejected_run
        # only measurements gated against an estimate come here
        assert self._p_map is not None and self._range_m is not None
        if run and np.linalg.norm(p_map - run[-1][0]) > cfg.gate_distance_m:
            run.clear()
        run.append((p_map, range_m))
        if len(run) >= cfg.reacquire_n:
            refines = (np.linalg.norm(p_map - self._p_map) <= cfg.gate_distance_m
                       and max(r for _, r in run) <= REFINE_RANGE_RATIO * self._range_m)
            far_from_hint = self.hint_map is not None and np.linalg.norm(
                p_map - self.hint_map) > cfg.hint_radius_m
            if (self.locked or far_from_hint) and not refines:
                # another object where the target was, or away from where it is said to
                # be: a look-alike, never a switch
                self.counters['switch_refused'] += 1
                run.clear()
                return
            self._reset(stamp_s, p_map, n_map, R_meas, range_m)
            self.counters['refined' if refines else 'reacquired'] += 1

    def _reset(self, stamp_s: float, p_map: NDArray[np.float64], n_map: NDArray[np.float64],
               P: NDArray[np.float64], range_m: float) -> None:
        self._range_m = float(range_m)
        self._p_map = np.array(p_map, dtype=float)
        self._n_map = np.array(n_map, dtype=float)
        self._P = np.array(P, dtype=float)
        self._stamp_s = float(stamp_s)
        self._rejected_run = []
