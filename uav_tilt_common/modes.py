"""Mission modes as controller/status reports them (DESIGN section 3), defined once for the
mission that sets them and every reader of the status."""
import enum


class Mode(str, enum.Enum):
    """Mission modes (the value is what status reports)."""

    IDLE = 'IDLE'
    TAKEOFF = 'TAKEOFF'
    HOVER = 'HOVER'
    SEARCH = 'SEARCH'
    APPROACH = 'APPROACH'
    CONTACT = 'CONTACT'
    HOLD = 'HOLD'
    SLIDE = 'SLIDE'
    TARGET_LOST = 'TARGET_LOST'
    RETREAT = 'RETREAT'
    LAND = 'LAND'
    FAILSAFE_LAND = 'FAILSAFE_LAND'


# What controller/status says before its first odometry (the mission has not started).
WAITING_FOR_SENSORS = 'WAITING_FOR_SENSORS'
# Modes in which no mission is under way.
NOT_FLYING = (Mode.IDLE.value, WAITING_FOR_SENSORS)
