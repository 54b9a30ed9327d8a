"""Randomised worlds: one scenario per seed, drawn over the ranges a user's worlds span
(the wall's distance, direction, inclination, stiffness and friction, the target's place
and its look-alikes, wind, sensor noise, model mismatch), the worlds of a campaign and of
the Gymnasium environment.

``corners`` draws every range at one of its two ends instead, where failures gather. A
world whose wall carries a look-alike of the target comes with a hint (where the target is
on the wall, as a survey would say it), off the target by at most ``hint_error_m`` along
each of the wall's axes (HINT_ERROR_M): the error the controller takes a hint to have.
"""
from typing import Any, Callable

import numpy as np

from uav_tilt_common.config import from_dict
from uav_tilt_common.targets import HINT_ERROR_M, OBJECT_CLASSES
from uav_tilt_sim.scenario import Scenario, check_scenario

# The world a campaign draws from.
START_YAW_DEG = 180.0         # vehicle heading at takeoff, from the direction to the wall
WALL_DISTANCE_M = (2.0, 5.0)
WALL_YAW_DEG = 45.0           # the wall's normal off the line of sight
WALL_INCLINATION_DEG = 25.0
TARGET_HEIGHT_M = (0.8, 2.5)
TARGET_U_M = 1.5              # target within +-1.5 m of the wall's centre line
STIFFNESS_N_PER_M = (500.0, 50000.0)   # log-uniform
FRICTION = (0.2, 1.0)
MEAN_WIND_M_S = 2.0
GUST_PEAK_M_S = 3.0           # 3-sigma gust excursion
MASS_MISMATCH = 0.15
LOOKALIKE_PROB = 0.3          # a second bolt plate; the draw then has a hint (a plan)

# rng.uniform(lo, hi), or a stand-in for it
Draw = Callable[[float, float], float]


def random_draw(seed: int, corners: bool = False) -> tuple[Scenario, list[float] | None]:
    """(scenario, hint) of one randomised world: the hint (u, v on the wall, within
    HINT_ERROR_M of the target) when the wall carries a look-alike of the target, else
    None.

    ``corners``: each range (distance, yaw and inclination of the wall, the target's place,
    stiffness, friction, wind, noise, mismatch, start yaw, the hint's error) is drawn at one
    of its two ends, where failures gather; directions (where the wall and the wind are)
    and the other objects stay uniform."""
    rng = np.random.default_rng(seed)
    draw: Draw = _range_ends(rng) if corners else rng.uniform
    distance = draw(*WALL_DISTANCE_M)
    bearing = rng.uniform(-np.pi, np.pi)           # where the wall is, seen from the start
    wall_yaw = np.degrees(bearing) + draw(-WALL_YAW_DEG, WALL_YAW_DEG)
    target_u, target_v = draw(-TARGET_U_M, TARGET_U_M), draw(*TARGET_HEIGHT_M)
    objects: list[dict[str, Any]] = [dict(cls='bolt_plate', u_m=target_u, v_m=target_v,
                                          target=True)]
    taken = [(target_u, target_v)]
    hint = None
    if rng.random() < LOOKALIKE_PROB:
        u, v = _free_spot(rng, taken, 0.8, 1.5)
        objects.append(dict(cls='bolt_plate', u_m=u, v_m=v))
        hint = [target_u + draw(-HINT_ERROR_M, HINT_ERROR_M),
                target_v + draw(-HINT_ERROR_M, HINT_ERROR_M)]
    others = [c for c in OBJECT_CLASSES if c != 'bolt_plate']
    for _ in range(int(rng.integers(1, 3))):
        u, v = _free_spot(rng, taken, 0.45, 1.0)
        objects.append(dict(cls=str(rng.choice(others)), u_m=u, v_m=v))
    gust_std = draw(0.0, GUST_PEAK_M_S / 3.0)
    heading = rng.uniform(0.0, 2 * np.pi)
    mean = draw(0.0, MEAN_WIND_M_S)
    data = dict(
        seed=int(seed),
        start_yaw_deg=float(_wrap_deg(np.degrees(bearing)
                                      + draw(-START_YAW_DEG, START_YAW_DEG))),
        wall=dict(position_m=[float(distance * np.cos(bearing)),
                              float(distance * np.sin(bearing))],
                  yaw_deg=float(_wrap_deg(wall_yaw)),
                  inclination_deg=float(draw(-WALL_INCLINATION_DEG, WALL_INCLINATION_DEG)),
                  width_m=6.0,
                  stiffness_n_per_m=_log_uniform(draw, *STIFFNESS_N_PER_M),
                  friction=float(draw(*FRICTION))),
        objects=objects,
        wind=dict(mean_m_s=[float(mean * np.cos(heading)), float(mean * np.sin(heading)), 0.0],
                  gust_std_m_s=float(gust_std), gust_tau_s=float(draw(0.5, 2.0))),
        noise=dict(imu_gyro_rad_s=float(draw(0, 0.005)),
                   imu_accel_m_s2=float(draw(0, 0.1)),
                   odom_pos_m=float(draw(0, 0.002)),
                   odom_att_rad=float(draw(0, 0.003)),
                   ft_force_n=float(draw(0, 0.1)),
                   depth_m=float(draw(0, 0.003))),
        mismatch=dict(mass_scale=float(draw(1 - MASS_MISMATCH, 1 + MASS_MISMATCH)),
                      inertia_scale=float(draw(0.85, 1.15))),
    )
    return check_scenario(from_dict(Scenario, data)), hint


def _range_ends(rng: np.random.Generator) -> Draw:
    """A stand-in for ``rng.uniform(lo, hi)`` that gives lo or hi, each half the time."""
    return lambda lo, hi: float(hi if rng.random() < 0.5 else lo)


def _log_uniform(draw: Draw, lo: float, hi: float) -> float:
    """Log-uniform in [lo, hi] with ``draw`` = ``rng.uniform``; exactly an end with
    ``_range_ends`` (exp(log(500)) is not 500)."""
    return float(lo * (hi / lo) ** draw(0.0, 1.0))


def _free_spot(rng: np.random.Generator, taken: list[tuple[float, float]], min_gap_m: float,
               spread_m: float) -> tuple[float, float]:
    """(u, v) on the wall at least ``min_gap_m`` (in u or v) from every taken spot, near the
    first one; appended to ``taken``."""
    u0, v0 = taken[0]
    while True:
        u = u0 + rng.uniform(-spread_m, spread_m)
        v = float(np.clip(v0 + rng.uniform(-0.6, 0.6), 0.5, 2.9))
        if all(max(abs(u - a), abs(v - b)) >= min_gap_m for a, b in taken):
            taken.append((u, v))
            return float(u), v


def _wrap_deg(angle: float) -> float:
    return (angle + 180.0) % 360.0 - 180.0
