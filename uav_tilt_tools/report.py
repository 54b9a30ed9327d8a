"""`uav-tilt report RUN_DIR`: summary.json (DESIGN section 7) and PNG plots from the MCAP.

A *recording* is a dict {topic: [(log_time_ns, message), ...]} with topics named as in
:mod:`uav_tilt_common.names` (relative to /uav, /clock absolute) and messages anything
with the ROS field attributes (decoded MCAP, rclpy messages, test doubles). Everything
past :func:`load_recording` is pure; a topic that is missing gives null values, not errors.
Times are sim time (header stamps) unless named log time (when the recorder got them).
"""
import glob
import json
import math
import os

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from uav_tilt_common import names
from uav_tilt_common.geometry import quat_to_matrix
from uav_tilt_common.ros_msgs import from_stamp
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control.mission import DEFAULT_CONTACT_FORCE_N
from uav_tilt_tools.task_metrics import task_results

# What the report reads; the camera images and the noisy sensors stay on disk.
REPORT_TOPICS = (names.CLOCK, names.GROUND_TRUTH_ODOM, names.GROUND_TRUTH_TARGET,
                 names.EE_WRENCH, names.ACTUATORS_STATE, names.ACTUATORS_CMD,
                 names.CONTROLLER_STATUS, names.VISION_STATUS, names.TARGET_POSE,
                 names.CAMERA_INFO, names.CONTROLLER_PLAN)
# ... and every topic under these (each target's ground truth, by its id)
REPORT_PREFIXES = (names.GROUND_TRUTH_TARGETS + '/',)
HOLD = 'HOLD'
NOT_FLYING = ('IDLE', 'WAITING_FOR_SENSORS')
SUMMARY_KEYS = ('success', 'poi_error_m', 'force_mean_n', 'force_rms_error_n', 'contact_lost',
                'max_force_n', 'mission_time_s', 'rtf', 'controller_rate_hz', 'vision_fps',
                'vision_latency_ms_p95', 'tasks')


def register(sub):
    """Add the `report` sub-command."""
    parser = sub.add_parser('report', help='summary.json and plots of a recorded run')
    parser.add_argument('run_dir', help='folder with the MCAP recording')
    parser.set_defaults(func=run)


def run(args):
    """Write summary.json and the plots into the run folder; print the summary."""
    from uav_tilt_tools.report_plots import write_plots   # matplotlib only when plotting
    try:
        rec = load_recording(args.run_dir)
    except FileNotFoundError as err:
        print(f'uav-tilt report: {err}')
        return 1
    tool_tip_x_m = VehicleParams().tool_tip_x_m
    summary = summarize(rec, tool_tip_x_m)
    with open(os.path.join(args.run_dir, 'summary.json'), 'w', encoding='utf-8') as stream:
        json.dump(summary, stream, indent=2)
    write_plots(rec, args.run_dir, tool_tip_x_m)
    print(json.dumps(summary))
    return 0


# --- the thin MCAP layer ------------------------------------------------------------------
def load_recording(run_dir, namespace=names.NAMESPACE, topics=REPORT_TOPICS):
    """The recording of ``topics`` in every RUN_DIR/*.mcap (FileNotFoundError if none)."""
    paths = sorted(glob.glob(os.path.join(run_dir, '*.mcap')))
    if not paths:
        raise FileNotFoundError(f'no *.mcap in {run_dir}')
    prefix = namespace.rstrip('/') + '/'
    absolute = {t if t.startswith('/') else prefix + t: t for t in topics}
    rec = {}
    for path in paths:
        with open(path, 'rb') as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            wanted = dict(absolute)
            summary = reader.get_summary()
            for channel in summary.channels.values() if summary is not None else ():
                relative = channel.topic[len(prefix):]
                if channel.topic.startswith(prefix) and relative.startswith(REPORT_PREFIXES):
                    wanted[channel.topic] = relative
            for _, channel, message, msg in reader.iter_decoded_messages(topics=list(wanted)):
                rec.setdefault(wanted[channel.topic], []).append((message.log_time, msg))
    return rec


# --- series -------------------------------------------------------------------------------
def stamp_s(msg):
    """Header stamp in seconds."""
    return from_stamp(msg.header.stamp)


def _value(text):
    """A status value as bool, float or the string itself."""
    if text in ('True', 'False'):
        return text == 'True'
    try:
        return float(text)
    except ValueError:
        return text


def statuses(rec, topic):
    """[(t_s, {key: value})] of a DiagnosticArray topic (its first status)."""
    return [(stamp_s(m), {kv.key: _value(kv.value) for kv in m.status[0].values})
            for _, m in rec.get(topic, ()) if m.status]


def runs_of_mode(ctrl, mode):
    """[(t_first, t_last)] of each run of consecutive controller statuses in ``mode``:
    strictly inside the mode, whatever the status rate."""
    runs, start, last = [], None, None
    for t, values in ctrl:
        if values.get('mode') == mode:
            start = t if start is None else start
            last = t
        elif start is not None:
            runs.append((start, last))
            start = None
    if start is not None:
        runs.append((start, last))
    return runs


def inside(t, runs):
    """Boolean mask of the times ``t`` inside any of ``runs``."""
    t = np.asarray(t, dtype=float)
    mask = np.zeros(t.shape, dtype=bool)
    for t0, t1 in runs:
        mask |= (t >= t0) & (t <= t1)
    return mask


def _pose(pose):
    p, o = pose.position, pose.orientation
    return np.array([p.x, p.y, p.z]), quat_to_matrix(np.array([o.x, o.y, o.z, o.w]))


def target_pose(rec):
    """(POI position, R_map_target) of ground_truth/target, or None."""
    msgs = rec.get(names.GROUND_TRUTH_TARGET)
    return _pose(msgs[-1][1].pose) if msgs else None


def target_poses(rec):
    """Target id ('' = the first target) -> (POI position, R_map_target) of the ground
    truth topics."""
    topics = {'': names.GROUND_TRUTH_TARGET, **{
        topic[len(names.GROUND_TRUTH_TARGETS) + 1:]: topic for topic in rec
        if topic.startswith(names.GROUND_TRUTH_TARGETS + '/')}}
    return {target_id: _pose(rec[topic][-1][1].pose) for target_id, topic in topics.items()
            if rec.get(topic)}


def plan_tasks(rec):
    """The task entries of the last controller/plan (its JSON), or None."""
    msgs = rec.get(names.CONTROLLER_PLAN)
    return json.loads(msgs[-1][1].data)['tasks'] if msgs else None


def wrench_series(rec, tool_tip_x_m):
    """(t_s, tool tips (N, 3), contact force on the vehicle (N, 3)) in map, of each
    ee_wrench with the vehicle's ground-truth pose at its stamp."""
    poses = vehicle_poses(rec)
    t, tips, forces = [], [], []
    for _, m in rec.get(names.EE_WRENCH, ()):
        pose = poses.get(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
        if pose is None:
            continue
        f = m.wrench.force
        t.append(stamp_s(m))
        tips.append(pose[0] + pose[1][:, 0] * tool_tip_x_m)
        forces.append(pose[1] @ np.array([f.x, f.y, f.z]))
    return np.array(t), np.array(tips).reshape(-1, 3), np.array(forces).reshape(-1, 3)


def task_summaries(rec, tool_tip_x_m):
    """summary.json ``tasks``: the recorded plan's results (uav_tilt_tools.task_metrics),
    or None without a plan."""
    tasks = plan_tasks(rec)
    if tasks is None:
        return None
    targets = target_poses(rec)
    normal = targets[''][1][:, 2] if '' in targets else None
    return task_results(tasks, *wrench_series(rec, tool_tip_x_m), targets, normal)


def vehicle_poses(rec):
    """{stamp_ns: (p_map, R_map_base)} of ground_truth/odom."""
    return {m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec: _pose(m.pose.pose)
            for _, m in rec.get(names.GROUND_TRUTH_ODOM, ())}


def tool_tips(rec, tool_tip_x_m):
    """(t_s, tip positions (N, 3)) of the tool tip in map from ground_truth/odom."""
    t, tips = [], []
    for _, m in rec.get(names.GROUND_TRUTH_ODOM, ()):
        p, R = _pose(m.pose.pose)
        t.append(stamp_s(m))
        tips.append(p + R[:, 0] * tool_tip_x_m)
    return np.array(t), np.array(tips).reshape(-1, 3)


def contact_forces(rec):
    """(t_s, push [N], |F| [N]) of ee_wrench. The push is the force along the surface
    normal, positive pushing (the wall's reaction along +z_target); without the target or
    the vehicle's attitude at that stamp, along -x of the tool, as the controller does."""
    target = target_pose(rec)
    poses = vehicle_poses(rec)
    t, push, magnitude = [], [], []
    for _, m in rec.get(names.EE_WRENCH, ()):
        f = m.wrench.force
        f_ee = np.array([f.x, f.y, f.z])
        pose = poses.get(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
        if target is not None and pose is not None:
            push.append(float((pose[1] @ f_ee) @ target[1][:, 2]))
        else:
            push.append(float(-f_ee[0]))
        t.append(stamp_s(m))
        magnitude.append(float(np.linalg.norm(f_ee)))
    return np.array(t), np.array(push), np.array(magnitude)


def frame_latencies_ms(rec):
    """(t_s, latency ms) per target/pose: its log time minus that of the camera_info with
    the same stamp (published with the image), i.e. image out -> pose out."""
    published = {stamp_s(m): log for log, m in rec.get(names.CAMERA_INFO, ())}
    pairs = [(stamp_s(m), (log - published[stamp_s(m)]) * 1e-6)
             for log, m in rec.get(names.TARGET_POSE, ()) if stamp_s(m) in published]
    return np.array(pairs).reshape(-1, 2).T


def detections(rec):
    """(t_s, seen) per target/pose: covariance[0] = -1 means no target in that frame."""
    pairs = [(stamp_s(m), m.pose.covariance[0] != -1.0)
             for _, m in rec.get(names.TARGET_POSE, ())]
    return np.array(pairs, dtype=float).reshape(-1, 2).T


# --- summary ------------------------------------------------------------------------------
def _number(x):
    """JSON-safe float: None for missing, non-numeric or non-finite."""
    if isinstance(x, (int, float, np.number)) and math.isfinite(float(x)):
        return float(x)
    return None


def _log_rate(log_times_ns):
    if len(log_times_ns) < 2 or log_times_ns[-1] == log_times_ns[0]:
        return None
    return (len(log_times_ns) - 1) / ((log_times_ns[-1] - log_times_ns[0]) * 1e-9)


def contact_setpoint_n(ctrl):
    """The controller's contact_force from its last status, else the default 5 N."""
    return ctrl[-1][1].get('contact_force', DEFAULT_CONTACT_FORCE_N) if ctrl \
        else DEFAULT_CONTACT_FORCE_N


def mission_time_s(ctrl):
    """Sim time from leaving IDLE to being back in IDLE (or the last status)."""
    flying = [i for i, (_, v) in enumerate(ctrl) if v.get('mode') not in NOT_FLYING]
    if not flying:
        return None
    start = ctrl[flying[0]][0]
    back = [t for t, v in ctrl[flying[0]:] if v.get('mode') == 'IDLE']
    return (back[0] if back else ctrl[-1][0]) - start


def real_time_factor(rec):
    """Sim time span over log (wall) time span of /clock."""
    clock = rec.get(names.CLOCK, ())
    if len(clock) < 2 or clock[-1][0] == clock[0][0]:
        return None
    sim = from_stamp(clock[-1][1].clock) - from_stamp(clock[0][1].clock)
    return sim / ((clock[-1][0] - clock[0][0]) * 1e-9)


def summarize(rec, tool_tip_x_m):
    """The summary.json dict (DESIGN section 7); null where the recording lacks the data."""
    ctrl = statuses(rec, names.CONTROLLER_STATUS)
    last = ctrl[-1][1] if ctrl else {}
    vision = statuses(rec, names.VISION_STATUS)
    vision_last = vision[-1][1] if vision else {}
    hold = runs_of_mode(ctrl, HOLD)
    setpoint_n = contact_setpoint_n(ctrl)

    t_f, push, magnitude = contact_forces(rec)
    held = push[inside(t_f, hold)]
    t_tip, tips = tool_tips(rec, tool_tip_x_m)
    target = target_pose(rec)
    tips_held = tips[inside(t_tip, hold)]
    latency = frame_latencies_ms(rec)[1]

    success = last.get('success')
    contact_lost = last.get('contact_lost')
    summary = dict(
        success=success if isinstance(success, bool) else None,
        poi_error_m=(float(np.mean(np.linalg.norm(tips_held - target[0], axis=1)))
                     if target is not None and len(tips_held) else None),
        force_mean_n=float(np.mean(held)) if len(held) else None,
        force_rms_error_n=(float(np.sqrt(np.mean((held - setpoint_n) ** 2)))
                           if len(held) else None),
        contact_lost=int(contact_lost) if isinstance(contact_lost, float) else None,
        max_force_n=float(np.max(magnitude)) if len(magnitude) else None,
        mission_time_s=mission_time_s(ctrl),
        rtf=real_time_factor(rec),
        controller_rate_hz=last.get('loop_rate_hz'),
        vision_fps=vision_last.get(
            'fps', _log_rate([log for log, _ in rec.get(names.TARGET_POSE, ())])),
        vision_latency_ms_p95=vision_last.get(
            'latency_ms_p95', np.percentile(latency, 95) if len(latency) else None),
    )
    summary = {k: (v if isinstance(v, (bool, int, type(None))) else _number(v))
               for k, v in summary.items()}
    summary['tasks'] = task_summaries(rec, tool_tip_x_m)
    return summary
