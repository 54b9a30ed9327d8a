"""Rendered detector data sets: format, label geometry, determinism, split separation."""

import json

import numpy as np
import pybullet as p
import pytest

from uav_tilt_sim.camera import CameraConfig, Lighting, make_renderer
from uav_tilt_sim.visuals import Scene
from uav_tilt_sim.textures import OBJECT_CLASSES, OBJECT_SIZE_M
from uav_tilt_vision.training import cli as vision_cli, dataset
from uav_tilt_vision.training.yolo_data import (IGNORE_CLASS, YoloDataset, random_crop,
                                                read_labels)


@pytest.fixture(scope='module')
def small_set(tmp_path_factory):
    out = tmp_path_factory.mktemp('ds')
    return out, dataset.generate(out, 9, seed=4, show_progress=False)


def test_yolo_layout_and_meta(small_set):
    out, meta = small_set
    assert len(YoloDataset(out)) == 9
    assert meta['classes'] == list(OBJECT_CLASSES) and meta['split'] == 'train'
    saved = json.loads((out / 'meta.json').read_text())
    assert saved['seed'] == 4 and saved['split_spec']['wall_families']
    rows = np.concatenate([read_labels(f) for f in sorted((out / 'labels').iterdir())])
    assert len(rows) == sum(meta['boxes_per_class']) > 0
    assert sorted(f.name for f in (out / 'ignore').iterdir()) == \
        sorted(f.name for f in (out / 'labels').iterdir())
    assert set(rows[:, 0].astype(int)) <= set(range(len(OBJECT_CLASSES)))
    assert np.all((rows[:, 1:] > 0) & (rows[:, 1:] <= 1))


def test_same_seed_same_images_any_job_count(small_set, tmp_path):
    out, _ = small_set
    dataset.generate(tmp_path, 9, seed=4, jobs=2, show_progress=False)
    for name in ('000000', '000008'):
        for folder in ('labels', 'ignore'):
            assert (tmp_path / folder / f'{name}.txt').read_text() == \
                (out / folder / f'{name}.txt').read_text()
        assert (tmp_path / 'images' / f'{name}.png').read_bytes() == \
            (out / 'images' / f'{name}.png').read_bytes()


def test_splits_are_disjoint():
    train, held = dataset.SPLITS['train'], dataset.SPLITS['heldout']
    assert train.stream != held.stream
    assert not set(train.wall_families) & set(held.wall_families)
    for field in ('ambient', 'diffuse', 'light_tint', 'light_azimuth_deg'):
        a, b = getattr(train, field), getattr(held, field)
        assert a[1] <= b[0] or b[1] <= a[0], field


@pytest.fixture(scope='module', params=dataset.SCENES)
def views(request):
    """(info, seg, eye, R_cam) of 24 training-split views: 4 in each of 6 worlds of a wall
    or of structures."""
    cam = CameraConfig()
    renderer = make_renderer(cam)
    client = p.connect(p.DIRECT)
    scene = Scene(client)
    out = []
    try:
        for world in range(6):
            rng = np.random.default_rng([11, world])
            info = dataset.build_random_world(scene, rng, dataset.SPLITS['train'],
                                              request.param)
            for _ in range(4):
                eye, R_cam = dataset.camera_pose(rng, info, cam)
                _, _, seg = renderer.render(scene, eye, R_cam, Lighting(), segmentation=True)
                out.append((info, seg, eye, R_cam))
            p.resetSimulation(physicsClientId=client)
            scene.clear()
    finally:
        p.disconnect(client)
        renderer.close()
    return out


def test_boxes_match_the_projected_object_faces(views):
    """Unoccluded flat objects fully in view: box == bounds of the projected face corners."""
    cam = CameraConfig()
    checked = 0
    if any(s.kind != 'wall' for info, *_ in views for s in info.structures):
        pytest.skip('an object on a pipe follows its curve: its corners do not bound it')
    for info, seg, eye, R_cam in views:
        rows, _ = dataset.labels_from_segmentation(seg, info, eye, R_cam, cam)
        for obj in info.objects:
            corners = [obj.centre_map + info.R_map_wall @ [su, sv, 0.0]
                       for su in (-OBJECT_SIZE_M / 2, OBJECT_SIZE_M / 2)
                       for sv in (-OBJECT_SIZE_M / 2, OBJECT_SIZE_M / 2)]
            pc = np.array([R_cam.T @ (c - eye) for c in corners])
            uv = (cam.k_matrix() @ pc.T).T
            uv = uv[:, :2] / uv[:, 2:]
            inside = np.all((uv > 2) & (uv < [cam.width - 2, cam.height - 2]))
            if not inside or np.count_nonzero(seg == obj.body) < 400:
                continue
            box = np.concatenate([uv.min(0), uv.max(0)])
            labelled = [[(cx - w / 2) * cam.width, (cy - h / 2) * cam.height,
                         (cx + w / 2) * cam.width, (cy + h / 2) * cam.height]
                        for c, cx, cy, w, h in rows
                        if c == OBJECT_CLASSES.index(obj.cls)]
            assert labelled, 'a fully visible object got no label'
            best = min(labelled, key=lambda b: np.abs(np.subtract(b, box)).max())
            # 1.5 px: rasterisation of the edges (pixel centres) on each side
            np.testing.assert_allclose(best, box, atol=1.5)
            checked += 1
    assert checked >= 3


def test_every_object_in_view_is_labelled_or_an_ignore_region(views):
    """Objects with visible pixels split by the visibility rule; none is dropped."""
    cam = CameraConfig()
    n_ignored = 0
    for info, seg, eye, R_cam in views:
        rows, ignore = dataset.labels_from_segmentation(seg, info, eye, R_cam, cam)
        expected = {True: [], False: []}
        for obj in info.objects:
            ys, xs = np.nonzero(seg == obj.body)
            if len(xs) == 0:
                continue
            full = dataset.projected_area(obj.centre_map, obj.R_map_surface, eye, R_cam, cam)
            visible = len(xs) >= max(dataset.MIN_VISIBLE_PX,
                                     dataset.MIN_VISIBLE_FRACTION * full)
            # pixel bounds, centre and size normalised like a YOLO row
            x1, x2, y1, y2 = xs.min(), xs.max() + 1, ys.min(), ys.max() + 1
            expected[visible].append([OBJECT_CLASSES.index(obj.cls),
                                      (x1 + x2) / 2 / cam.width, (y1 + y2) / 2 / cam.height,
                                      (x2 - x1) / cam.width, (y2 - y1) / cam.height])
        np.testing.assert_allclose(np.reshape(rows, (-1, 5)),
                                   np.reshape(expected[True], (-1, 5)))
        np.testing.assert_allclose(np.reshape(ignore, (-1, 5)),
                                   np.reshape(expected[False], (-1, 5)))
        n_ignored += len(ignore)
    assert n_ignored >= 1, 'no view has a partly visible object; the test checks nothing'


def test_structure_scenes_put_objects_on_the_campaign_s_structures(views):
    """Structure worlds are of the campaign's kinds other than a wall, every object on one
    of them, and most views label an object."""
    if all(s.kind == 'wall' for info, *_ in views for s in info.structures):
        pytest.skip('a wall scene')
    cam, kinds, labelled = CameraConfig(), set(), 0
    for info, seg, eye, R_cam in views:
        ids = {s.id for s in info.structures}
        assert info.objects and all(o.on in ids for o in info.objects)
        kinds.add(tuple(sorted(s.id for s in info.structures)))
        labelled += bool(dataset.labels_from_segmentation(seg, info, eye, R_cam, cam)[0])
    assert len(kinds) >= 3 and labelled >= len(views) // 2, (kinds, labelled)


def test_photometric_keeps_shape_and_changes_pixels():
    rng = np.random.default_rng(0)
    img = np.full((24, 32, 3), 128, np.uint8)
    out = dataset.photometric(img, rng)
    assert out.shape == img.shape and out.dtype == np.uint8 and not np.array_equal(out, img)


def test_unknown_split_is_refused(tmp_path):
    with pytest.raises(ValueError, match='split'):
        dataset.generate(tmp_path, 1, split='test')


def test_random_crop_keeps_an_object_and_clips_boxes():
    img = np.arange(256 * 320 * 3, dtype=np.uint32).reshape(256, 320, 3).astype(np.uint8)
    lab = np.array([[1, 100.0, 100.0, 60, 60], [2, 220.0, 150.0, 80, 80],
                    [IGNORE_CLASS, 20.0, 20.0, 10, 10]])
    n_cut = 0
    for seed in range(20):
        out, kept = random_crop(img, lab, (192, 160), np.random.default_rng(seed))
        labelled, cut = kept[kept[:, 0] != IGNORE_CLASS], kept[kept[:, 0] == IGNORE_CLASS]
        assert out.shape == (160, 192, 3) and len(labelled) >= 1
        x1y1, x2y2 = kept[:, 1:3] - kept[:, 3:] / 2, kept[:, 1:3] + kept[:, 3:] / 2
        assert np.all(x1y1 >= 0) and np.all(x2y2 <= [192, 160])
        assert np.all(kept[:, 3] * kept[:, 4] > 0)
        # every box still labelled keeps at least 40 % of its area
        full = np.where(labelled[:, 0] == 1, 3600.0, 6400.0)
        assert np.all(labelled[:, 3] * labelled[:, 4] >= 0.4 * full - 1e-6)
        # a label cut further is not dropped but becomes an ignore region
        n_cut += int(np.sum(cut[:, 3] * cut[:, 4] > 100))
    assert n_cut >= 1


@pytest.mark.parametrize('distance_m', [(0.4, 0.6), (4.5, 5.0)])
def test_camera_looks_at_the_wall_from_the_asked_distance(distance_m):
    cam, client = CameraConfig(), p.connect(p.DIRECT)
    try:
        seed = int(np.random.default_rng().integers(2**31))
        rng = np.random.default_rng(seed)
        info = dataset.build_random_world(Scene(client), rng, dataset.SPLITS['train'])
        n = info.R_map_wall[:, 2]
        for _ in range(40):
            eye, R_cam = dataset.camera_pose(rng, info, cam, distance_m)
            if eye[2] <= 0.15:      # lifted off the ground: no longer on the drawn ray
                continue
            # along the optical axis to the wall's plane: the drawn distance (the objects it aims
            # at stand out of the plane by their thickness, a few mm)
            t = (info.wall_origin_map - eye) @ n / (R_cam[:, 2] @ n)
            assert distance_m[0] - 0.02 <= t <= distance_m[1] + 0.02, (seed, t)
    finally:
        p.disconnect(client)


def test_cli_dataset_prints_json(tmp_path, capsys):
    assert vision_cli.main(['dataset', '--out', str(tmp_path), '--n', '2', '--seed', '3',
                            '--split', 'heldout', '--distance-m', '1', '2']) == 0
    out = json.loads(capsys.readouterr().out)
    assert out['seed'] == 3 and out['split'] == 'heldout' and out['n'] == 2
    assert out['distance_m'] == [1.0, 2.0]
    assert json.loads((tmp_path / 'meta.json').read_text())['distance_m'] == [1.0, 2.0]
    assert len(list((tmp_path / 'images').iterdir())) == 2


@pytest.mark.parametrize('bad', [['dataset', '--out', 'x', '--n', '1', '--distance-m', '3', '1'],
                                 ['dataset', '--out', 'x', '--n', '1', '--distance-m', '0', '1'],
                                 ['eval', '--data', 'x', '--bootstrap', '-1']])
def test_cli_refuses_bad_ranges_with_exit_2(bad, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:
        vision_cli.main(bad)
    assert stop.value.code == 2 and 'must be' in capsys.readouterr().err
    assert not (tmp_path / 'x').exists()
