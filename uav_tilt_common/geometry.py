"""Rotor geometry of the H quadrotor and the article's wrench equations (DESIGN section 2).

Body frame ``base_link`` is FLU. The article's frame P has x_P right, y_P forward, z_P up,
so a vector converts as v_FLU = (v_P.y, -v_P.x, v_P.z).
"""
import math
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

# a short vector or quaternion as callers pass it: a numpy array, a tuple or a list
Vector = Sequence[float] | NDArray[np.float64]

# Spin sign s_i of each rotor: reaction torque s_i * k * F_i about its own thrust axis.
SPIN = np.array([1.0, -1.0, 1.0, -1.0])
# Which arm carries each rotor: 0 = front (alpha), 1 = rear (beta).
ARM_OF_ROTOR = np.array([0, 1, 1, 0])


def rotor_positions_flu(l1_m: float, l2_m: float) -> NDArray[np.float64]:
    """Rotor hub positions (4x3, FLU) for half rotor spacing l1 and half arm spacing l2."""
    return np.array([
        [l2_m, l1_m, 0.0],
        [-l2_m, l1_m, 0.0],
        [-l2_m, -l1_m, 0.0],
        [l2_m, -l1_m, 0.0],
    ])


def thrust_axes_flu(alpha_rad: float, beta_rad: float) -> NDArray[np.float64]:
    """Unit thrust direction (4x3, FLU) of each rotor; arms tilt about +y_FLU."""
    tilt = np.array([alpha_rad, beta_rad])[ARM_OF_ROTOR]
    return np.column_stack([np.sin(tilt), np.zeros(4), np.cos(tilt)])


def rotor_wrench_matrix(alpha_rad: float, beta_rad: float, l1_m: float, l2_m: float,
                        k_m: float) -> NDArray[np.float64]:
    """6x4 matrix A, [force; torque] (FLU, about the rotor centroid) = A @ thrusts_n.

    Column i is the unit-thrust wrench of rotor i from first principles:
    d_i and r_i x d_i + s_i * k * d_i, with d_i the rotor's thrust axis.
    """
    axes = thrust_axes_flu(alpha_rad, beta_rad)
    torques = _cross_rows(rotor_positions_flu(l1_m, l2_m), axes) + (SPIN * k_m)[:, None] * axes
    return np.vstack([axes.T, torques.T])


def rotor_wrench_flu(thrusts_n: ArrayLike, alpha_rad: float, beta_rad: float, l1_m: float,
                     l2_m: float, k_m: float
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Total rotor force and torque about the rotor centroid in FLU: (force_n, torque_nm)."""
    wrench = rotor_wrench_matrix(alpha_rad, beta_rad, l1_m, l2_m, k_m) @ np.asarray(
        thrusts_n, dtype=float)
    return wrench[:3], wrench[3:]


def _cross_rows(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Row-wise cross product of two (n, 3) arrays (np.cross is slow on the physics path)."""
    return np.column_stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
                            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]])


def article_wrench_p(thrusts_n: ArrayLike, alpha_rad: float, beta_rad: float, l1_m: float,
                     l2_m: float, k_m: float) -> NDArray[np.float64]:
    """The article's eq. (1)-(2) in frame P: returns (F_y, F_z, tau_x, tau_y, tau_z)."""
    f1, f2, f3, f4 = np.asarray(thrusts_n, dtype=float).tolist()
    sa, ca = math.sin(alpha_rad), math.cos(alpha_rad)
    sb, cb = math.sin(beta_rad), math.cos(beta_rad)
    return np.array([
        (f1 + f4) * sa + (f2 + f3) * sb,
        (f1 + f4) * ca + (f2 + f3) * cb,
        (f1 + f4) * l2_m * ca - (f2 + f3) * l2_m * cb,
        (f1 - f4) * (ca * l1_m + sa * k_m) + (f2 - f3) * (cb * l1_m - sb * k_m),
        (f4 - f1) * (sa * l1_m - ca * k_m) + (f3 - f2) * (sb * l1_m + cb * k_m),
    ])


def p_to_flu(v_p: ArrayLike) -> NDArray[np.float64]:
    """Convert a vector (or torque) from the article's frame P to FLU."""
    v = np.asarray(v_p, dtype=float)
    return np.array([v[1], -v[0], v[2]])


def flu_to_p(v_flu: ArrayLike) -> NDArray[np.float64]:
    """Convert a vector (or torque) from FLU to the article's frame P."""
    v = np.asarray(v_flu, dtype=float)
    return np.array([-v[1], v[0], v[2]])


def quat_to_matrix(q: NDArray[np.float64] | Sequence[float]) -> NDArray[np.float64]:
    """Rotation matrix of a unit quaternion (x, y, z, w); cheaper than scipy per call."""
    # plain floats: arithmetic on numpy scalars costs several times more
    x, y, z, w = q.tolist() if isinstance(q, np.ndarray) else q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


# Per-tick single-rotation helpers: scipy's Rotation costs 20-100 us per call through its
# array-API layer, these a few us. Quaternions are (x, y, z, w) like scipy's; results match
# scipy's Rotation to rounding.


def cross3(a: Vector, b: Vector) -> NDArray[np.float64]:
    """Cross product of two 3-vectors (np.cross costs ~20 us per call)."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def matrix_to_quat(R: ArrayLike) -> NDArray[np.float64]:
    """Unit quaternion of a rotation matrix, as scipy's ``Rotation.from_matrix.as_quat``."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = np.asarray(R, dtype=float).tolist()
    trace = m00 + m11 + m22
    decision = (m00, m11, m22, trace)
    # Shepperd's method, branch on the largest of the same four values as scipy
    choice = decision.index(max(decision))
    if choice == 0:
        q = (1.0 - trace + 2.0 * m00, m10 + m01, m20 + m02, m21 - m12)
    elif choice == 1:
        q = (m10 + m01, 1.0 - trace + 2.0 * m11, m21 + m12, m02 - m20)
    elif choice == 2:
        q = (m20 + m02, m21 + m12, 1.0 - trace + 2.0 * m22, m10 - m01)
    else:
        q = (m21 - m12, m02 - m20, m10 - m01, 1.0 + trace)
    return np.array(q) / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])


def quat_multiply(p: Vector, q: Vector) -> NDArray[np.float64]:
    """Hamilton product p * q: the rotation q followed by p (scipy's ``Rotation * ``)."""
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return np.array([pw * qx + qw * px + py * qz - pz * qy,
                     pw * qy + qw * py + pz * qx - px * qz,
                     pw * qz + qw * pz + px * qy - py * qx,
                     pw * qw - px * qx - py * qy - pz * qz])


def quat_to_rotvec(q: Vector) -> NDArray[np.float64]:
    """Rotation vector (angle in [0, pi]) of a unit quaternion, as scipy's ``as_rotvec``."""
    x, y, z, w = (float(c) for c in q)
    if w < 0.0 or (w == 0.0 and (x < 0.0 or (x == 0.0 and (y < 0.0 or (y == 0.0 and z < 0.0))))):
        x, y, z, w = -x, -y, -z, -w
    angle = 2.0 * math.atan2(math.sqrt(x * x + y * y + z * z), w)
    if angle <= 1e-3:
        # Taylor series of angle / sin(angle / 2), which is 0 / 0 at zero
        angle2 = angle * angle
        scale = 2.0 + angle2 / 12.0 + 7.0 * angle2 * angle2 / 2880.0
    else:
        scale = angle / math.sin(angle / 2.0)
    return np.array([scale * x, scale * y, scale * z])


def rotvec_to_quat(v: Vector) -> NDArray[np.float64]:
    """Unit quaternion of a rotation vector, as scipy's ``from_rotvec.as_quat``."""
    x, y, z = (float(c) for c in v)
    angle = math.sqrt(x * x + y * y + z * z)
    if angle <= 1e-3:
        # Taylor series of sin(angle / 2) / angle
        angle2 = angle * angle
        scale = 0.5 - angle2 / 48.0 + angle2 * angle2 / 3840.0
    else:
        scale = math.sin(angle / 2.0) / angle
    return np.array([scale * x, scale * y, scale * z, math.cos(angle / 2.0)])


def quat_slerp(q0: Vector, q1: Vector, u: float) -> NDArray[np.float64]:
    """Unit quaternion a fraction ``u`` of the way from q0 to q1 along the shortest arc."""
    x, y, z, w = q0
    relative = quat_multiply((-x, -y, -z, w), q1)
    return quat_multiply(q0, rotvec_to_quat(u * quat_to_rotvec(relative)))


def euler_zyx_to_matrix(yaw_rad: float, pitch_rad: float, roll_rad: float
                        ) -> NDArray[np.float64]:
    """R = Rz(yaw) Ry(pitch) Rx(roll), scipy's intrinsic 'ZYX' Euler angles."""
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    cp, sp = math.cos(pitch_rad), math.sin(pitch_rad)
    cr, sr = math.cos(roll_rad), math.sin(roll_rad)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def matrix_to_euler_zyx(R: ArrayLike) -> tuple[float, float, float]:
    """(yaw, pitch, roll) of R = Rz(yaw) Ry(pitch) Rx(roll); away from pitch = +-pi/2 these
    are scipy's ``as_euler('ZYX')``, at it roll is 0 as in scipy."""
    (m00, _, _), (m10, m11, m12), (m20, m21, m22) = np.asarray(R, dtype=float).tolist()
    pitch = -math.asin(min(max(m20, -1.0), 1.0))
    if math.hypot(m00, m10) < 1e-12:
        # gimbal lock: only yaw -+ roll is defined
        return math.atan2(m12 * math.copysign(1.0, -m20), m11), pitch, 0.0
    return math.atan2(m10, m00), pitch, math.atan2(m21, m22)


def wall_rotation(yaw_deg: float, inclination_deg: float) -> NDArray[np.float64]:
    """R_map_wall of a wall (DESIGN section 5) faced along heading ``yaw`` (from the vehicle
    to the wall) with its top leaning away by ``inclination``: columns x_W right as seen
    from in front, y_W up the wall, z_W the outward surface normal."""
    yaw, inc = math.radians(yaw_deg), math.radians(inclination_deg)
    facing = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    normal = -math.cos(inc) * facing + np.array([0.0, 0.0, math.sin(inc)])
    up = math.sin(inc) * facing + np.array([0.0, 0.0, math.cos(inc)])
    return np.column_stack([cross3(up, normal), up, normal])


def cylinder_rotation(yaw_deg: float, elevation_deg: float) -> NDArray[np.float64]:
    """Columns (c1, c2, axis): the axis at heading yaw, elevation above horizontal; c1 the
    horizontal side (heading yaw + 90 deg), c2 = axis x c1 (up for a horizontal axis). An
    angle theta about the axis is the radial cos(theta) c1 + sin(theta) c2."""
    yaw, el = math.radians(yaw_deg), math.radians(elevation_deg)
    axis = np.array([math.cos(el) * math.cos(yaw), math.cos(el) * math.sin(yaw),
                     math.sin(el)])
    c1 = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    return np.column_stack([c1, cross3(axis, c1), axis])


def wall_point(position_m: Vector, yaw_deg: float,
               inclination_deg: float, u_m: float, v_m: float) -> NDArray[np.float64]:
    """Map point at (u right, v up) on the surface of a wall whose ground line passes
    through ``position_m`` (x, y): the scenario's and the plan's wall coordinates."""
    R = wall_rotation(yaw_deg, inclination_deg)
    return np.array([position_m[0], position_m[1], 0.0]) + R[:, 0] * u_m + R[:, 1] * v_m
