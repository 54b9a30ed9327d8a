"""Exposure normalisation of the detector input: dark frames brightened, others untouched."""
import numpy as np
import pytest

from uav_tilt_vision.exposure import MAX_GAIN, TARGET_MEAN, normalize_exposure


def test_a_dark_frame_is_brightened_to_the_target_mean():
    rng = np.random.default_rng(0)
    img = rng.integers(40, 80, (240, 320, 3)).astype(np.uint8)    # mean ~60
    out = normalize_exposure(img)
    assert out.dtype == np.uint8 and out.shape == img.shape
    # the mean is estimated on a sparse sample: within 2 levels of the target
    assert out.mean() == pytest.approx(TARGET_MEAN, abs=2.0)


def test_a_well_exposed_frame_passes_unchanged():
    img = np.full((240, 320, 3), int(TARGET_MEAN) + 20, np.uint8)
    assert normalize_exposure(img) is img


def test_the_gain_is_capped():
    img = np.full((240, 320, 3), 10, np.uint8)
    assert normalize_exposure(img).max() == round(10 * MAX_GAIN)
