"""`uav-tilt vision` refuses bad inputs (option values, files, folders) with one line, exit 2."""
import json
import shutil

import cv2
import numpy as np
import onnx
import pytest
import torch

from uav_tilt_common import resources
from uav_tilt_common.config import ConfigError
from uav_tilt_vision.training import cli as vision_cli
from uav_tilt_vision.training.compress import MAX_PRUNING_RATIO, prune
from uav_tilt_vision.detector import Detector, load_model
from uav_tilt_vision.training.train import card_path, train
from uav_tilt_vision.training.yolo_data import read_labels

torch.set_num_threads(2)
FP32 = str(resources.default_path('models/detector_fp32.pt'))
INT8 = str(resources.default_path('models/detector_int8.onnx'))


def make_set(root, n=4, seed=0):
    """n 320x240 images with three labelled rectangles of distinct sizes each."""
    rng = np.random.default_rng(seed)
    for folder in ('images', 'labels'):
        (root / folder).mkdir(parents=True)
    for i in range(n):
        img = np.full((240, 320, 3), 90, np.uint8)
        lines = []
        for _ in range(3):
            cls = int(rng.integers(3))
            bw, bh = (int(v) for v in rng.integers(20, 90, 2))
            x1, y1 = int(rng.integers(0, 320 - bw)), int(rng.integers(0, 240 - bh))
            cv2.rectangle(img, (x1, y1), (x1 + bw - 1, y1 + bh - 1), (40 + 80 * cls, 200, 60), -1)
            cx, cy = (x1 + bw / 2) / 320, (y1 + bh / 2) / 240
            lines.append(f'{cls} {cx} {cy} {bw / 320} {bh / 240}')
        cv2.imwrite(str(root / 'images' / f'{i:03d}.png'), img)
        (root / 'labels' / f'{i:03d}.txt').write_text('\n'.join(lines) + '\n')
    (root / 'meta.json').write_text(json.dumps({'seed': seed, 'classes': ['a', 'b', 'c']}))
    return root


@pytest.fixture(scope='module')
def data(tmp_path_factory):
    return make_set(tmp_path_factory.mktemp('data'))


@pytest.fixture(scope='module')
def tiny(data, tmp_path_factory):
    """A one-epoch 2-scale model trained on ``data`` (card beside it)."""
    path = tmp_path_factory.mktemp('tiny') / 'tiny.pt'
    train(data, path, epochs=1, batch=4, width_mult=0.125, scales=2, device='cpu',
          log=lambda s: None)
    return path


def refused(capsys, argv, *named):
    """Run the CLI; assert exit 2, one line on stderr naming each of ``named``, no stdout."""
    capsys.readouterr()
    try:
        code = vision_cli.main([str(a) for a in argv])
    except SystemExit as stop:  # argparse's own error line
        code = stop.code
    out, err = capsys.readouterr()
    assert code == 2, err
    line = err.strip().splitlines()[-1]
    assert line.startswith('uav-tilt vision') and ': error: ' in line, err
    assert all(str(n) in line for n in named), line
    assert out == ''
    return line


def test_dataset_refuses_an_out_folder_that_holds_a_set(tmp_path, capsys):
    (tmp_path / 'images').mkdir()
    (tmp_path / 'images' / '000000.png').write_bytes(b'old')
    refused(capsys, ['dataset', '--out', tmp_path, '--n', '1'], tmp_path, 'images/')
    assert not (tmp_path / 'meta.json').exists()


@pytest.mark.parametrize('line', ['0 0.5 0.5 0.1 0.1 7', '0 0.5 0.5 0.1', 'a 0.5 0.5 0.1 0.1',
                                  '3 0.5 0.5 0.1 0.1', '0.5 0.5 0.5 0.1 0.1',
                                  '-1 0.5 0.5 0.1 0.1', '0 nan 0.5 0.1 0.1'])
def test_a_malformed_label_line_is_refused_naming_file_and_line(tmp_path, line):
    (tmp_path / 'x.txt').write_text(f'1 0.5 0.5 0.2 0.2\n{line}\n')
    with pytest.raises(ConfigError, match='x.txt:2: '):
        read_labels(tmp_path / 'x.txt', num_classes=3)


def test_eval_names_a_bad_label_file(data, tmp_path, capsys):
    bad = tmp_path / 'bad'
    shutil.copytree(data, bad)
    (bad / 'labels' / '002.txt').write_text('7 0.5 0.5 0.1 0.1\n')
    refused(capsys, ['eval', '--data', bad, '--model', FP32], '002.txt:1')


def test_eval_names_an_unreadable_image(data, tmp_path, capsys):
    bad = tmp_path / 'bad'
    shutil.copytree(data, bad)
    (bad / 'images' / '001.png').write_bytes(b'not a png')
    refused(capsys, ['eval', '--data', bad, '--model', FP32], '001.png')


def test_eval_refuses_a_set_without_labels(data, tmp_path, capsys):
    shutil.copytree(data / 'images', tmp_path / 'nolabels' / 'images')
    refused(capsys, ['eval', '--data', tmp_path / 'nolabels', '--model', FP32], 'labels/')
    (tmp_path / 'nolabels' / 'labels').mkdir()
    refused(capsys, ['eval', '--data', tmp_path / 'nolabels', '--model', FP32], 'no labelled')


@pytest.mark.parametrize('ratio', ['0', '-0.5', '0.99', '1.0', '1.5', 'nan'])
def test_compress_refuses_a_ratio_that_prunes_nothing(ratio, capsys):
    refused(capsys, ['compress', '--data', 'x', '--ratio', ratio], '--ratio')


def test_the_largest_ratio_prunes_every_wide_conv():
    before = load_model(FP32).channels()
    after = prune(load_model(FP32), MAX_PRUNING_RATIO).channels()
    assert all(a < b for a, b in zip(after, before) if b >= 32)


def test_pruning_that_removes_nothing_is_refused():
    with pytest.raises(ConfigError, match='removes no channel'):
        prune(Detector(3, 0.125, [8] * 11), 0.5)


def test_compress_defaults_to_the_shipped_ratio_and_shows_it():
    ap = vision_cli.parser()
    assert ap.parse_args(['compress', '--data', 'x']).ratio == 0.25
    sub = ap._subparsers._group_actions[0].choices['compress']
    assert '(default: 0.25)' in ' '.join(sub.format_help().split())


def test_eval_reports_the_file_it_scored_and_the_fallback_note(data, capsys):
    capsys.readouterr()
    assert vision_cli.main(['eval', '--data', str(data), '--model', INT8,
                            '--backend', 'torch']) == 0
    out = json.loads(capsys.readouterr().out)
    assert out['model'].endswith('detector_pruned.pt') and out['backend_used'] == 'torch'
    assert 'fell back' in out['note']


@pytest.fixture
def not_models(tmp_path):
    """Files named like models that are not: text, text named .onnx, an ONNX model without
    the detector's metadata."""
    (tmp_path / 'text.pt').write_text('hello\n')
    (tmp_path / 'text.onnx').write_text('hello\n')
    x = onnx.helper.make_tensor_value_info('x', onnx.TensorProto.FLOAT, [1])
    y = onnx.helper.make_tensor_value_info('y', onnx.TensorProto.FLOAT, [1])
    graph = onnx.helper.make_graph([onnx.helper.make_node('Identity', ['x'], ['y'])], 'g',
                                   [x], [y])
    onnx.save(onnx.helper.make_model(graph), str(tmp_path / 'plain.onnx'))
    return tmp_path


@pytest.mark.parametrize('args, bad', [
    (['eval', '--model'], 'text.pt'), (['eval', '--model'], 'text.onnx'),
    (['eval', '--model'], 'plain.onnx'), (['eval', '--backend', 'torch', '--model'], 'plain.onnx'),
    (['train', '--init'], 'text.pt'), (['train', '--teacher'], 'text.pt'),
    (['train', '--init'], 'plain.onnx'), (['quantize', '--model'], 'text.pt'),
    (['profile', '--model'], 'text.pt'), (['profile', '--model'], 'plain.onnx'),
    (['compress', '--model'], 'text.pt')])
def test_a_file_that_is_not_a_model_is_one_line(data, not_models, capsys, args, bad):
    argv = args + [not_models / bad] + ([] if args[0] == 'profile' else ['--data', data])
    refused(capsys, argv, bad, 'not a detector model')


@pytest.mark.parametrize('argv, option', [
    (['train', '--epochs', '0'], '--epochs'), (['train', '--epochs', '-1'], '--epochs'),
    (['compress', '--finetune-epochs', '0'], '--finetune-epochs'),
    (['train', '--batch', '0'], '--batch'), (['train', '--workers', '-1'], '--workers'),
    (['--threads', '-1', 'eval'], '--threads'), (['train', '--device', 'bogus'], '--device'),
    (['train', '--device', 'cuda:99'], '--device'), (['train', '--lr', 'nan'], '--lr'),
    (['train', '--crop', '0', '0'], '--crop'), (['train', '--crop', '100', '64'], '--crop'),
    (['quantize', '--calib-images', '0'], '--calib-images'),
    (['quantize', '--calib-images', '-3'], '--calib-images'),
    (['train', '--width-mult', '0'], '--width-mult'),
    (['train', '--width-mult', '-1'], '--width-mult'),
    (['train', '--hsv', '-0.1', '0.5', '0.5'], '--hsv'),
    (['eval', '--bootstrap', '-1'], '--bootstrap')])
def test_a_bad_number_is_argparses_error(argv, option, capsys):
    refused(capsys, argv + ['--data', 'x'], option)


@pytest.mark.parametrize('argv, option', [
    (['--n', '0'], '--n'), (['--n', '-5'], '--n'), (['--jobs', '0'], '--jobs'),
    (['--jobs', '-1'], '--jobs'), (['--distance-m', '1', 'inf'], '--distance-m'),
    (['--distance-m', '1', '1e6'], '--distance-m')])
def test_dataset_refuses_bad_numbers(argv, option, tmp_path, capsys):
    refused(capsys, ['dataset', '--out', tmp_path / 'x', '--n', '1'] + argv, option)
    assert not (tmp_path / 'x').exists()


def test_train_refuses_a_crop_larger_than_the_input(data, tmp_path, capsys):
    refused(capsys, ['train', '--data', data, '--out', tmp_path / 'm.pt', '--crop', '640', '640'],
            'crop')


def test_compress_refuses_a_crop_larger_than_the_input_before_it_prunes(tiny, data, tmp_path,
                                                                        capsys):
    out = tmp_path / 'out'
    refused(capsys, ['compress', '--model', tiny, '--data', data, '--out-dir', out,
                     '--crop', '640', '640'], 'crop')
    assert not out.exists()


def test_growing_to_the_scales_a_model_has_is_refused(data, tmp_path, capsys):
    refused(capsys, ['train', '--data', data, '--out', tmp_path / 'm.pt', '--init', FP32,
                     '--grow-scales', '3'], 'scales')


def test_models_are_found_from_any_folder_and_a_mismatched_teacher_is_one_line(
        data, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)   # no models/ here: the package's is used
    refused(capsys, ['train', '--data', data, '--out', tmp_path / 'm.pt', '--scales', '2',
                     '--teacher', 'models/detector_fp32.pt'], 'teacher and model differ')


def test_a_teacher_saved_in_half_precision_matches_its_student(data, tiny, tmp_path):
    card = train(data, tmp_path / 's.pt', epochs=1, batch=4, width_mult=0.125, scales=2,
                 device='cpu', teacher=load_model(tiny), log=lambda s: None)
    assert card['distill_gain'] == 1.0


def test_quantize_checks_the_card_before_writing(tiny, data, tmp_path, capsys):
    shutil.copy(tiny, tmp_path / 'p.pt')
    refused(capsys, ['quantize', '--model', tmp_path / 'p.pt', '--data', data], 'p.json')
    assert not (tmp_path / 'detector_int8.onnx').exists()


def test_quantize_records_the_calibration_images_it_used(tiny, data, tmp_path, capsys):
    shutil.copy(tiny, tmp_path / 'p.pt')
    shutil.copy(card_path(tiny), tmp_path / 'p.json')
    assert vision_cli.main(['quantize', '--model', str(tmp_path / 'p.pt'), '--data', str(data),
                            '--calib-images', '1000']) == 0
    assert json.loads((tmp_path / 'detector_int8.json').read_text())['calib_images'] == 4
