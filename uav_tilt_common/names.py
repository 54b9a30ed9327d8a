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
SETPOINT_POSE = 'setpoint/pose'
GROUND_TRUTH_ODOM = 'ground_truth/odom'
GROUND_TRUTH_TARGET = 'ground_truth/target'
GROUND_TRUTH_TARGETS = 'ground_truth/targets'     # + '/<id>': each target of a scenario
PLANT_STATUS = 'plant/status'
CONTROLLER_STATUS = 'controller/status'
CONTROLLER_PLAN = 'controller/plan'     # std_msgs/String (JSON), latched
VISION_STATUS = 'vision/status'

# Controller services (std_srvs/Trigger).
SRV_TAKEOFF = 'takeoff'
SRV_INSPECT = 'inspect'
SRV_ABORT = 'abort'
SRV_LAND = 'land'


def ground_truth_target(target_id=''):
    """The ground-truth topic of target ``target_id`` ('' = the scenario's first target)."""
    return f'{GROUND_TRUTH_TARGETS}/{target_id}' if target_id else GROUND_TRUTH_TARGET
