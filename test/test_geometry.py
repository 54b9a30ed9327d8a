"""The first-principles rotor wrench reproduces the article's eq. (1)-(2)."""
import numpy as np

from uav_tilt_common.geometry import (article_wrench_p, flu_to_p, p_to_flu,
                                      rotor_wrench_flu)


def test_rotor_wrench_equals_article_equations_for_random_inputs():
    rng = np.random.default_rng(0)
    for _ in range(500):
        thrusts = rng.uniform(0.0, 9.0, 4)
        alpha, beta = rng.uniform(-1.2, 1.2, 2)
        l1, l2, k = rng.uniform(0.05, 0.4), rng.uniform(0.05, 0.4), rng.uniform(0.0, 0.05)
        force, torque = rotor_wrench_flu(thrusts, alpha, beta, l1, l2, k)
        f_y, f_z, tau_x, tau_y, tau_z = article_wrench_p(thrusts, alpha, beta, l1, l2, k)
        assert np.allclose(flu_to_p(force), [0.0, f_y, f_z], atol=1e-12)
        assert np.allclose(flu_to_p(torque), [tau_x, tau_y, tau_z], atol=1e-12)


def test_frame_conversion_is_a_proper_rotation():
    v = np.array([0.3, -1.2, 2.0])
    assert np.allclose(flu_to_p(p_to_flu(v)), v)
    # x_P is right = -y_FLU; y_P is forward = x_FLU.
    assert np.allclose(p_to_flu([1, 0, 0]), [0, -1, 0])
    assert np.allclose(p_to_flu([0, 1, 0]), [1, 0, 0])
    M = np.column_stack([p_to_flu(e) for e in np.eye(3)])
    assert np.isclose(np.linalg.det(M), 1.0)
