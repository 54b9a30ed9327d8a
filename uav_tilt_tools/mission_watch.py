"""Wait for the controller's mission to end and exit with its result (used by launch.sh).

Watches `controller/status`: the mission has started once the mode leaves IDLE and ended
when it is back in IDLE; the exit code is 0 when the status then says ``success``, else 1.
"""
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import ExternalShutdownException

from uav_tilt_common import names, parent_watch, ros_qos

# Modes in which no mission is under way.
GROUNDED = ('IDLE', 'WAITING_FOR_SENSORS')


class MissionWatch:
    """Follows a stream of controller status dicts; ``result`` is None until the end."""

    def __init__(self):
        self.started = False
        self.result = None
        self.mode = None

    def update(self, values):
        """Feed one status (key -> string value)."""
        self.mode = values.get('mode', self.mode)
        if self.mode not in GROUNDED:
            self.started = True
        elif self.started and self.mode == 'IDLE' and self.result is None:
            self.result = values.get('success') == 'True'


def main(args=None):
    """Exit 0 when the mission succeeded, 1 when it failed, 130 when interrupted first."""
    parent_watch.die_with_parent()
    rclpy.init(args=args)
    node = rclpy.create_node('mission_watch')
    watch = MissionWatch()

    def on_status(msg):
        if msg.status:
            watch.update({kv.key: kv.value for kv in msg.status[0].values})

    node.create_subscription(DiagnosticArray, names.CONTROLLER_STATUS, on_status,
                             ros_qos.STATUS)
    code = 130
    try:
        while watch.result is None and rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.5)
        if watch.result is not None:
            code = 0 if watch.result else 1
            node.get_logger().info(f'mission ended: {"success" if watch.result else "failure"}')
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == '__main__':
    raise SystemExit(main())
