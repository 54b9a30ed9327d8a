"""Topic, service, frame and actuator names of DESIGN section 2-3 (relative topic names)."""

NAMESPACE = '/uav'

# Frames (REP-103).
FRAME_MAP = 'map'
FRAME_BASE = 'base_link'
FRAME_CAMERA = 'camera_color_optical_frame'
FRAME_EE = 'ee_link'

# Actuators, in the order of DESIGN section 2's rotor table.
ROTOR_NAMES = ('rotor_1', 'rotor_2', 'rotor_3', 'rotor_4')
TILT_NAMES = ('tilt_front', 'tilt_rear')
ACTUATOR_NAMES = ROTOR_NAMES + TILT_NAMES

# Topics.
CLOCK = '/clock'
IMU = 'imu'
ODOM = 'odom'
EE_WRENCH = 'ee_wrench'
ACTUATORS_CMD = 'actuators/cmd'
ACTUATORS_STATE = 'actuators/state'
CAMERA_COLOR = 'camera/color/image_raw'
CAMERA_DEPTH = 'camera/depth/image_raw'
CAMERA_INFO = 'camera/camera_info'
TARGET_POSE = 'target/pose'
TARGET_CANDIDATES = 'target/candidates'
VISION_DEBUG_IMAGE = 'vision/debug_image'
VISION_PLANES = 'vision/planes'
SETPOINT_POSE = 'setpoint/pose'
GROUND_TRUTH_ODOM = 'ground_truth/odom'
GROUND_TRUTH_TARGET = 'ground_truth/target'
GROUND_TRUTH_TARGETS = 'ground_truth/targets'     # + '/<id>': each target of a scenario
PLANT_STATUS = 'plant/status'
PLANT_SCENARIO = 'plant/scenario'       # std_msgs/String (JSON), latched: the world flown
CONTROLLER_STATUS = 'controller/status'
CONTROLLER_PLAN = 'controller/plan'     # std_msgs/String (JSON), latched
VISION_STATUS = 'vision/status'

# Controller services (std_srvs/Trigger).
SRV_TAKEOFF = 'takeoff'
SRV_INSPECT = 'inspect'
SRV_ABORT = 'abort'
SRV_LAND = 'land'

# The message type of each topic (DESIGN section 3), for those that listen before the
# publishers exist (the recorder), and the topics published latched (transient local).
TOPIC_TYPES = {
    CLOCK: 'rosgraph_msgs/msg/Clock',
    IMU: 'sensor_msgs/msg/Imu',
    ODOM: 'nav_msgs/msg/Odometry',
    EE_WRENCH: 'geometry_msgs/msg/WrenchStamped',
    ACTUATORS_CMD: 'sensor_msgs/msg/JointState',
    ACTUATORS_STATE: 'sensor_msgs/msg/JointState',
    CAMERA_COLOR: 'sensor_msgs/msg/Image',
    CAMERA_DEPTH: 'sensor_msgs/msg/Image',
    CAMERA_INFO: 'sensor_msgs/msg/CameraInfo',
    TARGET_POSE: 'geometry_msgs/msg/PoseWithCovarianceStamped',
    TARGET_CANDIDATES: 'sensor_msgs/msg/PointCloud2',
    VISION_DEBUG_IMAGE: 'sensor_msgs/msg/Image',
    VISION_PLANES: 'sensor_msgs/msg/PointCloud2',
    SETPOINT_POSE: 'geometry_msgs/msg/PoseStamped',
    GROUND_TRUTH_ODOM: 'nav_msgs/msg/Odometry',
    GROUND_TRUTH_TARGET: 'geometry_msgs/msg/PoseStamped',
    PLANT_STATUS: 'diagnostic_msgs/msg/DiagnosticArray',
    PLANT_SCENARIO: 'std_msgs/msg/String',
    CONTROLLER_STATUS: 'diagnostic_msgs/msg/DiagnosticArray',
    CONTROLLER_PLAN: 'std_msgs/msg/String',
    VISION_STATUS: 'diagnostic_msgs/msg/DiagnosticArray',
}
LATCHED_TOPICS = (GROUND_TRUTH_TARGET, CONTROLLER_PLAN, PLANT_SCENARIO)
# The recorder's node name, and the longest a recorded run (hold_until_recorded) waits for
# it to listen before it starts anyway (wall clock).
RECORDER_NODE = 'recorder'
RECORDER_WAIT_S = 30.0


def is_latched(topic):
    """Whether the contract's publisher of ``topic`` (relative name) latches it: the plan,
    the scenario and every target's ground truth."""
    return topic in LATCHED_TOPICS or topic.startswith(GROUND_TRUTH_TARGETS + '/')


def ground_truth_target(target_id=''):
    """The ground-truth topic of target ``target_id`` ('' = the scenario's first target)."""
    return f'{GROUND_TRUTH_TARGETS}/{target_id}' if target_id else GROUND_TRUTH_TARGET
