"""Rotor geometry of the H quadrotor and the article's wrench equations (DESIGN section 2).

Body frame ``base_link`` is FLU. The article's frame P has x_P right, y_P forward, z_P up,
so a vector converts as v_FLU = (v_P.y, -v_P.x, v_P.z).
"""
import numpy as np

# Spin sign s_i of each rotor: reaction torque s_i * k * F_i about its own thrust axis.
SPIN = np.array([1.0, -1.0, 1.0, -1.0])
# Which arm carries each rotor: 0 = front (alpha), 1 = rear (beta).
ARM_OF_ROTOR = np.array([0, 1, 1, 0])


def rotor_positions_flu(l1_m, l2_m):
    """Rotor hub positions (4x3, FLU) for half rotor spacing l1 and half arm spacing l2."""
    return np.array([
        [l2_m, l1_m, 0.0],
        [-l2_m, l1_m, 0.0],
        [-l2_m, -l1_m, 0.0],
        [l2_m, -l1_m, 0.0],
    ])


def thrust_axes_flu(alpha_rad, beta_rad):
    """Unit thrust direction (4x3, FLU) of each rotor; arms tilt about +y_FLU."""
    tilt = np.array([alpha_rad, beta_rad])[ARM_OF_ROTOR]
    return np.column_stack([np.sin(tilt), np.zeros(4), np.cos(tilt)])


def rotor_wrench_matrix(alpha_rad, beta_rad, l1_m, l2_m, k_m):
    """6x4 matrix A, [force; torque] (FLU, about the rotor centroid) = A @ thrusts_n.

    Column i is the unit-thrust wrench of rotor i from first principles:
    d_i and r_i x d_i + s_i * k * d_i, with d_i the rotor's thrust axis.
    """
    axes = thrust_axes_flu(alpha_rad, beta_rad)
    torques = _cross_rows(rotor_positions_flu(l1_m, l2_m), axes) + (SPIN * k_m)[:, None] * axes
    return np.vstack([axes.T, torques.T])


def rotor_wrench_flu(thrusts_n, alpha_rad, beta_rad, l1_m, l2_m, k_m):
    """Total rotor force and torque about the rotor centroid in FLU: (force_n, torque_nm)."""
    wrench = rotor_wrench_matrix(alpha_rad, beta_rad, l1_m, l2_m, k_m) @ np.asarray(
        thrusts_n, dtype=float)
    return wrench[:3], wrench[3:]


def _cross_rows(a, b):
    """Row-wise cross product of two (n, 3) arrays (np.cross is slow on the physics path)."""
    return np.column_stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
                            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]])


def article_wrench_p(thrusts_n, alpha_rad, beta_rad, l1_m, l2_m, k_m):
    """The article's eq. (1)-(2) in frame P: returns (F_y, F_z, tau_x, tau_y, tau_z)."""
    f1, f2, f3, f4 = np.asarray(thrusts_n, dtype=float)
    sa, ca, sb, cb = np.sin(alpha_rad), np.cos(alpha_rad), np.sin(beta_rad), np.cos(beta_rad)
    return np.array([
        (f1 + f4) * sa + (f2 + f3) * sb,
        (f1 + f4) * ca + (f2 + f3) * cb,
        (f1 + f4) * l2_m * ca - (f2 + f3) * l2_m * cb,
        (f1 - f4) * (ca * l1_m + sa * k_m) + (f2 - f3) * (cb * l1_m - sb * k_m),
        (f4 - f1) * (sa * l1_m - ca * k_m) + (f3 - f2) * (sb * l1_m + cb * k_m),
    ])


def p_to_flu(v_p):
    """Convert a vector (or torque) from the article's frame P to FLU."""
    v = np.asarray(v_p, dtype=float)
    return np.array([v[1], -v[0], v[2]])


def flu_to_p(v_flu):
    """Convert a vector (or torque) from FLU to the article's frame P."""
    v = np.asarray(v_flu, dtype=float)
    return np.array([-v[1], v[0], v[2]])


def quat_to_matrix(q):
    """Rotation matrix of a unit quaternion (x, y, z, w); cheaper than scipy per call."""
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
