"""Data passed between the mission, the impedance law and the attitude loop."""
import dataclasses

import numpy as np


@dataclasses.dataclass
class ImpedanceSetpoint:
    """What the high-level impedance law tracks, in the target frame t.

    The target frame has its origin at the point of interest and z_t along the surface
    normal (out of the wall); in free flight it is ``map`` (R_map_t = I, origin 0).
    lambda_d_t is the desired position of base_link's origin in frame t.
    """

    R_map_t: np.ndarray = dataclasses.field(default_factory=lambda: np.eye(3))
    origin_map: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    lambda_d_t: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    dlambda_d_t: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    ddlambda_d_t: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    # The push along -z_t wanted at rest, and its rate fed forward: the law holds its
    # reference push_n / K_z (the contact K_z) behind lambda_d_t, eq. (6) at rest, so the
    # mission speaks of forces and the law of springs.
    push_n: float = 0.0
    dpush_n_s: float = 0.0
    # The measured push trims it (impedance.force_tau_s): a soft wall, which gives way,
    # still gets push_n. While False the trim is let go with the push.
    trim_push: bool = False
    yaw_rad: float = 0.0          # desired heading of x_FLU in map
    pitch_rad: float = 0.0        # held pitch (DESIGN section 2)
    contact_gains: bool = False   # True: the selective (contact) K, C; False: free flight
    # Sliding: cancel the measured contact force along the wall (x_t, y_t), friction, and
    # its moment about base_link; the push along z_t stays the spring of eq. (6).
    tangential_feedforward: bool = False
    # False while the ground may carry the vehicle (taking off, landing): the disturbance
    # observer's vertical axis is off, the ground's reaction is no wind.
    airborne: bool = True
