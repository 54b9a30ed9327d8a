"""Reading a recorded run: the MCAP files of RUN_DIR and the series the report needs.

A *recording* is a dict {topic: [(log_time_ns, message), ...]} in the order the recorder got
them, with topics named as in :mod:`uav_tilt_common.names` (relative to /uav, /clock
absolute) and messages anything with the ROS field attributes the series read (decoded
MCAP, the topics of every tick and frame cut down to those fields as they are read,
:data:`SLIM`; rclpy messages; test doubles). Everything past :func:`load_recording` is
pure; a topic that is missing gives empty series, not errors. Times are sim time (header
stamps) unless named log time (when the recorder got them).
"""
import collections
import glob
import json
import os
import struct
from typing import Any, Callable, Iterable

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap.writer import MCAP0_MAGIC
from mcap_ros2.decoder import DecoderFactory

from uav_tilt_common import names
from uav_tilt_common.geometry import quat_to_matrix
from uav_tilt_common.ros_msgs import diagnostics_values, from_stamp, stamp_ns
from uav_tilt_common.targets import is_no_target
from uav_tilt_tools.metrics.mission import push_along_normal

# {topic: [(log_time_ns, message), ...]}, see the module docstring
Recording = dict[str, list[tuple[int, Any]]]
# (POI position, R_map_target) of a target, or (p_map, R_map_base) of the vehicle
Pose3 = tuple[np.ndarray, np.ndarray]

# What the report reads; the camera images and the noisy sensors stay on disk.
REPORT_TOPICS = (names.GROUND_TRUTH_ODOM, names.GROUND_TRUTH_TARGET,
                 names.EE_WRENCH, names.ACTUATORS_STATE, names.ACTUATORS_CMD,
                 names.CONTROLLER_STATUS, names.VISION_STATUS, names.PLANT_STATUS,
                 names.TARGET_POSE, names.CAMERA_INFO, names.CONTROLLER_PLAN,
                 names.PLANT_SCENARIO)
# ... and every topic under these (each target's ground truth, by its id)
REPORT_PREFIXES = (names.GROUND_TRUTH_TARGETS + '/',)
# What reading a file that ends early may raise at its torn tail (OSError: a seek before
# the start of a file shorter than MCAP's footer).
TORN_TAIL = (McapError, EOFError, struct.error, ValueError, OSError)


# The fields the report reads of the topics that come every tick or frame, kept as they are
# read: a decoded Odometry takes about 5 KB of Python objects (two 36-float covariances, the
# twist), its stamp and pose as these tuples 0.6 KB.
Stamp = collections.namedtuple('Stamp', 'sec nanosec')
Header = collections.namedtuple('Header', 'stamp')
Vector = collections.namedtuple('Vector', 'x y z')
Quaternion = collections.namedtuple('Quaternion', 'x y z w')
Pose = collections.namedtuple('Pose', 'position orientation')
PoseHolder = collections.namedtuple('PoseHolder', 'pose')
Odometry = collections.namedtuple('Odometry', 'header pose')
WrenchStamped = collections.namedtuple('WrenchStamped', 'header wrench')
Wrench = collections.namedtuple('Wrench', 'force')
JointState = collections.namedtuple('JointState', 'header position effort')
Stamped = collections.namedtuple('Stamped', 'header')


def _header(msg: Any) -> Header:
    return Header(Stamp(msg.header.stamp.sec, msg.header.stamp.nanosec))


def _odometry(msg: Any) -> Odometry:
    p, o = msg.pose.pose.position, msg.pose.pose.orientation
    return Odometry(_header(msg), PoseHolder(Pose(Vector(p.x, p.y, p.z),
                                                  Quaternion(o.x, o.y, o.z, o.w))))


def _wrench(msg: Any) -> WrenchStamped:
    f = msg.wrench.force
    return WrenchStamped(_header(msg), Wrench(Vector(f.x, f.y, f.z)))


def _joint_state(msg: Any) -> JointState:
    return JointState(_header(msg), tuple(msg.position), tuple(msg.effort))


SLIM: dict[str, Callable[[Any], Any]] = {
    names.GROUND_TRUTH_ODOM: _odometry, names.EE_WRENCH: _wrench,
    names.ACTUATORS_STATE: _joint_state, names.ACTUATORS_CMD: _joint_state,
    names.CAMERA_INFO: lambda msg: Stamped(_header(msg))}


class RecordingError(ValueError):
    """A run that cannot be read as one recording: no MCAP file, or several."""


class NotMcap(RecordingError):
    """A RUN_DIR/*.mcap that is no MCAP file."""


def recording_file(run: str) -> str:
    """The MCAP file of ``run``: the file itself, or the one ``*.mcap`` in the folder
    (RecordingError when there is none, or several: the runs of a folder are not merged)."""
    if os.path.isfile(run):
        return run
    if not os.path.isdir(run):
        raise RecordingError(f'{run}: no such folder or file')
    paths = sorted(glob.glob(os.path.join(run, '*.mcap')))
    if not paths:
        raise RecordingError(f'no *.mcap in {run}')
    if len(paths) > 1:
        raise RecordingError(f'{len(paths)} MCAP files in {run} '
                             f'({", ".join(os.path.basename(p) for p in paths)}): '
                             f'give the one to read')
    return paths[0]


def load_recording(run: str, namespace: str = names.NAMESPACE,
                   topics: Iterable[str] = REPORT_TOPICS, notes: list[str] | None = None,
                   prefixes: Iterable[str] = REPORT_PREFIXES,
                   progress: Callable[[int, int], None] | None = None) -> Recording:
    """The recording of ``topics`` and of the topics under ``prefixes`` in the MCAP file of
    ``run`` (:func:`recording_file`; NotMcap for a file that is no MCAP).

    A file without its summary (the recorder was killed) is read up to its last complete
    chunk; one line about it goes to ``notes`` (a list) when given. ``progress(read,
    size)``, when given, is told the bytes read so far of the file's size as it goes.
    """
    path = recording_file(run)
    prefix = namespace.rstrip('/') + '/'
    absolute = {t if t.startswith('/') else prefix + t: t for t in topics}
    rec: Recording = {}
    complete, count = _read_mcap(path, absolute, (prefix, tuple(prefixes)), rec, progress)
    if not complete and notes is not None:
        notes.append(f'{os.path.basename(path)} is incomplete (no footer: the recorder did '
                     f'not finish); read {count} messages up to its last complete chunk')
    return rec


def _read_mcap(path: str, absolute: dict[str, str], under: tuple[str, tuple[str, ...]],
               rec: Recording, progress: Callable[[int, int], None] | None = None
               ) -> tuple[bool, int]:
    """Add the messages of one file to ``rec``: those on the topics of ``absolute``
    (absolute name -> recording name) and, ``under`` = (namespace prefix, relative
    prefixes), those on the namespace's topics under the prefixes. Returns (complete,
    messages read)."""
    namespace, prefixes = under
    count = seen = 0
    decoders: dict[int, Callable[[bytes], Any]] = {}
    factory = DecoderFactory()
    size = os.path.getsize(path)
    with open(path, 'rb') as stream:
        # a killed recorder's file has its start and not its end: a file without the start
        # would otherwise read as an empty, torn recording
        if stream.read(len(MCAP0_MAGIC)) != MCAP0_MAGIC:
            raise NotMcap(f'{path} is not an MCAP file (it does not start with the MCAP '
                          f'magic)')
        stream.seek(0)
        try:
            make_reader(stream).get_summary()
            complete = True
        except TORN_TAIL:       # no footer where it belongs
            complete = False
        stream.seek(0)
        # read in file order, one chunk at a time: the seeking reader's file-order iteration
        # reads every chunk (the images too) before it yields the first message
        messages = NonSeekingReader(stream).iter_messages(
            topics=None if prefixes else list(absolute), log_time_order=False)
        while True:
            try:
                schema, channel, message = next(messages)
            except StopIteration:
                break
            except TORN_TAIL:
                if complete:
                    raise
                break           # the chunk being written when the recorder died
            seen += 1
            if progress is not None and seen % 1000 == 0:
                progress(stream.tell(), size)
            name = absolute.get(channel.topic)
            if name is None:
                relative = channel.topic[len(namespace):]
                if not (channel.topic.startswith(namespace) and relative.startswith(prefixes)):
                    continue
                name = absolute[channel.topic] = relative
            if channel.id not in decoders:
                decode = factory.decoder_for(channel.message_encoding, schema)
                # every channel of the ros2 profile is cdr, which mcap_ros2 decodes
                assert decode is not None, (channel.topic, channel.message_encoding)
                decoders[channel.id] = _slimmed(decode, SLIM.get(name))
            rec.setdefault(name, []).append(
                (message.log_time, decoders[channel.id](message.data)))
            count += 1
    return complete, count


def _slimmed(decode: Callable[[bytes], Any], slim: Callable[[Any], Any] | None
             ) -> Callable[[bytes], Any]:
    """``decode``, followed by ``slim`` when there is one (:data:`SLIM`)."""
    if slim is None:
        return decode
    return lambda data: slim(decode(data))


# --- series -------------------------------------------------------------------------------
def stamp_s(msg: Any) -> float:
    """Header stamp in seconds."""
    return from_stamp(msg.header.stamp)


def statuses(rec: Recording, topic: str) -> list[tuple[float, dict[str, Any]]]:
    """[(t_s, {key: value})] of a DiagnosticArray topic (its first status)."""
    return [(stamp_s(m), diagnostics_values(m)) for _, m in rec.get(topic, ()) if m.status]


def _pose(pose: Any) -> Pose3:
    p, o = pose.position, pose.orientation
    return np.array([p.x, p.y, p.z]), quat_to_matrix(np.array([o.x, o.y, o.z, o.w]))


def target_pose(rec: Recording) -> Pose3 | None:
    """(POI position, R_map_target) of ground_truth/target, or None."""
    msgs = rec.get(names.GROUND_TRUTH_TARGET)
    return _pose(msgs[-1][1].pose) if msgs else None


def target_poses(rec: Recording) -> dict[str, Pose3]:
    """Target id ('' = the first target) -> (POI position, R_map_target) of the ground
    truth topics."""
    topics = {'': names.GROUND_TRUTH_TARGET, **{
        topic[len(names.GROUND_TRUTH_TARGETS) + 1:]: topic for topic in rec
        if topic.startswith(names.GROUND_TRUTH_TARGETS + '/')}}
    return {target_id: _pose(rec[topic][-1][1].pose) for target_id, topic in topics.items()
            if rec.get(topic)}


def plan_tasks(rec: Recording) -> list[dict[str, Any]] | None:
    """The task entries of the last controller/plan (its JSON), or None."""
    msgs = rec.get(names.CONTROLLER_PLAN)
    return json.loads(msgs[-1][1].data)['tasks'] if msgs else None


def world(rec: Recording) -> dict[str, Any] | None:
    """The world the plant flew (plant/scenario's JSON, :mod:`uav_tilt_sim.world_json`:
    ``scenario``, ``wall``, ``objects``), or None when it was not recorded."""
    msgs = rec.get(names.PLANT_SCENARIO)
    return json.loads(msgs[-1][1].data) if msgs else None


def wrench_series(rec: Recording, tool_tip_x_m: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t_s, tool tips (N, 3), F/T force on the vehicle (N, 3), tool axes (N, 3)) in map, of
    each ee_wrench with the vehicle's ground-truth pose at its stamp."""
    poses = vehicle_poses(rec)
    t: list[float] = []
    tips: list[np.ndarray] = []
    forces: list[np.ndarray] = []
    axes: list[np.ndarray] = []
    for _, m in rec.get(names.EE_WRENCH, ()):
        pose = poses.get(stamp_ns(m.header.stamp))
        if pose is None:
            continue
        f = m.wrench.force
        t.append(stamp_s(m))
        tips.append(pose[0] + pose[1][:, 0] * tool_tip_x_m)
        forces.append(pose[1] @ np.array([f.x, f.y, f.z]))
        axes.append(pose[1][:, 0])
    return (np.array(t), np.array(tips).reshape(-1, 3), np.array(forces).reshape(-1, 3),
            np.array(axes).reshape(-1, 3))


def vehicle_poses(rec: Recording) -> dict[int, Pose3]:
    """{stamp_ns: (p_map, R_map_base)} of ground_truth/odom."""
    return {stamp_ns(m.header.stamp): _pose(m.pose.pose)
            for _, m in rec.get(names.GROUND_TRUTH_ODOM, ())}


def tool_tips(rec: Recording, tool_tip_x_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(t_s, tip positions (N, 3)) of the tool tip in map from ground_truth/odom."""
    t, tips, _ = tool_poses(rec, tool_tip_x_m)
    return t, tips


def tool_poses(rec: Recording, tool_tip_x_m: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_s, tip positions (N, 3), tool axes (N, 3)) in map from ground_truth/odom."""
    t: list[float] = []
    tips: list[np.ndarray] = []
    axes: list[np.ndarray] = []
    for _, m in rec.get(names.GROUND_TRUTH_ODOM, ()):
        p, R = _pose(m.pose.pose)
        t.append(stamp_s(m))
        tips.append(p + R[:, 0] * tool_tip_x_m)
        axes.append(R[:, 0])
    return np.array(t), np.array(tips).reshape(-1, 3), np.array(axes).reshape(-1, 3)


def contact_forces(rec: Recording) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_s, push [N], |F| [N]) of ee_wrench. The push is
    :func:`metrics.mission.push_along_normal` with the true attitude at that stamp; without
    the target or that attitude, along -x of the tool, as the controller does."""
    target = target_pose(rec)
    poses = vehicle_poses(rec)
    t: list[float] = []
    push: list[float] = []
    magnitude: list[float] = []
    for _, m in rec.get(names.EE_WRENCH, ()):
        f = m.wrench.force
        f_ee = np.array([f.x, f.y, f.z])
        pose = poses.get(stamp_ns(m.header.stamp))
        if target is not None and pose is not None:
            push.append(push_along_normal(pose[1], f_ee, target[1]))
        else:
            push.append(float(-f_ee[0]))
        t.append(stamp_s(m))
        magnitude.append(float(np.linalg.norm(f_ee)))
    return np.array(t), np.array(push), np.array(magnitude)


def frame_latencies_ms(rec: Recording) -> np.ndarray:
    """(t_s, latency ms) per target/pose: its log time minus that of the camera_info with
    the same stamp (published with the image), i.e. image out -> pose recorded, in the
    recorder's clock (sim time when it ran with use_sim_time)."""
    published = {stamp_s(m): log for log, m in rec.get(names.CAMERA_INFO, ())}
    pairs = [(stamp_s(m), (log - published[stamp_s(m)]) * 1e-6)
             for log, m in rec.get(names.TARGET_POSE, ()) if stamp_s(m) in published]
    return np.array(pairs).reshape(-1, 2).T


def detections(rec: Recording) -> np.ndarray:
    """(t_s, seen) per target/pose: covariance[0] = -1 means no target in that frame."""
    pairs = [(stamp_s(m), not is_no_target(m.pose.covariance))
             for _, m in rec.get(names.TARGET_POSE, ())]
    return np.array(pairs, dtype=float).reshape(-1, 2).T
