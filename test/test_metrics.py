"""Tests of the COCO-style mAP against hand-computed cases (and pycocotools when present)."""

import numpy as np
import pytest

from uav_tilt_vision.training.metrics import (bootstrap, coco_map, confidence_intervals,
                                              mean_ap, set_matches, summarize)

GT = np.array([[0, 0, 10, 10, 0.0]])


def det(box, score, cls=0):
    return [*box, score, cls]


def test_perfect_detection_scores_one():
    assert coco_map([np.array([det([0, 0, 10, 10], 0.9)])], [GT]) == \
        {'map50': 1.0, 'map50_95': 1.0, 'ap50_per_class': {0: 1.0},
         'map50_by_area': {'small': 1.0, 'medium': None, 'large': None}}


def test_area_ranges_ignore_what_lies_outside_them():
    gts = [np.array([[0, 0, 10, 10, 0], [50, 50, 90, 90, 0.0]])]    # 100 and 1600 px^2
    preds = [np.array([det([100, 100, 140, 140], 0.95),   # medium, matches nothing
                       det([50, 50, 90, 90], 0.9),        # the medium one
                       det([200, 200, 210, 210], 0.7),    # small, matches nothing
                       det([0, 0, 10, 10], 0.5)])]        # the small one
    res = coco_map(preds, gts)
    # in each range: a false positive, then a hit; the other range's detections are
    # ignored, so precision is 1/2 at full recall (1/4 if they counted as false positives)
    assert res['map50_by_area'] == {'small': pytest.approx(0.5), 'medium': pytest.approx(0.5),
                                    'large': None}
    assert res['map50'] == pytest.approx(0.5)


def test_iou_062_matches_three_of_ten_thresholds():
    # IoU = 62 / 100: matched at 0.50, 0.55, 0.60 only
    res = coco_map([np.array([det([0, 0, 10, 6.2], 0.9)])], [GT])
    assert res['map50'] == pytest.approx(1.0)
    assert res['map50_95'] == pytest.approx(0.3)


def test_false_positive_ranked_first_gives_two_thirds():
    gts = [np.array([[0, 0, 10, 10, 0], [20, 20, 30, 30, 0.0]])]
    preds = [np.array([det([50, 50, 60, 60], 0.9), det([0, 0, 10, 10], 0.8),
                       det([20, 20, 30, 30], 0.7)])]
    # precision (0, 1/2, 2/3) at recall (0, 1/2, 1): envelope is 2/3 everywhere
    res = coco_map(preds, gts)
    assert res['map50'] == pytest.approx(2 / 3) and res['map50_95'] == pytest.approx(2 / 3)


def test_half_recall_samples_51_of_101_points():
    gts = [np.array([[0, 0, 10, 10, 0], [20, 20, 30, 30, 0.0]])]
    res = coco_map([np.array([det([0, 0, 10, 10], 0.8)])], gts)
    assert res['map50'] == pytest.approx(51 / 101)


def test_lower_scored_duplicate_does_not_lower_ap():
    preds = [np.array([det([0, 0, 10, 10], 0.9), det([0, 0, 10, 10], 0.8)])]
    assert coco_map(preds, [GT])['map50'] == pytest.approx(1.0)


def test_counted_ground_truth_wins_over_a_better_overlapping_ignored_one():
    gts = [np.array([[0, 0, 30, 30, 0], [0, 0, 40, 40, 0.0]])]      # small, medium
    preds = [np.array([det([0, 0, 31, 31], 0.9)])]   # IoU 0.94 with the small, 0.60 medium
    res = coco_map(preds, gts)
    # over all areas it takes the small one and the medium one is missed (half recall)
    assert res['map50'] == pytest.approx(51 / 101)
    assert res['map50_by_area'] == {'small': 1.0, 'medium': 1.0, 'large': None}


def test_classes_without_gt_ignored_and_missed_classes_zero():
    gts = [np.array([[0, 0, 10, 10, 0], [20, 20, 30, 30, 1.0]])]
    preds = [np.array([det([0, 0, 10, 10], 0.9, 0), det([40, 40, 50, 50], 0.9, 2)])]
    # class 0 AP 1, class 1 AP 0 (no detection), class 2 has no gt and is not averaged
    res = coco_map(preds, gts)
    assert res['map50'] == pytest.approx(0.5)
    assert res['ap50_per_class'] == {0: 1.0, 1: 0.0}


def test_only_100_detections_per_image_count():
    fps = [det([100 + i, 100, 105 + i, 105], 0.9) for i in range(100)]
    preds = [np.array(fps + [det([0, 0, 10, 10], 0.5)])]
    assert coco_map(preds, [GT])['map50'] == 0.0
    assert coco_map([np.array(fps[:99] + [det([0, 0, 10, 10], 0.5)])], [GT])['map50'] > 0


def test_greedy_matching_across_images():
    gts = [GT, GT]
    preds = [np.array([det([0, 0, 10, 10], 0.6)]), np.array([det([0, 0, 10, 10], 0.9)])]
    assert coco_map(preds, gts)['map50_95'] == pytest.approx(1.0)
    assert coco_map([np.zeros((0, 6)), np.zeros((0, 6))], gts)['map50'] == 0.0


def test_detections_inside_ignore_regions_are_neither_true_nor_false():
    # a label found at 0.8; above it two detections of the same class inside one ignore
    # region (a partly visible object): a small one wholly inside it (IoU with the region
    # 0.25, share inside 1) and one that is the region
    ignores = [np.array([[40, 40, 60, 60, 0.0]])]
    preds = [np.array([det([40, 40, 50, 50], 0.95), det([40, 40, 60, 60], 0.9),
                       det([0, 0, 10, 10], 0.8)])]
    assert coco_map(preds, [GT], ignores)['map50_95'] == pytest.approx(1.0)
    # counted as false positives without the region: precision 1/3 at full recall
    assert coco_map(preds, [GT])['map50'] == pytest.approx(1 / 3)


def test_ignore_regions_excuse_only_their_class_and_enough_overlap():
    ignores = [np.array([[40, 40, 60, 60, 1.0]])]
    other_class = [np.array([det([40, 40, 60, 60], 0.9), det([0, 0, 10, 10], 0.8)])]
    assert coco_map(other_class, [GT], ignores)['map50'] == pytest.approx(0.5)
    # 40 % of this detection lies inside the region: below 0.5, a false positive
    ignores = [np.array([[40, 40, 60, 60, 0.0]])]
    half_out = [np.array([det([52, 40, 72, 60], 0.9), det([0, 0, 10, 10], 0.8)])]
    assert coco_map(half_out, [GT], ignores)['map50'] == pytest.approx(0.5)


def test_a_label_wins_over_an_ignore_region():
    # the detection overlaps the label at IoU 0.64 and lies wholly inside the region: it is
    # the label's true positive, so a second detection of the region stays ignored
    ignores = [np.array([[0, 0, 20, 20, 0.0]])]
    preds = [np.array([det([0, 0, 10, 6.4], 0.9), det([0, 0, 20, 20], 0.8)])]
    res = coco_map(preds, [GT], ignores)
    assert res['map50'] == pytest.approx(1.0)
    assert res['map50_95'] == pytest.approx(0.3)    # IoU 0.64 with the label


def random_set(seed, n_img=12):
    rng = np.random.default_rng(seed)
    preds, gts = [], []
    for _ in range(n_img):
        g = rng.uniform(0, 200, (rng.integers(0, 6), 2))
        # sides of 8-130 px: COCO's small, medium and large objects
        g = np.concatenate([g, g + rng.uniform(8, 130, g.shape),
                            rng.integers(0, 3, (len(g), 1))], 1)
        jitter = rng.normal(0, 4, (len(g), 4)).clip(-3.9, 3.9)  # sizes >= 8 stay positive
        p = np.concatenate([g[:, :4] + jitter, rng.uniform(0.2, 1, (len(g), 1)), g[:, 4:]], 1)
        extra = rng.uniform(0, 200, (rng.integers(0, 4), 2))
        extra = np.concatenate([extra, extra + rng.uniform(8, 130, extra.shape),
                                rng.uniform(0, 1, (len(extra), 1)),
                                rng.integers(0, 3, (len(extra), 1))], 1)
        preds.append(np.concatenate([p, extra]))
        gts.append(g)
    return preds, gts


def random_ignores(seed, preds):
    """Ignore regions around some of the unmatched detections, a little larger or shifted."""
    rng = np.random.default_rng(seed + 100)
    out = []
    for p in preds:
        pick = p[rng.random(len(p)) < 0.4]
        grow = rng.uniform(-6, 10, (len(pick), 4)) * [-1, -1, 1, 1]
        out.append(np.concatenate([pick[:, :4] + grow, pick[:, 5:]], 1))
    return out


@pytest.mark.parametrize('seed, with_ignores', [(0, False), (1, False), (2, False),
                                                (3, True), (4, True), (5, True)])
def test_agrees_with_pycocotools(seed, with_ignores):
    pytest.importorskip('pycocotools')
    preds, gts = random_set(seed)
    ignores = random_ignores(seed, preds) if with_ignores else None
    ours = coco_map(preds, gts, ignores)
    ref = mean_ap(preds, gts, ignores)
    assert ref['backend'] == 'pycocotools'
    assert ours['map50'] == pytest.approx(ref['map50'], abs=1e-9)
    assert ours['map50_95'] == pytest.approx(ref['map50_95'], abs=1e-9)
    assert ours['ap50_per_class'] == pytest.approx(ref['ap50_per_class'], abs=1e-9)
    assert ours['map50_by_area'] == pytest.approx(ref['map50_by_area'], abs=1e-9)


@pytest.mark.parametrize('seed', [10, 11, 12])
def test_a_weighted_set_scores_as_the_set_holding_each_image_that_often(seed):
    # what a bootstrap draw computes from matches made once, against pycocotools (or
    # coco_map) scoring the drawn set itself, duplicates and all
    preds, gts = random_set(seed, n_img=20)
    ignores = random_ignores(seed, preds)
    weights = np.random.default_rng(seed).integers(0, 4, len(gts))
    idx = np.repeat(np.arange(len(gts)), weights)
    ref = mean_ap([preds[i] for i in idx], [gts[i] for i in idx], [ignores[i] for i in idx])
    got = summarize(set_matches(preds, gts, ignores), weights)
    for key in ('map50', 'map50_95', 'ap50_per_class', 'map50_by_area'):
        assert got[key] == pytest.approx(ref[key], abs=1e-9), key


def recall_set(n, found, rng):
    """``n`` images with one labelled box each; a ``found`` share of them detected exactly."""
    gts = [np.array([[10.0, 10.0, 60.0, 60.0, 0]]) for _ in range(n)]
    hit = rng.permutation(n) < round(found * n)
    preds = [np.array([[10.0, 10.0, 60.0, 60.0, 0.9, 0]]) if h else np.zeros((0, 6))
             for h in hit]
    return preds, gts


def test_bootstrap_interval_has_the_binomial_width():
    # AP@0.5 of a set whose detections are all right but find a share f of the objects is
    # its recall f (to the 101-point sampling); resampling images spreads it as a binomial
    # share: standard deviation sqrt(f (1 - f) / n).
    n, f = 100, 0.8
    preds, gts = recall_set(n, f, np.random.default_rng())
    samples = bootstrap(preds, gts, resamples=100, seed=1)
    lo, hi = confidence_intervals(samples)['map50']
    sd = np.sqrt(f * (1 - f) / n)
    assert lo < f < hi
    assert 0.6 * 2 * 1.96 * sd <= hi - lo <= 1.4 * 2 * 1.96 * sd
    # the same seed draws the same images: a model paired with itself differs by nothing
    again = bootstrap(preds, gts, resamples=100, seed=1)
    assert [s['map50'] for s in again] == [s['map50'] for s in samples]


def test_bootstrap_over_groups_spreads_as_the_groups_do():
    # a group (a world) found or missed as a whole: the recall varies as the share of
    # g groups found, sqrt(f (1 - f) / g), not as that of the images
    g, per, f = 20, 6, 0.5
    hit = np.random.default_rng().permutation(g) < f * g
    gts = [np.array([[10.0, 10.0, 60.0, 60.0, 0]])] * (g * per)
    preds = [np.array([[10.0, 10.0, 60.0, 60.0, 0.9, 0]]) if hit[i // per] else np.zeros((0, 6))
             for i in range(g * per)]
    lo, hi = confidence_intervals(bootstrap(preds, gts, resamples=100,
                                            groups=np.arange(g * per) // per))['map50']
    sd = np.sqrt(f * (1 - f) / g)
    assert 0.6 * 2 * 1.96 * sd <= hi - lo <= 1.4 * 2 * 1.96 * sd


def test_bootstrap_of_perfect_detections_is_one_everywhere():
    preds, gts = recall_set(50, 1.0, np.random.default_rng(0))
    ci = confidence_intervals(bootstrap(preds, gts, resamples=20))
    assert ci['map50'] == [1.0, 1.0] and ci['ap50_per_class'] == {0: [1.0, 1.0]}
    assert ci['map50_by_area']['small'] is None and ci['level'] == 0.95  # 50 px boxes
