"""Reference segments of the mission: (p, v, a) of a point against time, in one frame.

Every segment has ``t0_s``, its duration ``T``, its end point ``p1``, ``done(t)`` and
``sample(t) -> (p, v, a)`` (held at ``p1`` after the end), so that the mission can swap one
for another and lambda_d, dlambda_d and ddlambda_d stay consistent:

- :class:`MinJerk`: a quintic from a point (and speed) to rest, for free flight;
- :class:`Ramp`: constant velocity, the guarded move of a touch;
- :class:`Cruise`: a straight line at a cruise speed with smooth speed-up and slow-down,
  and :class:`PolylineCruise`, one Cruise per leg of a polyline (at rest at each vertex):
  the tool tip sliding along a plane, and :class:`SurfaceCruise`, the same along a path on
  any surface, with the surface's normal where the reference is.
"""
import bisect
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uav_tilt_control.surfaces import SurfacePath

# Shortest reference segment: bounds the accelerations of a segment that only has to
# bring the reference velocity to rest.
MIN_SEGMENT_S = 1.0
# Peak speed of a minimum-jerk segment (and of the 'smootherstep' speed-up of a Cruise,
# per unit of its mean) is 1.875 times the mean.
MIN_JERK_PEAK = 1.875
# A MinJerk segment that starts moving brings that start velocity v0 to rest over
# T_b = v0 * BRAKE_PEAK / BRAKE_ACCEL_M_S2 (at least MIN_SEGMENT_S, at most the segment):
# spread over the whole of a long segment, as a single quintic does, it would carry the
# reference BRAKE_REACH * v0 * T away from the line between the ends (a metre below it,
# into the ground, for a 0.3 m/s descent turned into a 17 s approach). The brake's share of the
# quintic, h(tau) = tau - 6 tau^3 + 8 tau^4 - 3 tau^5, peaks at BRAKE_REACH in position
# and BRAKE_PEAK in acceleration (per v0 T_b and v0 / T_b).
BRAKE_ACCEL_M_S2 = 1.0
BRAKE_PEAK = 3.9402
BRAKE_REACH = 16.0 / 81.0

# (p, v, a) of a segment at one time
Pva = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]


class MinJerk:
    """Minimum jerk from (p0, v0, a0) to (p1, v=0, a=0) with peak speed about v_max.

    The part of v0 along p1 - p0 carries on: with it the segment is the quintic from
    (p0, v0) to p1 over the whole of T, which reaches p1 without overshoot and never
    exceeds v_max while that part is at most MIN_JERK_PEAK |p1 - p0| / T (any more of it
    is braked like the rest). The rest of v0, and a0, are brought to rest within about
    BRAKE_ACCEL_M_S2 by a quintic that ends where it began. So a goal that moves on ahead
    of the reference (a stream of setpoints) is followed at its speed, a ramp lagging
    0.6 MIN_SEGMENT_S behind it at any rate of setpoints, instead of being braked for at
    every new one."""

    def __init__(self, t0_s: float, p0: NDArray[np.float64], p1: ArrayLike, v_max: float,
                 v0: ArrayLike = np.zeros(3), a0: ArrayLike = np.zeros(3)) -> None:
        self.t0_s = t0_s
        self.p1 = np.asarray(p1, dtype=float).copy()
        v0 = np.asarray(v0, dtype=float)
        d = self.p1 - p0
        # the norm of a float64 vector is a np.float64, so a float (numpy's stubs say floating)
        distance_m = cast(float, np.linalg.norm(d))
        self.T = max(MIN_JERK_PEAK * distance_m / v_max, MIN_SEGMENT_S)
        T = self.T
        along = d / distance_m if distance_m > 0.0 else np.zeros(3)
        v_keep = along * float(np.clip(v0 @ along, 0.0, MIN_JERK_PEAK * distance_m / T))
        v_brake = v0 - v_keep
        self.T_brake = min(max(BRAKE_PEAK * cast(float, np.linalg.norm(v_brake))
                               / BRAKE_ACCEL_M_S2, MIN_SEGMENT_S), T)
        zero = np.zeros(3)
        self._c = np.array([p0, zero, zero, 10 * d / T ** 3, -15 * d / T ** 4,
                            6 * d / T ** 5], dtype=float) + _brake_quintic(v_keep, T)
        self._brake = _brake_quintic(v_brake, self.T_brake, np.asarray(a0, dtype=float))

    def done(self, t_s: float) -> bool:
        """True once the segment has reached p1."""
        return t_s >= self.t0_s + self.T

    def sample(self, t_s: float) -> Pva:
        """(p, v, a) at ``t_s``; held at p1 after the end."""
        if self.done(t_s):
            return self.p1.copy(), np.zeros(3), np.zeros(3)
        t1 = max(t_s - self.t0_s, 0.0)
        rows = _quintic_rows(t1)
        pva = rows @ self._c
        if t1 < self.T_brake:
            pva += rows @ self._brake
        p, v, a = pva
        return p, v, a


def _brake_quintic(v0: NDArray[np.float64], T: float,
                   a0: NDArray[np.float64] = np.zeros(3)) -> NDArray[np.float64]:
    """Coefficients of the quintic from (0, v0, a0) back to (0, 0, 0) over T."""
    return np.array([np.zeros(3), v0, a0 / 2, -6 * v0 / T ** 2 - 1.5 * a0 / T,
                     8 * v0 / T ** 3 + 1.5 * a0 / T ** 2, -3 * v0 / T ** 4 - 0.5 * a0 / T ** 3],
                    dtype=float)


def _quintic_rows(t: float) -> NDArray[np.float64]:
    """Rows d^k/dt^k (k = 0, 1, 2) of (1, t, ..., t^5): one product gives p, v and a."""
    t2 = t * t
    t3 = t2 * t
    return np.array([[1.0, t, t2, t3, t3 * t, t3 * t2],
                     [0.0, 1.0, 2.0 * t, 3.0 * t2, 4.0 * t3, 5.0 * t3 * t],
                     [0.0, 0.0, 2.0, 6.0 * t, 12.0 * t2, 20.0 * t3]])


class Ramp:
    """Constant-velocity segment from p0 along ``velocity`` for at most ``duration`` s (the
    guarded move of a touch)."""

    def __init__(self, t0_s: float, p0: ArrayLike, velocity: ArrayLike,
                 duration: float) -> None:
        self.t0_s = t0_s
        self.T = float(duration)
        self._p0 = np.asarray(p0, dtype=float).copy()
        self._v = np.asarray(velocity, dtype=float).copy()
        self.p1 = self._p0 + self._v * self.T

    def done(self, t_s: float) -> bool:
        """True once the segment has run its full length."""
        return t_s >= self.t0_s + self.T

    def sample(self, t_s: float) -> Pva:
        """(p, v, a) at ``t_s``; held at the end point after the end."""
        if self.done(t_s):
            return self.p1.copy(), np.zeros(3), np.zeros(3)
        return self._p0 + self._v * max(t_s - self.t0_s, 0.0), self._v.copy(), np.zeros(3)


def smootherstep(x: float) -> tuple[float, float]:
    """(s, ds/dx) of 10x^3 - 15x^4 + 6x^5 on [0, 1]: rises from 0 to 1 with zero first and
    second derivatives at both ends."""
    x2 = x * x
    return x2 * x * (10.0 + x * (-15.0 + 6.0 * x)), 30.0 * x2 * (1.0 - x) ** 2


class Cruise:
    """From p0 to p1 on a straight line, at rest at both ends: the speed rises smoothly
    (smootherstep, continuous acceleration) to ``speed`` with at most ``accel`` m/s^2,
    cruises, and comes down the same way. A leg too short to reach ``speed`` cruises at the
    highest speed it can reach."""

    def __init__(self, t0_s: float, p0: ArrayLike, p1: ArrayLike, speed: float,
                 accel: float) -> None:
        self.t0_s = t0_s
        self._p0 = np.asarray(p0, dtype=float).copy()
        self.p1 = np.asarray(p1, dtype=float).copy()
        self.length = float(np.linalg.norm(self.p1 - self._p0))
        self._u = (self.p1 - self._p0) / self.length if self.length > 0.0 else np.zeros(3)
        # a speed-up of duration T_a to v covers v T_a / 2 with peak acceleration
        # 1.875 v / T_a (as a min-jerk segment's peak speed)
        speed = min(float(speed), float(np.sqrt(self.length * accel / MIN_JERK_PEAK)))
        self.speed = speed
        self._t_ramp = MIN_JERK_PEAK * speed / accel if speed > 0.0 else 0.0
        cruise = self.length / speed - self._t_ramp if speed > 0.0 else 0.0
        self.T = 2.0 * self._t_ramp + max(cruise, 0.0)

    def done(self, t_s: float) -> bool:
        """True once the leg has reached p1."""
        return t_s >= self.t0_s + self.T

    def distance(self, t_s: float) -> tuple[float, float, float]:
        """(s, ds/dt, d2s/dt2) along the leg at ``t_s``."""
        t = min(max(t_s - self.t0_s, 0.0), self.T)
        v, ramp = self.speed, self._t_ramp
        if ramp <= 0.0:
            return 0.0, 0.0, 0.0
        if t < ramp:
            rise, slope = smootherstep(t / ramp)
            return v * ramp * _integral_smootherstep(t / ramp), v * rise, v * slope / ramp
        if t > self.T - ramp:
            rise, slope = smootherstep((self.T - t) / ramp)
            return (self.length - v * ramp * _integral_smootherstep((self.T - t) / ramp),
                    v * rise, -v * slope / ramp)
        return v * ramp / 2.0 + v * (t - ramp), v, 0.0

    def sample(self, t_s: float) -> Pva:
        """(p, v, a) at ``t_s``; held at p1 after the end."""
        if self.done(t_s):
            return self.p1.copy(), np.zeros(3), np.zeros(3)
        s, ds, dds = self.distance(t_s)
        return self._p0 + self._u * s, self._u * ds, self._u * dds


def _integral_smootherstep(x: float) -> float:
    """The integral of the smootherstep from 0 to x (1/2 at x = 1)."""
    x2 = x * x
    return x2 * x2 * (2.5 + x * (-3.0 + x))


class PolylineCruise:
    """A :class:`Cruise` along each leg of a polyline, one after the other, at rest at each
    vertex (a corner taken at speed would need an unbounded acceleration)."""

    def __init__(self, t0_s: float, points: ArrayLike, speed: float, accel: float) -> None:
        points = np.asarray(points, dtype=float)
        self.t0_s = t0_s
        self.legs: list[Cruise] = []
        t = t0_s
        for p0, p1 in zip(points[:-1], points[1:]):
            leg = Cruise(t, p0, p1, speed, accel)
            self.legs.append(leg)
            t += leg.T
        self.T = t - t0_s
        self.p1 = points[-1].copy()
        self.length = float(sum(leg.length for leg in self.legs))

    def done(self, t_s: float) -> bool:
        """True once the last leg has ended."""
        return t_s >= self.t0_s + self.T

    def _leg(self, t_s: float) -> Cruise:
        for leg in self.legs:
            if t_s < leg.t0_s + leg.T:
                return leg
        return self.legs[-1]

    def sample(self, t_s: float) -> Pva:
        """(p, v, a) at ``t_s``; held at the last point after the end."""
        if self.done(t_s):
            return self.p1.copy(), np.zeros(3), np.zeros(3)
        return self._leg(t_s).sample(t_s)

    def progress(self, t_s: float) -> float:
        """Fraction of the polyline's length covered by the reference at ``t_s``."""
        if self.length <= 0.0 or self.done(t_s):
            return 1.0
        covered = 0.0
        for leg in self.legs:
            if t_s < leg.t0_s + leg.T:
                return (covered + leg.distance(t_s)[0]) / self.length
            covered += leg.length
        return 1.0


class SurfaceCruise:
    """A slide's reference along a :class:`~uav_tilt_control.surfaces.SurfacePath`: the
    speed along the path as :class:`PolylineCruise`'s (at rest at each of the path's own
    vertices), the point on the surface and its normal moving with it. The mission works
    in a frame that rides on that point, turned to that normal, with the body's reference
    a fixed offset out along the normal: round a curve that offset point moves faster than
    the surface's (by offset / radius) and is pulled round harder, which :meth:`sample`
    feeds forward."""

    def __init__(self, t0_s: float, path: SurfacePath, speed: float, accel: float) -> None:
        self._points = np.asarray(path.points_map, dtype=float)
        self._normals = np.asarray(path.normals_map, dtype=float)
        legs = np.linalg.norm(np.diff(self._points, axis=0), axis=1)
        self._s = np.concatenate(([0.0], np.cumsum(legs)))
        self._s_list = self._s.tolist()     # looked up every control tick
        # the step of the derivatives: a leg, so that they span the legs round a point
        self._h = float(legs.mean())
        self._cruise = PolylineCruise(t0_s, self._s[path.vertices][:, None], speed, accel)
        self.t0_s, self.T, self.length = t0_s, self._cruise.T, self._cruise.length

    def done(self, t_s: float) -> bool:
        """True once the reference has reached the path's end."""
        return self._cruise.done(t_s)

    def progress(self, t_s: float) -> float:
        """Fraction of the path's length covered by the reference at ``t_s``."""
        return self._cruise.progress(t_s)

    def at(self, s: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(point, unit normal) ``s`` metres along the path (clamped to it)."""
        starts = self._s_list
        s = min(max(s, 0.0), starts[-1])
        k = min(max(bisect.bisect_right(starts, s) - 1, 0), len(starts) - 2)
        w = (s - starts[k]) / (starts[k + 1] - starts[k])
        normal = self._normals[k] + w * (self._normals[k + 1] - self._normals[k])
        return (self._points[k] + w * (self._points[k + 1] - self._points[k]),
                normal / np.linalg.norm(normal))

    def sample(self, t_s: float, offset_m: float = 0.0
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                          NDArray[np.float64]]:
        """(point, unit normal) of the reference at ``t_s`` on the surface, and (v, a) in
        map of the point ``offset_m`` out along the normal from it."""
        s_arr, ds_arr, dds_arr = self._cruise.sample(t_s)
        s, ds, dds = float(s_arr[0]), float(ds_arr[0]), float(dds_arr[0])
        point, normal = self.at(s)

        def out(x: float) -> NDArray[np.float64]:
            p, n = self.at(x)
            return p + n * offset_m

        h, length = self._h, float(self._s[-1])
        lo, hi = max(s - h, 0.0), min(s + h, length)
        dq = (out(hi) - out(lo)) / (hi - lo)
        # the bend, where the path goes on both sides (at its ends the reference is at rest)
        ddq = (out(hi) - 2.0 * out(s) + out(lo)) / h ** 2 if h <= s <= length - h \
            else np.zeros(3)
        return point, normal, dq * ds, dq * dds + ddq * ds ** 2
