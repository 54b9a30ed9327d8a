"""target/candidates on the wire: what vision sends comes back, and a candidate that is no
measurement (non-finite, a normal that is no unit vector) or a cloud laid out otherwise is
refused, so that the controller counts it as a rejected input."""
import numpy as np
import pytest

from uav_tilt_common import ros_msgs
from uav_tilt_common.targets import TargetCandidate


def candidate(rng):
    n = rng.normal(size=3)
    a = rng.normal(size=(3, 3)) * 1e-3
    return TargetCandidate(rng.uniform(-2, 2, 3), n / np.linalg.norm(n), a @ a.T,
                           float(rng.uniform()), int(rng.integers(0, 3)))


def test_candidates_cross_the_wire():
    rng = np.random.default_rng()
    sent = [candidate(rng) for _ in range(3)]
    back = ros_msgs.candidates_of_msg(ros_msgs.candidates_msg(sent, ros_msgs.to_stamp(2.0)))
    for a, b in zip(sent, back, strict=True):
        np.testing.assert_allclose(b.p_cam, a.p_cam, rtol=1e-6)
        np.testing.assert_allclose(b.n_cam, a.n_cam, rtol=1e-6)
        np.testing.assert_allclose(b.cov_cam, a.cov_cam, rtol=1e-5, atol=1e-12)
        assert (b.score, b.class_id) == (pytest.approx(a.score), a.class_id)


@pytest.mark.parametrize('normal, words', [
    ([0.0, 0.0, 0.0], 'unit vector'),
    ([0.0, 0.0, -2.0], 'unit vector'),
    ([np.nan, 0.0, -1.0], 'non-finite'),
])
def test_a_candidate_that_is_no_measurement_is_refused(normal, words):
    bad = candidate(np.random.default_rng(1))
    bad.n_cam = np.array(normal)
    msg = ros_msgs.candidates_msg([bad], ros_msgs.to_stamp(0.0))
    with pytest.raises(ValueError, match=words):
        ros_msgs.candidates_of_msg(msg)
