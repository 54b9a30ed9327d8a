"""Test isolation: every test run gets its own ROS domain and local-only discovery."""
import os
import sys

import pytest


def _domain_id():
    """This test process's ROS domain (Fast DDS takes 0-232): one per run, apart from
    other runs on the machine (by pid, or by the run's id under pytest-xdist), and one per
    xdist worker within a run, which runs its own graphs beside the others'."""
    if 'UAV_TILT_TEST_DOMAIN' in os.environ:
        return int(os.environ['UAV_TILT_TEST_DOMAIN'])
    worker = os.environ.get('PYTEST_XDIST_WORKER')
    if worker is None:
        return 10 + os.getpid() % 200
    count = int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1'))
    run = int(os.environ.get('PYTEST_XDIST_TESTRUNUID', '0'), 16)
    return 10 + run % max(200 // count, 1) * count + int(worker.removeprefix('gw'))


os.environ['ROS_DOMAIN_ID'] = str(_domain_id())
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('PYTHONUNBUFFERED', '1')
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def pytest_collection_modifyitems(items):
    """The `slow` files first, each in its order: pytest-xdist hands the files out in this
    order, so the long ones start at once and the short ones fill in around them."""
    items.sort(key=lambda item: item.get_closest_marker('slow') is None)


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
