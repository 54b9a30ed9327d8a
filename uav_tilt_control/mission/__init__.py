"""The inspection mission and its failsafes: a plan executor that outputs the
ImpedanceSetpoints of the impedance law.

- :mod:`~uav_tilt_control.mission.executor`: :class:`Mission`, the commands, the plan and
  its task records, transitions, status and events;
- :mod:`~uav_tilt_control.mission.reference`: the working frame, its segments, rate limits,
  arrival, the setpoint;
- :mod:`~uav_tilt_control.mission.detectors`: persistence, landing, upset, a bump in free
  flight, the geofence;
- one module per family of modes, each mode a class that owns its state:
  :mod:`~uav_tilt_control.mission.flight` (IDLE, TAKEOFF, HOVER, LAND, FAILSAFE_LAND),
  :mod:`~uav_tilt_control.mission.search` (SEARCH and its confirmation),
  :mod:`~uav_tilt_control.mission.contact` (APPROACH, CONTACT, TARGET_LOST),
  :mod:`~uav_tilt_control.mission.push` (HOLD, SLIDE, RETREAT);
- :mod:`~uav_tilt_control.mission.config`: :class:`MissionConfig`, by group.
"""
from uav_tilt_common.modes import Mode
from uav_tilt_control.mission.base import NEAR_WALL
from uav_tilt_control.mission.config import MissionConfig
from uav_tilt_control.mission.executor import DEFAULT_CONTACT_FORCE_N, Mission
from uav_tilt_control.mission.records import NOT_RUN, TaskRecord

__all__ = ['DEFAULT_CONTACT_FORCE_N', 'Mission', 'MissionConfig', 'Mode', 'NEAR_WALL',
           'NOT_RUN', 'TaskRecord']
