"""run_node's SIGINT bookkeeping (no ROS graph needed)."""
import os
import signal
import time

import pytest

from uav_tilt_common.ros_params import note_sigint


@pytest.fixture
def restore_sigint():
    saved = signal.getsignal(signal.SIGINT)
    yield
    signal.signal(signal.SIGINT, saved)


def test_sigint_is_noted_and_the_default_handler_still_raises(restore_sigint):
    signal.signal(signal.SIGINT, signal.default_int_handler)
    seen = note_sigint()
    assert seen == []
    with pytest.raises(KeyboardInterrupt):
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(5)   # the handler runs as soon as the signal lands
    assert seen == [signal.SIGINT]


def test_a_quiet_previous_handler_stays_quiet(restore_sigint):
    calls = []
    signal.signal(signal.SIGINT, lambda *_: calls.append(1))   # as the recorder does
    seen = note_sigint()
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.1)
    assert seen == [signal.SIGINT] and calls == [1]
