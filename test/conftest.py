"""Test isolation: every test run gets its own ROS domain and local-only discovery."""
import os
import sys

import pytest

# Fast DDS domain ids 0-232; the pid spreads concurrent runs on one machine apart.
os.environ['ROS_DOMAIN_ID'] = str(os.environ.get('UAV_TILT_TEST_DOMAIN', 10 + os.getpid() % 200))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('PYTHONUNBUFFERED', '1')
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.fixture
def probe():
    """An in-process ROS node recording /uav topics (see ros_graph.Probe)."""
    from ros_graph import Probe
    probe = Probe()
    yield probe
    probe.close()


@pytest.fixture
def half_rounded():
    """Rounds a model's float weights in place to what ``save_model`` stores (float16)."""
    import torch

    def round_weights(model):
        with torch.no_grad():
            for tensor in model.state_dict().values():
                if tensor.is_floating_point():
                    tensor.copy_(tensor.half())
        return model
    return round_weights
