"""What a recording keeps of the camera images: its ``images`` profile (DESIGN section 6).

- ``all``: every frame of every image topic;
- ``thin``: the frames at the detector's own rate (:data:`THIN_RATE_HZ`, the camera's 30 Hz
  over vision's ``detect_every`` 5): the first frame of each 1/rate period of sim time,
  by the image's header stamp, the same frame for the colour and the depth image;
- ``none``: no image (camera_info, a few hundred bytes a frame, is kept: it says when each
  frame was drawn).

The images are most of a recording's size (a 320x240 colour and depth frame pair is about
0.5 MB before compression, 30 of them a second); the report reads none of them.
"""
import math

from uav_tilt_common import cdr, names

PROFILES = ('all', 'thin', 'none')
# The image topics a profile thins or leaves out (relative names).
IMAGE_TOPICS = (names.CAMERA_COLOR, names.CAMERA_DEPTH, names.VISION_DEBUG_IMAGE)
# The detector's rate: the camera's 30 Hz (camera.rate_hz) over vision's detect_every (5).
THIN_RATE_HZ = 6.0
# A stamp this close below a period's start (of the period) is in it: stamps are whole
# nanoseconds of a frame time such as k / 30 s.
_PERIOD_TOLERANCE = 1e-6
# Periods remembered: a frame of one image topic may come after the next frames of another.
_KEPT_PERIODS = 8


def stamp_ns(data: bytes | memoryview) -> int:
    """The header stamp [ns] of a serialized message that begins with a std_msgs/Header
    (an Image); ValueError when it is not CDR."""
    return cdr.decode_clock(data)


class Thinning:
    """Which frames ``thin`` keeps, over every image topic together: the first stamp seen of
    each 1/``rate_hz`` period of sim time, and every image with that stamp."""

    def __init__(self, rate_hz: float = THIN_RATE_HZ) -> None:
        self.rate_hz = rate_hz
        self.chosen: dict[int, int] = {}      # period -> the stamp kept for it

    def keep(self, stamp: int) -> bool:
        """Whether the image stamped ``stamp`` [ns] is kept."""
        period = math.floor(stamp * 1e-9 * self.rate_hz + _PERIOD_TOLERANCE)
        if period not in self.chosen:
            if self.chosen and period < max(self.chosen) - _KEPT_PERIODS:
                return False        # long gone: its frame was kept or lost then
            self.chosen[period] = stamp
            for old in [p for p in self.chosen if p < period - _KEPT_PERIODS]:
                del self.chosen[old]
        return self.chosen[period] == stamp
