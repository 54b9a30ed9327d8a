"""The H quadrotor as a PyBullet multibody: hub, two tilting arms, a tool on a F/T joint.

Link frames are aligned with base_link (FLU) at zero tilt. The arms turn about +y_FLU
(DESIGN section 2). A counterweight inside the hub keeps the centre of mass at the rotor
centroid, so equal thrusts hover without torque.
"""
import dataclasses

import numpy as np
from numpy.typing import NDArray

from uav_tilt_common.geometry import Vector
from uav_tilt_common.vehicle import VehicleParams, check_body
from uav_tilt_sim.bullet import pybullet as p
from uav_tilt_sim.visuals import BOX, CYLINDER, SPHERE, Scene, Visual, pybullet_shape

ARM_FRONT, ARM_REAR, TOOL = 0, 1, 2     # link indices = joint indices
TOOL_ROOT_X_M = 0.10                    # where the tool rod leaves the hub
HUB_HALF_EXTENTS_M = (0.08, 0.07, 0.05)
HUB_CENTRE_Z_M = -0.03                  # hub hangs below the arms; its bottom is the skid
VISUAL_CLEARANCE_M = 0.06             # nothing is drawn closer to the camera than this


@dataclasses.dataclass
class BodyIds:
    """PyBullet handles of the vehicle."""

    body: int
    base_com_offset_m: np.ndarray   # base inertial frame in base_link (counterweight)
    bottom_z_m: float               # lowest point below base_link origin


def _rod_inertia(mass: float, length: float, axis: int) -> NDArray[np.float64]:
    """Principal inertia (3,) of a thin rod of ``length`` along ``axis`` (0=x, 1=y, 2=z)."""
    inertia = np.full(3, mass * length ** 2 / 12.0)
    inertia[axis] = 1e-6
    return inertia


def create_vehicle(client: int, vehicle: VehicleParams, position_m: Vector, yaw_rad: float,
                   mass_scale: float = 1.0, inertia_scale: float = 1.0,
                   scene: Scene | None = None) -> BodyIds:
    """Create the vehicle in ``client`` (its visuals in ``scene`` when given); returns
    :class:`BodyIds`.

    ``vehicle`` is a VehicleParams; mass/inertia scales model a plant that differs from it.
    """
    check_body(vehicle)         # one line for a hub left too light (a scale keeps ratios)
    mass = vehicle.mass_kg * mass_scale
    m_arm = vehicle.arm_mass_kg * mass_scale
    m_tool = vehicle.tool_mass_kg * mass_scale
    m_hub = mass - 2 * m_arm - m_tool
    tool_len = vehicle.tool_tip_x_m - TOOL_ROOT_X_M
    tool_com_x = TOOL_ROOT_X_M + tool_len / 2.0
    # Counterweight: the hub's centre of mass sits behind so the whole CoM is at the origin.
    hub_com = np.array([-m_tool * tool_com_x / m_hub, 0.0, 0.0])

    inertia_total = np.asarray(vehicle.inertia_kgm2) * inertia_scale
    arm_inertia = _rod_inertia(m_arm, 2 * vehicle.l1_m, 1)
    tool_inertia = _rod_inertia(m_tool, tool_len, 0)
    parallel = np.array([0.0, 1.0, 1.0])
    others = (2 * (arm_inertia + m_arm * vehicle.l2_m ** 2 * parallel)
              + tool_inertia + m_tool * tool_com_x ** 2 * parallel
              + m_hub * hub_com[0] ** 2 * parallel)
    hub_inertia = np.maximum(inertia_total - others, 0.1 * inertia_total)

    hub_col = p.createCollisionShape(
        p.GEOM_BOX, halfExtents=HUB_HALF_EXTENTS_M,
        collisionFramePosition=[0, 0, HUB_CENTRE_Z_M], physicsClientId=client)
    hub = [Visual(BOX, HUB_HALF_EXTENTS_M, (0.15, 0.15, 0.18, 1.0),
                  position=(0.0, 0.0, HUB_CENTRE_Z_M))]
    arm = [_arm_visual(vehicle.l1_m)]
    # ee_link is the front of the spherical tip, tool_tip_x_m ahead of base_link.
    tip_centre_x = tool_len / 2.0 - vehicle.tool_tip_radius_m
    tool_col = p.createCollisionShape(
        p.GEOM_SPHERE, radius=vehicle.tool_tip_radius_m,
        collisionFramePosition=[tip_centre_x, 0, 0], physicsClientId=client)
    # The drawn rod starts ahead of the camera, for the same near-plane reason as the arms.
    rod_start = max(TOOL_ROOT_X_M, vehicle.camera_xyz_m[0] + VISUAL_CLEARANCE_M)
    rod_len = vehicle.tool_tip_x_m - vehicle.tool_tip_radius_m - rod_start
    rod_centre = rod_start + rod_len / 2 - tool_com_x
    tool = [Visual(CYLINDER, (0.006, rod_len), (0.7, 0.7, 0.72, 1.0), position=(rod_centre, 0, 0),
                   quaternion=tuple(p.getQuaternionFromEuler([0, np.pi / 2, 0]))),
            Visual(SPHERE, (vehicle.tool_tip_radius_m,), (0.9, 0.3, 0.1, 1.0),
                   position=(tip_centre_x, 0, 0))]
    hub_vis, arm_vis, tool_vis = (pybullet_shape(client, v) for v in (hub, arm, tool))

    body = p.createMultiBody(
        baseMass=m_hub, baseCollisionShapeIndex=hub_col, baseVisualShapeIndex=hub_vis,
        basePosition=position_m, baseOrientation=p.getQuaternionFromEuler([0, 0, yaw_rad]),
        baseInertialFramePosition=hub_com.tolist(),
        linkMasses=[m_arm, m_arm, m_tool],
        linkCollisionShapeIndices=[-1, -1, tool_col],
        linkVisualShapeIndices=[arm_vis, arm_vis, tool_vis],
        linkPositions=[[vehicle.l2_m, 0, 0], [-vehicle.l2_m, 0, 0], [tool_com_x, 0, 0]],
        linkOrientations=[[0, 0, 0, 1]] * 3,
        linkInertialFramePositions=[[0, 0, 0]] * 3,
        linkInertialFrameOrientations=[[0, 0, 0, 1]] * 3,
        linkParentIndices=[0, 0, 0],
        linkJointTypes=[p.JOINT_REVOLUTE, p.JOINT_REVOLUTE, p.JOINT_FIXED],
        linkJointAxis=[[0, 1, 0], [0, 1, 0], [0, 0, 0]],
        physicsClientId=client)
    p.changeDynamics(body, -1, localInertiaDiagonal=hub_inertia.tolist(),
                     linearDamping=0.0, angularDamping=0.0, physicsClientId=client)
    for link, inertia in ((ARM_FRONT, arm_inertia), (ARM_REAR, arm_inertia),
                          (TOOL, tool_inertia)):
        # (linear/angular damping are base-only: passing them here redirects the call)
        p.changeDynamics(body, link, localInertiaDiagonal=inertia.tolist(),
                         physicsClientId=client)
    # Bullet multiplies the friction coefficients of a pair: 1 on the tip makes the wall's
    # (the scenario's) the contact's.
    p.changeDynamics(body, TOOL, lateralFriction=1.0, physicsClientId=client)
    for joint in (ARM_FRONT, ARM_REAR):
        # createMultiBody leaves the joint speed limit at 0, which freezes position motors.
        p.changeDynamics(body, joint, maxJointVelocity=50.0, physicsClientId=client)
    if scene is not None:
        for link, visuals in ((-1, hub), (ARM_FRONT, arm), (ARM_REAR, arm), (TOOL, tool)):
            scene.add(body, link, visuals, static=False)
    bottom = -(HUB_HALF_EXTENTS_M[2] - HUB_CENTRE_Z_M)
    return BodyIds(body, hub_com, bottom)


def _arm_visual(l1_m: float) -> Visual:
    """An arm rod along y. Propellers are not drawn: spinning blades are nearly invisible to
    a camera, and discs passing behind the eye-in-hand camera's near plane are mis-drawn
    by TinyRenderer (no near-plane clipping)."""
    return Visual(CYLINDER, (0.008, 2 * l1_m), (0.2, 0.2, 0.2, 1.0),
                  quaternion=tuple(p.getQuaternionFromEuler([np.pi / 2, 0, 0])))
