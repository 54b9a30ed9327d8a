"""foxglove_bridge: a live Foxglove view of the /uav graph on ws://127.0.0.1:<port>.

Streams the camera (`vision/debug_image` while vision publishes it, else the raw image),
the scene in `map` (wall, vehicle, tool, true and seen target, the plan's slide lines and
touch points as a SceneUpdate, with FrameTransforms map -> base_link -> ee_link / camera),
and force, mode (with the plan's task under way and its progress) and tilt as JSON messages
for Plot and State Transitions panels. Without foxglove-sdk it logs one line and
exits 0, so that a launch does not fail for want of a viewer.
"""
import dataclasses
import json
import sys
import time
from typing import Any, Sequence

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import String

from uav_tilt_common import names, ros_msgs, ros_qos
from uav_tilt_common.config import ConfigError, param
from uav_tilt_common.ros_params import declare_config, run_node
from uav_tilt_common.targets import is_no_target
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_sim.scenario import Scenario, load_scenario, structures_of
from uav_tilt_sim.structures import BOX, CYLINDER, WALL, WALL_THICKNESS_M, structure_of

try:
    import foxglove
    from foxglove import channels
    from foxglove import messages as fm
    from foxglove.websocket import Capability
except ImportError:
    foxglove = None     # type: ignore[assignment]

# Only local viewers: the stream is unauthenticated.
HOST = '127.0.0.1'
# The raw camera stands in for the debug image when none came for this long (wall clock).
DEBUG_IMAGE_STALE_S = 1.0
# Static scene and transforms are re-sent this often for viewers that join later.
STATIC_PERIOD_S = 1.0
NS = names.NAMESPACE + '/'
# a point or direction (x, y, z), or a quaternion (x, y, z, w)
Vec = Sequence[float] | np.ndarray


@dataclasses.dataclass
class FoxgloveConfig:
    """Parameters of the foxglove node."""

    port: int = param(8765, lo=0, hi=65535)     # 0: any free port
    scenario_file: str = param('')              # the wall drawn; empty: default scenario
    rate_hz: float = param(30.0, lo=1.0, hi=300.0)   # poses and plots, in sim time


def _float(text: Any, default: float) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return default


def _json_channel(topic: str, fields: list[tuple[str, str]]) -> 'foxglove.Channel':
    """A JSON channel whose messages hold the given (name, JSON type) fields."""
    schema = {'type': 'object', 'properties': {n: {'type': t} for n, t in fields}}
    return foxglove.Channel(NS + topic, schema=schema)


def _timestamp(stamp: Any) -> 'fm.Timestamp':
    return fm.Timestamp(sec=stamp.sec, nsec=stamp.nanosec)


def _vector(v: Vec) -> 'fm.Vector3':
    return fm.Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _quaternion(q: Vec) -> 'fm.Quaternion':
    return fm.Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))


def _pose(p: Vec, q: Vec = (0.0, 0.0, 0.0, 1.0)) -> 'fm.Pose':
    return fm.Pose(position=_vector(p), orientation=_quaternion(q))


def _transform(parent: str, child: str, p: Vec, q: Vec, stamp: 'fm.Timestamp'
               ) -> 'fm.FrameTransform':
    return fm.FrameTransform(timestamp=stamp, parent_frame_id=parent, child_frame_id=child,
                             translation=_vector(p), rotation=_quaternion(q))


def _color(r: float, g: float, b: float, a: float = 1.0) -> 'fm.Color':
    return fm.Color(r=r, g=g, b=b, a=a)


def _cube(p: Vec, q: Vec, size: Vec, color: 'fm.Color') -> 'fm.CubePrimitive':
    return fm.CubePrimitive(pose=_pose(p, q), size=_vector(size), color=color)


def _sphere(p: Vec, diameter: float, color: 'fm.Color') -> 'fm.SpherePrimitive':
    return fm.SpherePrimitive(pose=_pose(p), size=_vector([diameter] * 3), color=color)


@dataclasses.dataclass
class Shape:
    """One structure as the live view draws it, in map: a ``cube`` or a ``cylinder`` (about
    its z) of ``size`` centred at ``position``, or a mesh's ``triangles``
    (``points`` indexed by ``indices``, in its frame at ``position``)."""

    entity_id: str
    primitive: str
    position: np.ndarray
    quaternion: np.ndarray
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)
    points: np.ndarray | None = None
    indices: np.ndarray | None = None


def structure_shapes(scenario: Scenario) -> list[Shape]:
    """The scenario's structures, one shape each (id ``structure:<id>``; a world without
    structures: its wall, id ``wall``)."""
    shapes = []
    for i, cfg in enumerate(structures_of(scenario)):
        g = structure_of(cfg, f'structures[{i}]')
        q = Rotation.from_matrix(g.R).as_quat()
        entity_id = 'wall' if not scenario.structures else f'structure:{cfg.id}'
        if cfg.kind == WALL:
            shapes.append(Shape(entity_id, 'cube', g.centre_map(), q,
                                (cfg.width_m, cfg.height_m, WALL_THICKNESS_M)))
        elif cfg.kind == BOX:
            shapes.append(Shape(entity_id, 'cube', g.centre_map(), q, tuple(cfg.size_m)))
        elif cfg.kind == CYLINDER:
            d = 2 * cfg.radius_m
            shapes.append(Shape(entity_id, 'cylinder', g.position, q, (d, d, cfg.length_m)))
        else:
            assert g.mesh is not None
            shapes.append(Shape(entity_id, 'triangles', g.position, q,
                                points=g.mesh.vertices, indices=g.mesh.faces.ravel()))
    return shapes


def _entity(shape: Shape, stamp: 'fm.Timestamp') -> 'fm.SceneEntity':
    colour = _color(0.7, 0.7, 0.7, 0.6)
    pose = _pose(shape.position, shape.quaternion)
    if shape.primitive == 'cube':
        kwargs: dict[str, Any] = {'cubes': [fm.CubePrimitive(pose=pose, size=_vector(shape.size),
                                                             color=colour)]}
    elif shape.primitive == 'cylinder':
        kwargs = {'cylinders': [fm.CylinderPrimitive(pose=pose, size=_vector(shape.size),
                                                     bottom_scale=1.0, top_scale=1.0,
                                                     color=colour)]}
    else:
        assert shape.points is not None and shape.indices is not None
        kwargs = {'triangles': [fm.TriangleListPrimitive(
            pose=pose, color=colour, indices=[int(k) for k in shape.indices],
            points=[fm.Point3(x=float(x), y=float(y), z=float(z)) for x, y, z in shape.points])]}
    return fm.SceneEntity(timestamp=stamp, frame_id=names.FRAME_MAP, id=shape.entity_id,
                          **kwargs)


def _normal_arrow(p: Vec, q: Vec, color: 'fm.Color') -> 'fm.ArrowPrimitive':
    """An arrow along +z of the frame (p, q): the surface normal of a target."""
    q_arrow = (Rotation.from_quat(q) * Rotation.from_euler('y', -np.pi / 2)).as_quat()
    return fm.ArrowPrimitive(pose=_pose(p, q_arrow), shaft_length=0.2, shaft_diameter=0.01,
                             head_length=0.05, head_diameter=0.03, color=color)


class FoxgloveBridge(Node):
    """ROS subscriptions -> foxglove channels on one WebSocket server."""

    def __init__(self) -> None:
        super().__init__('foxglove')
        self.cfg = declare_config(self, FoxgloveConfig)
        self.vehicle = VehicleParams()
        self.scenario = load_scenario(self.cfg.scenario_file or None)
        try:
            self.server = foxglove.start_server(name='uav_tilt', host=HOST, port=self.cfg.port,
                                                capabilities=[Capability.Time])
        except RuntimeError as err:     # the port taken: another bridge or app has it
            raise ConfigError(f"parameter 'port' = {self.cfg.port}: {err}") from None
        self.ch_image = channels.RawImageChannel(NS + 'camera')
        self.ch_scene = channels.SceneUpdateChannel(NS + 'scene')
        self.ch_tf = channels.FrameTransformsChannel(NS + 'tf')
        self.ch_force = _json_channel('force', [('fx', 'number'), ('fy', 'number'),
                                                ('fz', 'number'), ('norm', 'number')])
        self.ch_tilt = _json_channel('tilt', [('alpha_rad', 'number'), ('beta_rad', 'number')])
        self.ch_mode = _json_channel('mode', [('mode', 'string'), ('in_contact', 'boolean'),
                                              ('success', 'boolean'), ('task', 'string'),
                                              ('task_index', 'number'),
                                              ('task_progress', 'number')])
        self.min_dt_ns = int(1e9 / self.cfg.rate_hz)
        self.last_ns: dict[str, int] = {}
        self.debug_image_wall = -np.inf

        q = ros_qos.CONTROL
        sub = ros_qos.quiet_subscription
        sub(self, Odometry, names.ODOM, self.on_odom, q)
        sub(self, WrenchStamped, names.EE_WRENCH, self.on_wrench, q)
        sub(self, JointState, names.ACTUATORS_STATE, self.on_actuators, q)
        sub(self, DiagnosticArray, names.CONTROLLER_STATUS, self.on_controller, ros_qos.STATUS)
        sub(self, Image, names.CAMERA_COLOR, self.on_camera, ros_qos.CAMERA_SUB)
        sub(self, Image, names.VISION_DEBUG_IMAGE, self.on_debug_image, ros_qos.CAMERA_SUB)
        sub(self, PoseStamped, names.GROUND_TRUTH_TARGET, self.on_true_target, ros_qos.LATCHED)
        sub(self, PoseWithCovarianceStamped, names.TARGET_POSE, self.on_seen_target, q)
        sub(self, String, names.CONTROLLER_PLAN, self.on_plan, ros_qos.LATCHED)
        self.on_static()
        # Wall clock: late viewers get the scene while sim time is paused, too.
        self.create_timer(STATIC_PERIOD_S, self.on_static,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f'Foxglove WebSocket on ws://{HOST}:{self.server.port}')

    def _due(self, key: str, stamp: Any) -> bool:
        """Rate limit per stream, in sim time."""
        ns = ros_msgs.stamp_ns(stamp)
        if ns - self.last_ns.get(key, -self.min_dt_ns) < self.min_dt_ns:
            return False
        self.last_ns[key] = ns
        return True

    # --- static scene: wall, vehicle body and tool ---------------------------------------
    def on_static(self) -> None:
        """Structures in map, body and tool in base_link, and the fixed frames of the vehicle."""
        stamp = fm.Timestamp(sec=0)
        v = self.vehicle
        entities = [
            *(_entity(shape, stamp) for shape in structure_shapes(self.scenario)),
            fm.SceneEntity(timestamp=stamp, frame_id=names.FRAME_BASE, id='vehicle',
                           frame_locked=True, cubes=[
                               _cube((0, 0, 0), (0, 0, 0, 1),
                                     (2 * v.l2_m + 0.1, 2 * v.l1_m + 0.1, 0.04),
                                     _color(0.2, 0.4, 0.9, 0.8)),
                               _cube((v.tool_tip_x_m / 2, 0, 0), (0, 0, 0, 1),
                                     (v.tool_tip_x_m, 0.01, 0.01), _color(0.3, 0.3, 0.3))]),
            fm.SceneEntity(timestamp=stamp, frame_id=names.FRAME_EE, id='tool',
                           frame_locked=True, spheres=[
                               _sphere((0, 0, 0), 2 * v.tool_tip_radius_m, _color(1, 0.5, 0))]),
        ]
        self.ch_scene.log(fm.SceneUpdate(entities=entities))
        camera = v.camera_in_base()
        R_cam, p_cam = camera.R, camera.p
        self.ch_tf.log(fm.FrameTransforms(transforms=[
            _transform(names.FRAME_BASE, names.FRAME_EE, (v.tool_tip_x_m, 0, 0), (0, 0, 0, 1),
                       stamp),
            _transform(names.FRAME_BASE, names.FRAME_CAMERA, p_cam,
                       Rotation.from_matrix(R_cam).as_quat(), stamp)]))

    # --- streams -------------------------------------------------------------------------
    def on_odom(self, msg: Any) -> None:
        """map -> base_link, and the server's clock (sim time)."""
        if not self._due('odom', msg.header.stamp):
            return
        self.server.broadcast_time(ros_msgs.stamp_ns(msg.header.stamp))
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
        self.ch_tf.log(fm.FrameTransforms(transforms=[_transform(
            names.FRAME_MAP, names.FRAME_BASE, (p.x, p.y, p.z), (o.x, o.y, o.z, o.w),
            _timestamp(msg.header.stamp))]))

    def on_wrench(self, msg: Any) -> None:
        """Contact force at the tool (ee_link)."""
        if self.ch_force.has_sinks() and self._due('force', msg.header.stamp):
            f = ros_msgs.vector_of(msg.wrench.force)
            self.ch_force.log(dict(fx=f[0], fy=f[1], fz=f[2], norm=float(np.linalg.norm(f))),
                              log_time=ros_msgs.stamp_ns(msg.header.stamp))

    def on_actuators(self, msg: Any) -> None:
        """Measured tilt of the front (alpha) and rear (beta) arms."""
        if self.ch_tilt.has_sinks() and self._due('tilt', msg.header.stamp):
            tilt = dict(zip(msg.name, msg.position))
            self.ch_tilt.log(dict(alpha_rad=tilt.get('tilt_front'),
                                  beta_rad=tilt.get('tilt_rear')),
                             log_time=ros_msgs.stamp_ns(msg.header.stamp))

    def on_controller(self, msg: Any) -> None:
        """Mission mode, contact and outcome from controller/status."""
        if msg.status:
            values = ros_msgs.diagnostics_values(msg)
            kind, target = values.get('task_kind', ''), values.get('task_target', '')
            self.ch_mode.log(dict(mode=values.get('mode', ''),
                                  in_contact=values.get('in_contact') is True,
                                  success=values.get('success') is True,
                                  task=f'{kind} {target}'.strip(),
                                  task_index=_float(values.get('task_index'), -1.0),
                                  task_progress=_float(values.get('task_progress'), 0.0)))

    def on_plan(self, msg: Any) -> None:
        """The plan's slide lines (blue, green once done) and touch points on the wall."""
        try:
            tasks = json.loads(msg.data)['tasks']
        except (ValueError, KeyError, TypeError):
            return
        lines, spheres = [], []
        for task in tasks:
            color = _color(0.1, 0.8, 0.2) if task.get('success') else _color(0.1, 0.4, 1.0)
            if task['kind'] == 'slide' and task.get('points_map'):
                lines.append(fm.LinePrimitive(
                    type=fm.LinePrimitiveLineType.LineStrip, pose=_pose((0.0, 0.0, 0.0)),
                    thickness=0.015, color=color,
                    points=[fm.Point3(x=p[0], y=p[1], z=p[2]) for p in task['points_map']]))
            elif task['kind'] == 'touch' and task.get('hint_map'):
                spheres.append(_sphere(task['hint_map'], 0.06, color))
        self.ch_scene.log(fm.SceneUpdate(entities=[fm.SceneEntity(
            frame_id=names.FRAME_MAP, id='plan', lines=lines, spheres=spheres)]))

    def on_debug_image(self, msg: Any) -> None:
        self.debug_image_wall = time.monotonic()
        self._log_image(msg)

    def on_camera(self, msg: Any) -> None:
        if time.monotonic() - self.debug_image_wall > DEBUG_IMAGE_STALE_S:
            self._log_image(msg)

    def _log_image(self, msg: Any) -> None:
        if self.ch_image.has_sinks():
            self.ch_image.log(fm.RawImage(
                timestamp=_timestamp(msg.header.stamp), frame_id=msg.header.frame_id,
                width=msg.width, height=msg.height, encoding=msg.encoding, step=msg.step,
                data=bytes(msg.data)))

    def on_true_target(self, msg: Any) -> None:
        """The target's point of interest and normal (ground truth, for comparison)."""
        p, o = msg.pose.position, msg.pose.orientation
        q = (o.x, o.y, o.z, o.w)
        self.ch_scene.log(fm.SceneUpdate(entities=[fm.SceneEntity(
            frame_id=names.FRAME_MAP, id='target_true',
            spheres=[_sphere((p.x, p.y, p.z), 0.04, _color(0, 0.8, 0, 0.8))],
            arrows=[_normal_arrow((p.x, p.y, p.z), q, _color(0, 0.8, 0))])]))

    def on_seen_target(self, msg: Any) -> None:
        """Vision's target in the camera frame; covariance[0] = -1 means none this frame."""
        if is_no_target(msg.pose.covariance):
            self.ch_scene.log(fm.SceneUpdate(deletions=[fm.SceneEntityDeletion(
                timestamp=_timestamp(msg.header.stamp), id='target_seen')]))
            return
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
        self.ch_scene.log(fm.SceneUpdate(entities=[fm.SceneEntity(
            timestamp=_timestamp(msg.header.stamp), frame_id=msg.header.frame_id,
            id='target_seen', spheres=[_sphere((p.x, p.y, p.z), 0.05, _color(1, 0, 0, 0.8))],
            arrows=[_normal_arrow((p.x, p.y, p.z), (o.x, o.y, o.z, o.w), _color(1, 0, 0))])]))

    def destroy_node(self) -> Any:
        """Close the WebSocket server with the node."""
        self.server.stop()
        return super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Entry point of the foxglove_bridge executable."""
    if foxglove is None:
        print('[foxglove] foxglove-sdk is not installed (pip install foxglove-sdk): '
              'no live view', file=sys.stderr, flush=True)
        return 0
    return run_node(FoxgloveBridge, args)


if __name__ == '__main__':
    raise SystemExit(main())
