"""Smoke tests of detector training on a tiny synthetic YOLO-format data set."""

import json

import cv2
import numpy as np
import pytest
import torch

from uav_tilt_vision.detector import DEFAULT_ANCHORS, STRIDES, load_model
from uav_tilt_vision.training.train import card_path, evaluate, grown, train
from uav_tilt_vision.training.yolo_data import (IGNORE_CLASS, YoloDataset, collate,
                                                kmeans_anchors, read_labels)
from uav_tilt_vision.training.yolo_loss import YoloLoss, assign, ciou, distill_loss, \
    ignored_cells

torch.set_num_threads(2)

COLOURS = ((230, 40, 40), (40, 200, 40), (40, 80, 230))  # RGB per class


def make_dataset(root, n, seed, size=(320, 240)):
    """n images with 1-3 filled shapes: class 0 rectangle, 1 circle, 2 triangle."""
    rng = np.random.default_rng(seed)
    (root / 'images').mkdir(parents=True)
    (root / 'labels').mkdir()
    w, h = size
    for i in range(n):
        img = np.full((h, w, 3), 90, np.uint8)
        lines = []
        for _ in range(rng.integers(1, 4)):
            cls = int(rng.integers(3))
            bw, bh = rng.integers(24, 70, 2)
            x1, y1 = int(rng.integers(0, w - bw)), int(rng.integers(0, h - bh))
            x2, y2 = x1 + int(bw), y1 + int(bh)
            if cls == 0:
                cv2.rectangle(img, (x1, y1), (x2 - 1, y2 - 1), COLOURS[0], -1)
            elif cls == 1:
                box = (((x1 + x2 - 1) / 2, (y1 + y2 - 1) / 2), (float(bw), float(bh)), 0.0)
                cv2.ellipse(img, box, COLOURS[1], -1)
            else:
                tri = np.array([[x1, y2 - 1], [x2 - 1, y2 - 1], [(x1 + x2) // 2, y1]], np.int32)
                cv2.fillPoly(img, [tri], COLOURS[2])
            lines.append(f'{cls} {(x1 + x2) / 2 / w} {(y1 + y2) / 2 / h} {bw / w} {bh / h}')
        cv2.imwrite(str(root / 'images' / f'{i:03d}.png'), img[:, :, ::-1])
        (root / 'labels' / f'{i:03d}.txt').write_text('\n'.join(lines) + '\n')
    (root / 'meta.json').write_text(json.dumps({'seed': seed, 'classes': ['rect', 'disc', 'tri']}))
    return root


@pytest.fixture(scope='module')
def data8(tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp('data8'), 8, seed=3)


def test_dataset_targets_match_labels(data8):
    ds = YoloDataset(data8)
    x, t = ds[0]
    assert x.shape == (3, 256, 320) and 0.0 <= float(x.min()) <= float(x.max()) <= 1.0
    lab = ds.labels(0)
    # 320x240 letterboxed to 320x256: scale 1, 8 px band on top
    expect = lab[:, 1:] * [320, 240, 320, 240] + [0, 8, 0, 0]
    np.testing.assert_allclose(t[:, 2:].numpy(), expect, atol=1e-3)
    images, targets = collate([ds[0], ds[1]])
    assert images.shape == (2, 3, 256, 320)
    assert set(targets[:, 0].tolist()) == {0.0, 1.0}


def test_hflip_mirrors_boxes(data8):
    plain = YoloDataset(data8)
    flipped = YoloDataset(data8, augment=True, hflip=True, hsv=(0, 0, 0))
    for i in range(len(plain)):
        (x0, t0), (x1, t1) = plain[i], flipped[i]
        if not torch.equal(x0, x1):
            torch.testing.assert_close(x1, x0.flip(-1))
            np.testing.assert_allclose(t1[:, 2].numpy(), 320 - t0[:, 2].numpy(), atol=1e-4)
            return
    pytest.fail('no image was flipped in 8 draws with p = 0.5')


def test_kmeans_recovers_six_size_clusters():
    rng = np.random.default_rng(0)
    sizes = np.array([[8, 8], [16, 12], [24, 30], [48, 40], [64, 70], [100, 90.0]])
    wh = np.concatenate([s + rng.uniform(-0.5, 0.5, (10, 2)) for s in sizes])
    anchors = kmeans_anchors(wh)
    # stride-32 head (scale 0) gets the three largest sizes; within a scale by area
    np.testing.assert_allclose(anchors, [sizes[3:], sizes[:3]], atol=0.5)
    with pytest.raises(ValueError):
        kmeans_anchors(sizes[:5])


def test_read_labels_formats(tmp_path):
    (tmp_path / 'a.txt').write_text('2 0.5 0.25 0.1 0.2\n0 0.1 0.1 0.05 0.05\n')
    (tmp_path / 'empty.txt').write_text('')
    np.testing.assert_allclose(read_labels(tmp_path / 'a.txt'),
                               [[2, 0.5, 0.25, 0.1, 0.2], [0, 0.1, 0.1, 0.05, 0.05]])
    assert read_labels(tmp_path / 'empty.txt').shape == (0, 5)
    assert read_labels(tmp_path / 'missing.txt').shape == (0, 5)


def test_ciou_hand_cases():
    a = torch.tensor([[0.0, 0.0, 2.0, 2.0], [0.0, 0.0, 2.0, 2.0]])
    b = torch.tensor([[0.0, 0.0, 2.0, 2.0], [4.0, 0.0, 2.0, 2.0]])
    # identical -> 1; disjoint, same shape: 0 - centre dist^2 16 / enclosing diag^2 (36 + 4)
    torch.testing.assert_close(ciou(a, b), torch.tensor([1.0, -0.4]))


def test_assign_best_anchor_and_threshold():
    anchors = torch.tensor([[[100.0, 100.0], [50.0, 50.0], [40.0, 60.0]],
                            [[10.0, 10.0], [20.0, 20.0], [200.0, 5.0]]])
    targets = torch.tensor([[0, 0, 50, 50, 50, 50.0], [0, 1, 50, 50, 9, 400.0]])
    mask = assign(targets, anchors, 0.25)
    # 50x50: exact match (0, 1); (40, 60) has IoU 2000 / 3000 > 0.25; (100, 100) 0.25, not >
    assert mask[0].tolist() == [[False, True, True], [False, False, False]]
    # a box unlike every anchor still gets its best one (40x60: IoU 540 / 5460)
    assert mask[1].tolist() == [[False, False, True], [False, False, False]]


def test_ignore_regions_follow_the_labels_as_targets(tmp_path):
    data = make_dataset(tmp_path / 'data', 2, seed=5)
    (data / 'ignore').mkdir()
    (data / 'ignore' / '000.txt').write_text('2 0.5 0.5 0.1 0.2\n')
    ds = YoloDataset(data)
    _, t = ds[0]
    n = len(ds.labels(0))
    assert t[:n, 1].tolist() == ds.labels(0)[:, 0].tolist()
    # 320x240 letterboxed to 320x256: scale 1, 8 px band on top
    np.testing.assert_allclose(t[n:].numpy(), [[0, IGNORE_CLASS, 160, 128, 32, 48]], atol=1e-4)
    # only labels shape the anchors
    assert len(ds.label_wh()) == len(ds.labels(0)) + len(ds.labels(1))


def test_ignored_cells_cover_the_cells_that_could_predict_the_region():
    regions = torch.tensor([[0, IGNORE_CLASS, 150, 60, 100, 40],    # x 100-200, y 40-80
                            [1, IGNORE_CLASS, 50, 50, 6, 6]])       # inside cell (1, 1) at 32
    for stride in STRIDES:
        h, w = 256 // stride, 320 // stride
        got = ignored_cells(regions, (2, h, w), stride)
        cy, cx = np.meshgrid((np.arange(h) + 0.5) * stride, (np.arange(w) + 0.5) * stride,
                             indexing='ij')
        inside = [(abs(cx - x) <= bw / 2) & (abs(cy - y) <= bh / 2)
                  for _, _, x, y, bw, bh in regions.tolist()]
        for b, (_, _, x, y, _, _) in enumerate(regions.tolist()):
            inside[b][int(y // stride), int(x // stride)] = True   # the centre's own cell
        assert got.tolist() == [m.tolist() for m in inside]
    assert ignored_cells(regions, (2, 8, 10), 32)[1].sum() == 1


def test_loss_ignores_objectness_in_ignore_regions_but_not_on_labels():
    torch.manual_seed(0)
    anchors = torch.tensor(DEFAULT_ANCHORS[3])
    loss = YoloLoss(anchors)
    strides = STRIDES[:len(anchors)]
    heads = [torch.randn(1, 3 * 8, 256 // s, 320 // s) for s in strides]
    label = torch.tensor([[0, 1, 60, 60, 30, 30.0]])
    region = torch.tensor([[0, IGNORE_CLASS, 200, 150, 60, 40.0]])

    def with_objectness(cells, logit):
        """``heads`` with every anchor's objectness set to ``logit`` where ``cells(stride)``."""
        out = []
        for h, s in zip(heads, strides):
            h = h.clone().view(1, 3, 8, *h.shape[2:])
            h[:, :, 4][:, :, cells(s)] = logit
            out.append(h.view(1, 24, *h.shape[3:]))
        return out

    def cells_of(box):
        def cells(s):
            return ignored_cells(torch.tensor([[0, IGNORE_CLASS, *box]]),
                                 (1, 256 // s, 320 // s), s)[0]
        return cells

    confident = with_objectness(cells_of([200, 150, 60, 40]), 8.0)
    # a confident prediction inside the region costs nothing with it, a lot without it
    assert loss(confident, torch.cat([label, region]))[0] == \
        pytest.approx(float(loss(heads, torch.cat([label, region]))[0]), rel=1e-6)
    assert loss(confident, label)[0] > loss(heads, label)[0] + 0.01
    # a label inside a region is still learnt: its own cells keep their objectness loss
    # (one or two cells of the ~5,000 averaged: a small but not a rounding-size change)
    inner = torch.tensor([[0, 1, 200, 150, 30, 30.0]])
    at_label = with_objectness(cells_of([200, 150, 1, 1]), -8.0)
    assert loss(at_label, torch.cat([inner, region]))[0] > \
        loss(heads, torch.cat([inner, region]))[0] + 1e-4


def test_train_one_epoch_writes_loadable_model(data8, tmp_path):
    out = tmp_path / 'det.pt'
    card = train(data8, out, epochs=1, seed=0, batch=4, device='cpu', log=lambda s: None)
    assert np.isfinite(card['final_loss'])
    saved = json.loads(card_path(out).read_text())
    assert saved['data_seed'] == 3 and saved['epochs'] == 1 and saved['num_classes'] == 3
    assert 'git_commit' in saved
    model = load_model(out)
    assert model.meta['final_loss'] == card['final_loss']
    dets = model.predict(cv2.imread(str(data8 / 'images' / '000.png'))[:, :, ::-1].copy())
    assert dets[0].shape[1] == 6
    metrics = evaluate(model, data8)
    assert 0.0 <= metrics['map50_95'] <= metrics['map50'] <= 1.0
    # per-class AP is keyed by the data set's class names
    assert set(metrics['ap50_per_class']) == {'rect', 'disc', 'tri'}


def test_training_is_reproducible(data8, tmp_path):
    a = train(data8, tmp_path / 'a.pt', epochs=1, seed=5, batch=4, device='cpu',
              log=lambda s: None)
    b = train(data8, tmp_path / 'b.pt', epochs=1, seed=5, batch=4, device='cpu',
              log=lambda s: None)
    assert a['loss_history'] == b['loss_history']


def test_bf16_autocast_trains_float32_weights_to_the_same_loss(data8, tmp_path):
    kw = dict(epochs=1, seed=5, batch=4, device='cpu', log=lambda s: None)
    ref = train(data8, tmp_path / 'a.pt', **kw)
    card = train(data8, tmp_path / 'b.pt', bf16=True, **kw)
    assert card['bf16'] and not ref['bf16']
    # same seed, same steps: bfloat16 rounding (0.4% relative) of the forward pass moves
    # the mean loss of one epoch by well under 5%
    np.testing.assert_allclose(card['loss_history'], ref['loss_history'], rtol=0.05)
    assert all(v.dtype == torch.float32 for v in load_model(tmp_path / 'b.pt').state_dict()
               .values() if v.is_floating_point())


def test_training_keeps_the_anchors(data8, tmp_path):
    anchors = [[[40.0, 40.0], [60.0, 50.0], [70.0, 70.0]],
               [[10.0, 12.0], [20.0, 20.0], [30.0, 28.0]]]
    card = train(data8, tmp_path / 'a.pt', epochs=2, seed=0, batch=4, device='cpu',
                 anchors=anchors, log=lambda s: None)
    # exactly: they are constants of the model, not weights
    assert card['anchors'] == anchors
    assert load_model(tmp_path / 'a.pt').anchors.tolist() == anchors


def test_overfit_four_images(tmp_path):
    data = make_dataset(tmp_path / 'data4', 4, seed=7)
    card = train(data, tmp_path / 'o.pt', epochs=40, seed=0, batch=4, device='cpu', lr=1e-2,
                 augment=False, log=lambda s: None)
    hist = card['loss_history']
    assert np.all(np.isfinite(hist))
    # memorising 4 images must cut the loss by far more than noise: below a fifth of the start
    assert min(hist[-5:]) < hist[0] / 5
    # ... and the memorised boxes must be found again on the training images
    assert evaluate(load_model(tmp_path / 'o.pt'), data)['map50'] > 0.5


def test_cli_continued_run_keeps_its_lineage(data8, tmp_path):
    from uav_tilt_vision.training import cli as vision_cli
    model = tmp_path / 'pruned.pt'
    train(data8, model, epochs=1, seed=0, batch=4, width_mult=0.125, device='cpu',
          log=lambda s: None)
    first = json.loads(card_path(model).read_text())
    first.update(source='models/fp32.pt', pruning_ratio=0.25)
    card_path(model).write_text(json.dumps(first))
    # continue in place, as docs/detector.md's last fine-tune of the pruned model does
    args = ['train', '--data', str(data8), '--init', str(model), '--out', str(model),
            '--epochs', '1', '--seed', '1', '--batch', '4', '--device', 'cpu']
    assert vision_cli.main(args) == 0
    card = json.loads(card_path(model).read_text())
    assert card['init']['seed'] == 0 and card['seed'] == 1 and card['total_epochs'] == 2
    assert (card['source'], card['pruning_ratio']) == ('models/fp32.pt', 0.25)
    assert load_model(model).meta['total_epochs'] == 2


def test_a_model_is_trained_at_its_own_input_size(data8, tmp_path):
    """A given model (a pruned or resized one) is fed inputs of its ``img_size``, whatever
    ``img_size`` says; the CLI's --img-size resizes an --init model and keeps its weights."""
    from uav_tilt_vision.training import cli as vision_cli
    small = tmp_path / 'small.pt'
    train(data8, small, epochs=1, seed=0, batch=4, width_mult=0.125, img_size=(256, 192),
          device='cpu', log=lambda s: None)
    model = load_model(small)
    seen = []
    model.register_forward_pre_hook(lambda m, x: seen.append(tuple(x[0].shape[2:])))
    train(data8, tmp_path / 'again.pt', epochs=1, seed=0, batch=4, model=model, device='cpu',
          log=lambda s: None)
    assert seen and set(seen) == {(192, 256)}
    big = tmp_path / 'big.pt'
    args = ['train', '--data', str(data8), '--init', str(small), '--img-size', '384', '288',
            '--out', str(big), '--epochs', '1', '--batch', '4', '--device', 'cpu', '--workers',
            '1']
    assert vision_cli.main(args) == 0
    card = json.loads(card_path(big).read_text())
    assert (card['img_size'], card['resized_from']) == ([384, 288], [256, 192])
    assert load_model(big).img_size == (384, 288)
    torch.testing.assert_close(load_model(big).anchors, load_model(small).anchors)
    with pytest.raises(SystemExit) as stop:
        vision_cli.main(['train', '--data', str(data8), '--img-size', '400', '300'])
    assert stop.value.code == 2


def test_grown_model_adds_a_finer_head_and_keeps_the_others(data8, tmp_path):
    from uav_tilt_vision.training import cli as vision_cli
    three = tmp_path / 'three.pt'
    anchors = [[[90.0, 90.0], [100.0, 100.0], [110.0, 110.0]],
               [[65.0, 65.0], [70.0, 70.0], [80.0, 80.0]],
               [[50.0, 50.0], [55.0, 55.0], [60.0, 60.0]]]
    train(data8, three, epochs=1, seed=0, batch=4, width_mult=0.125, scales=3, device='cpu',
          anchors=anchors, log=lambda s: None)
    model = load_model(three)
    four = grown(model, 4, data8).eval()
    assert four.strides == (32, 16, 8, 4)
    # the new head's anchors cluster the labels smaller than every anchor the model had
    wh = YoloDataset(data8).label_wh()
    small = wh[wh.prod(1) < float(model.anchors.prod(-1).min())]
    np.testing.assert_allclose(four.anchors[3].numpy(), kmeans_anchors(small, 1)[0], rtol=1e-6)
    assert float(four.anchors[3].prod(-1).max()) < float(model.anchors.prod(-1).min())
    torch.testing.assert_close(four.anchors[:3], model.anchors)
    x = torch.stack([YoloDataset(data8)[i][0] for i in range(2)])
    with torch.no_grad():
        for a, b in zip(model(x), four(x)[:3]):
            torch.testing.assert_close(a, b)
    out = tmp_path / 'four.pt'
    args = ['train', '--data', str(data8), '--init', str(three), '--grow-scales', '4',
            '--out', str(out), '--epochs', '1', '--batch', '4', '--device', 'cpu']
    assert vision_cli.main(args) == 0
    assert load_model(out).strides == (32, 16, 8, 4)
    assert json.loads(card_path(out).read_text())['grown_from_scales'] == 3
    with pytest.raises(SystemExit) as stop:
        vision_cli.main(['train', '--data', str(data8), '--grow-scales', '4'])
    assert stop.value.code == 2


def fake_heads(obj_logit_bg=-20.0, num_classes=3, seed=0):
    """Teacher-like raw heads of one 3-anchor scale: every cell background but one object."""
    torch.manual_seed(seed)
    head = torch.randn(1, 3 * (5 + num_classes), 4, 5)
    view = head.view(1, 3, 5 + num_classes, 4, 5)
    view[:, :, 4] = obj_logit_bg
    view[0, 1, 4, 2, 3] = 5.0            # anchor 1, cell (y 2, x 3) holds an object
    return head


def test_distill_loss_vanishes_at_the_teacher_and_weighs_by_objectness():
    teacher = fake_heads()
    student = teacher.clone().requires_grad_(True)
    loss, _ = distill_loss([student], [teacher], 3)
    loss.backward()
    assert abs(float(loss.detach())) < 1e-6 and float(student.grad.abs().max()) < 1e-6
    # one box logit moved from the teacher's value to +-2 around 0: KL(0.5 || sigmoid(2))
    kl = 0.5 * np.log(0.5 / (1 / (1 + np.exp(-2)))) + 0.5 * np.log(0.5 / (1 / (1 + np.exp(2))))
    for cell, expect in (((0, 1, 0, 2, 3), kl), ((0, 2, 0, 1, 1), 0.0)):   # object, background
        t, s = teacher.clone(), teacher.clone()
        t.view(1, 3, 8, 4, 5)[cell] = 0.0
        s.view(1, 3, 8, 4, 5)[cell] = 2.0
        _, parts = distill_loss([s], [t], 3)
        # the object cell's weight is sigmoid(5) = 0.993 of the whole
        assert parts['d_box'] == pytest.approx(expect, abs=0.01 * kl)
        assert parts['d_obj'] == parts['d_cls'] == 0.0


def test_distillation_pulls_the_student_towards_its_teacher(data8, tmp_path):
    anchors = [[[40.0, 40.0], [60.0, 50.0], [70.0, 70.0]],
               [[10.0, 12.0], [20.0, 20.0], [30.0, 28.0]]]
    kw = dict(epochs=8, batch=4, device='cpu', anchors=anchors, width_mult=0.125, lr=1e-2,
              ema_decay=0, augment=False, log=lambda s: None)
    train(data8, tmp_path / 't.pt', seed=0, **kw)
    teacher = load_model(tmp_path / 't.pt')
    train(data8, tmp_path / 'plain.pt', seed=1, **kw)
    card = train(data8, tmp_path / 'kd.pt', seed=1, teacher=teacher, distill_gain=5.0, **kw)
    assert card['distill_gain'] == 5.0
    x = torch.stack([YoloDataset(data8)[i][0] for i in range(8)])
    with torch.no_grad():
        ht = teacher(x)
        gap = {name: float(distill_loss(load_model(tmp_path / name)(x), ht, 3)[0])
               for name in ('plain.pt', 'kd.pt')}
    assert gap['kd.pt'] < 0.5 * gap['plain.pt']


def test_teacher_must_match_the_student(data8, tmp_path):
    from uav_tilt_vision.detector import Detector
    with pytest.raises(ValueError, match='teacher'):
        train(data8, tmp_path / 'x.pt', epochs=1, batch=4, device='cpu', width_mult=0.125,
              teacher=Detector(5, 0.125), log=lambda s: None)


def test_compress_cli_fine_tunes_from_the_unpruned_teacher(data8, tmp_path, capsys):
    from uav_tilt_vision.training import cli as vision_cli
    fp32 = tmp_path / 'fp32.pt'
    train(data8, fp32, epochs=1, seed=0, batch=4, width_mult=0.25, scales=3, device='cpu',
          log=lambda s: None)
    args = ['compress', '--model', str(fp32), '--data', str(data8), '--out-dir', str(tmp_path),
            '--ratio', '0.25', '--finetune-epochs', '1', '--calib-images', '4']
    capsys.readouterr()
    assert vision_cli.main(args) == 0
    # stdout is one JSON report (the calibrator's progress goes to stderr)
    assert set(json.loads(capsys.readouterr().out)) == {'fp32', 'pruned', 'int8'}
    card = json.loads(card_path(tmp_path / 'detector_pruned.pt').read_text())
    assert card['teacher'] == str(fp32) and card['distill_gain'] == 1.0
    assert card['pruning_ratio'] == 0.25 and (tmp_path / 'detector_int8.onnx').exists()
