"""uav-tilt vision from outside the checkout, and its one-line refusals of missing inputs."""
import json

import pytest

from uav_tilt_common import resources
from uav_tilt_vision.training import cli as vision_cli

FP32 = str(resources.default_path('models/detector_fp32.pt'))


@pytest.fixture(scope='module')
def data4(tmp_path_factory):
    """Four rendered images, as `uav-tilt vision dataset` writes them."""
    out = tmp_path_factory.mktemp('data4')
    vision_cli.main(['dataset', '--out', str(out), '--n', '4', '--seed', '1'])
    return out


@pytest.fixture
def elsewhere(tmp_path, monkeypatch, capsys):
    """Run from a folder without models/; the fixtures' output is left behind."""
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    return tmp_path


def test_the_default_models_are_the_packages_from_any_folder(data4, elsewhere, capsys):
    assert vision_cli.main(['eval', '--data', str(data4)]) == 0
    assert 0.0 <= json.loads(capsys.readouterr().out)['map50'] <= 1.0
    assert vision_cli.main(['profile']) == 0
    assert len(json.loads(capsys.readouterr().out)) == 4    # two references, two models


@pytest.mark.parametrize('args, named', [
    (['eval', '--data', 'nonexistent', '--model', FP32], 'nonexistent'),
    (['eval', '--data', 'DATA', '--model', 'models/nope.pt'], 'models/nope.pt'),
    (['profile', '--model', 'nope.pt'], 'nope.pt'),
    # a file where a folder goes
    (['eval', '--data', 'FILE', '--model', FP32], 'a_file'),
    (['dataset', '--out', 'FILE', '--n', '2'], 'a_file')])
def test_a_missing_input_is_one_line_and_exit_2(data4, elsewhere, capsys, args, named):
    (elsewhere / 'a_file').write_text('not a folder')
    args = [{'DATA': str(data4), 'FILE': 'a_file'}.get(a, a) for a in args]
    assert vision_cli.main(args) == 2
    out, err = capsys.readouterr()
    assert err.startswith('uav-tilt vision: error: ') and named in err
    assert err.count('\n') == 1 and out == ''
