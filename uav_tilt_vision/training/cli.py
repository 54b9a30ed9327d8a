"""``uav-tilt vision dataset|train|eval|compress|quantize|profile``; also ``python -m`` it.

What it does and prints: :data:`DESCRIPTION`, the text of its ``--help``.
"""

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Callable, Sequence, TypeVar

from uav_tilt_common import resources
from uav_tilt_common.config import ConfigError
from uav_tilt_common import cli_args

MODELS = 'models'
M = TypeVar('M')
# plain text, laid out as written: --help prints it
DESCRIPTION = """\
The detector's offline work: render a labelled data set, train, evaluate, compress
(prune, fine-tune, int8), quantize, profile.

Every sub-command prints one JSON object on stdout (progress bars go to stderr)."""


def log_stderr(line: str) -> None:
    """Progress lines go to stderr: stdout is the JSON result."""
    print(line, file=sys.stderr, flush=True)


def _model_file(path: str, option: str, load: Callable[[Path], M]) -> tuple[Path, M]:
    """The file ``path`` names (``resources.resolve``; as given when it is in the working
    directory, which cards cite) and ``load`` of it; ConfigError naming it when it is not a
    detector model."""
    found = Path(path) if Path(path).is_file() else resources.resolve(path, option)
    try:
        return found, load(found)
    except FileNotFoundError:   # e.g. the checkpoint an ONNX model falls back to
        raise
    except Exception as err:  # noqa: BLE001 - torch, pickle, protobuf and ONNX Runtime
        # each raise their own errors on a file of another kind; long messages are not one line
        reason = type(err).__name__ + (f': {err}' if len(str(err).splitlines()) == 1
                                       and len(str(err)) <= 80 else '')
        raise ConfigError(f'{path}: not a detector model ({reason})') from None


def _checkpoint(path: str, option: str) -> tuple[Path, Any]:
    """:func:`_model_file` of a ``Detector`` checkpoint (.pt), loaded."""
    from uav_tilt_vision.detector import load_model
    if Path(path).suffix == '.onnx':
        raise ConfigError(f'{path}: not a detector model for {option}, which takes a .pt '
                          'checkpoint, not ONNX')
    return _model_file(path, option, load_model)


def _dataset(a: argparse.Namespace) -> dict[str, Any]:
    from uav_tilt_vision.training.dataset import DISTANCE_M, generate
    meta = generate(a.out, a.n, a.seed, a.split, a.jobs, renderer=a.renderer,
                    distance_m=a.distance_m or DISTANCE_M, scenes=a.scenes)
    return {k: meta[k] for k in ('seed', 'split', 'n', 'classes', 'boxes_per_class',
                                 'renderer', 'distance_m', 'scenes')}


def _train(a: argparse.Namespace) -> dict[str, Any]:
    from uav_tilt_vision.detector import IMG_SIZE, resize_input
    from uav_tilt_vision.training.train import card_path, grown, train
    from uav_tilt_vision.training.yolo_data import HSV_GAINS
    extra: dict[str, Any] = {'teacher': a.teacher} if a.teacher else {}
    init, model = _checkpoint(a.init, '--init') if a.init else (None, None)
    teacher = _checkpoint(a.teacher, '--teacher')[1] if a.teacher else None
    if model is not None and a.img_size and tuple(a.img_size) != model.img_size:
        extra['resized_from'] = list(model.img_size)
        model = resize_input(model, a.img_size)
    if model is not None and a.grow_scales:   # main() refuses --grow-scales without --init
        extra['grown_from_scales'] = len(model.strides)
        model = grown(model, a.grow_scales, a.data)
    if init:  # a continued run: its card names the stage it started from
        prior = json.loads(card_path(init).read_text())
        extra['init'] = {k: prior.get(k)
                         for k in ('epochs', 'seed', 'lr', 'crop', 'hsv', 'init', 'teacher',
                                   'bf16')}
        extra['total_epochs'] = a.epochs + prior.get('total_epochs', prior['epochs'])
        extra.update({k: prior[k] for k in ('source', 'pruning_ratio') if k in prior})
    card = train(a.data, a.out, a.epochs, a.seed, a.width_mult, batch=a.batch, lr=a.lr,
                 img_size=a.img_size or IMG_SIZE, workers=a.workers,
                 device=a.device, eval_dir=a.eval_data, crop=a.crop, scales=a.scales,
                 hsv=a.hsv or HSV_GAINS,
                 model=model, teacher=teacher,
                 distill_gain=a.distill_gain, card_extra=extra, bf16=a.bf16, log=log_stderr)
    return {k: v for k, v in card.items() if k != 'loss_history'}


def _eval(a: argparse.Namespace) -> dict[str, Any]:
    from uav_tilt_vision.backends import load_detector
    from uav_tilt_vision.training.train import evaluate
    det = _model_file(a.model, '--model', lambda path: load_detector(path, a.backend))[1]
    # the file scored: a fallback runs another one than --model, and says why in its note
    return {**evaluate(det, a.data, resamples=a.bootstrap), 'model': det.model_path,
            'backend_used': det.backend, 'note': det.note}


def _compress(a: argparse.Namespace) -> dict[str, Any]:
    from uav_tilt_vision.training.compress import compress
    return compress(_checkpoint(a.model, '--model')[0], a.data, a.out_dir, a.ratio,
                    a.finetune_epochs, a.seed, a.calib_images, a.eval_data, crop=a.crop,
                    distill_gain=a.distill_gain, bf16=a.bf16, device=a.device,
                    workers=a.workers, log=log_stderr)


def _quantize(a: argparse.Namespace) -> dict[str, Any]:
    from uav_tilt_vision.training.compress import quantize
    return quantize(_checkpoint(a.model, '--model')[0], a.data, a.calib_images,
                    a.eval_data)


def _profile(a: argparse.Namespace) -> dict[str, Any]:
    from uav_tilt_vision.training.profile import report
    return report([_checkpoint(m, '--model')[0] for m in a.model])


def _device(text: str) -> str:
    """A torch device this machine has, or 'auto' (``train.resolve_device``)."""
    from uav_tilt_vision.training.train import resolve_device
    try:
        resolve_device(text)
    except ConfigError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    return text


def _pruning_ratio(text: str) -> float:
    """A channel pruning ratio that torch-pruning honours (``compress.MAX_PRUNING_RATIO``)."""
    from uav_tilt_vision.training.compress import MAX_PRUNING_RATIO
    return cli_args.ratio_up_to(MAX_PRUNING_RATIO)(text)


def parser() -> argparse.ArgumentParser:
    """The argparse parser of the vision sub-commands."""
    ap = argparse.ArgumentParser(prog='uav-tilt vision', description=DESCRIPTION,
                                 formatter_class=cli_args.HelpFormatter)
    ap.add_argument('--threads', type=cli_args.non_negative, default=0,
                    help="torch CPU threads (0: torch's own choice)")
    sub = ap.add_subparsers(dest='command', required=True, metavar='COMMAND')

    def command(name: str, help: str) -> argparse.ArgumentParser:
        return cli_args.add_command(sub, name, help)

    d = command('dataset', help='render a labelled, domain-randomised image set')
    d.add_argument('--out', required=True, help='a new or empty folder')
    d.add_argument('--n', type=cli_args.count, required=True, help='images')
    d.add_argument('--seed', type=cli_args.seed, default=0, help='random seed')
    d.add_argument('--split', choices=('train', 'heldout'), default='train',
                   help='which worlds, textures and lighting to draw from')
    d.add_argument('--jobs', type=cli_args.count, default=1, help='render processes')
    d.add_argument('--renderer', choices=('gl', 'tiny'), default='gl',
                   help="the camera's renderer (train on the plant's: gl)")
    d.add_argument('--distance-m', type=cli_args.positive, nargs=2, metavar=('MIN', 'MAX'),
                   help='camera distance range, log-uniform, up to the camera\'s far clip '
                        'plane (default dataset.DISTANCE_M: the mission\'s ranges)')
    d.add_argument('--scenes', choices=('wall', 'structures'), default='wall',
                   help='worlds of a wall, or of the campaign\'s structures (a corner, a '
                        'pillar, pipes, a tank, a mesh) with objects on them')
    d.set_defaults(run=_dataset)
    t = command('train', help='train the fp32 detector; writes weights + model card')
    t.add_argument('--data', required=True, help='training set (a `dataset` folder)')
    t.add_argument('--out', default=f'{MODELS}/detector_fp32.pt', help='weights; the card beside')
    t.add_argument('--epochs', type=cli_args.count, default=16, help='passes over --data')
    t.add_argument('--seed', type=cli_args.seed, default=0, help='random seed')
    t.add_argument('--width-mult', type=cli_args.positive, default=0.5,
                   help="channels relative to YOLOv3-tiny's")
    t.add_argument('--scales', type=int, default=3, choices=(2, 3, 4),
                   help='detection heads: 2 = YOLOv3-tiny, 3 = with a stride-8 head, '
                        '4 = and a stride-4 head')
    t.add_argument('--batch', type=cli_args.count, default=16, help='images per step')
    t.add_argument('--img-size', type=int, nargs=2, metavar=('W', 'H'),
                   help='network input, multiples of 32 (default detector.IMG_SIZE; with '
                        '--init: that model\'s, or this one, weights and anchors kept)')
    t.add_argument('--workers', type=cli_args.non_negative, default=0,
                   help='data loader processes')
    t.add_argument('--lr', type=cli_args.positive, default=3e-3, help='peak learning rate')
    t.add_argument('--device', type=_device, default='auto', help='auto: a GPU if any')
    t.add_argument('--eval-data', help='held-out set whose mAP goes in the model card')
    t.add_argument('--crop', type=int, nargs=2, metavar=('W', 'H'),
                   help='train on object-centred W x H windows (multiples of 32, within the '
                        'input)')
    t.add_argument('--init', help='continue from this checkpoint (its card is cited)')
    t.add_argument('--grow-scales', type=int, choices=(3, 4),
                   help='add finer heads to the --init model up to this many scales (their '
                        'anchors: k-means on the labels smaller than its smallest anchor); '
                        'its other weights are kept')
    t.add_argument('--teacher', help='also learn to match this model\'s outputs (distillation; '
                                     'same classes, input size and anchors)')
    t.add_argument('--distill-gain', type=cli_args.non_negative_number, default=1.0,
                   help='weight of the distillation loss (with --teacher)')
    t.add_argument('--hsv', type=cli_args.fraction, nargs=3, metavar=('H', 'S', 'V'),
                   help='hue, saturation, value jitter of the augmentation (fractions, 0-1; '
                        'default yolo_data.HSV_GAINS)')
    t.add_argument('--bf16', action='store_true',
                   help='bfloat16 autocast for the forward passes (faster on CPUs with '
                        'AVX-512 BF16 and on GPUs)')
    t.set_defaults(run=_train)
    e = command('eval', help='COCO mAP of a model on a YOLO-format set')
    e.add_argument('--data', required=True, help='the set to score (a `dataset` folder)')
    e.add_argument('--model', default=f'{MODELS}/detector_fp32.pt', help='.pt or .onnx')
    e.add_argument('--backend', default='auto', choices=('auto', 'torch', 'onnxruntime'),
                   help='auto: by the file suffix')
    e.add_argument('--bootstrap', type=cli_args.non_negative, default=0, metavar='N',
                   help='add 95%% confidence intervals (ci95) from N resamplings of the '
                        'set\'s worlds')
    e.set_defaults(run=_eval)
    c = command('compress', help='prune + fine-tune, then int8 ONNX (static QDQ)')
    c.add_argument('--model', default=f'{MODELS}/detector_fp32.pt',
                   help='the fp32 .pt to compress')
    c.add_argument('--data', required=True, help='training set (fine-tuning, calibration)')
    c.add_argument('--out-dir', default=MODELS, help='where the pruned and int8 models go')
    c.add_argument('--ratio', type=_pruning_ratio, default=0.25,
                   help='channel pruning ratio, above 0 and at most '
                        'compress.MAX_PRUNING_RATIO')
    c.add_argument('--finetune-epochs', type=cli_args.count, default=4,
                   help='epochs of fine-tuning after pruning')
    c.add_argument('--seed', type=cli_args.seed, default=0, help='random seed')
    c.add_argument('--calib-images', type=cli_args.count, default=128,
                   help='calibrate on this many images of --data (all, if it has fewer)')
    c.add_argument('--eval-data', help='held-out set evaluated for every stage')
    c.add_argument('--crop', type=int, nargs=2, metavar=('W', 'H'),
                   help='fine-tune on object-centred W x H windows (multiples of 32)')
    c.add_argument('--distill-gain', type=cli_args.non_negative_number, default=1.0,
                   help='fine-tune also matching the unpruned model\'s outputs with this '
                        'weight (0: labels only)')
    c.add_argument('--bf16', action='store_true',
                   help='bfloat16 autocast for the fine-tuning\'s forward passes')
    c.add_argument('--device', type=_device, default='auto',
                   help='fine-tuning device (auto: a GPU if any)')
    c.add_argument('--workers', type=cli_args.non_negative, default=0,
                   help='data loader processes')
    c.set_defaults(run=_compress)
    q = command('quantize', help='int8 ONNX of a pruned model only (compress step 3)')
    q.add_argument('--model', default=f'{MODELS}/detector_pruned.pt',
                   help='the pruned .pt (its card beside it)')
    q.add_argument('--data', required=True, help='training set (calibration)')
    q.add_argument('--calib-images', type=cli_args.count, default=128,
                   help='calibrate on this many images of --data (all, if it has fewer)')
    q.add_argument('--eval-data', help='held-out set to evaluate the int8 model on')
    q.set_defaults(run=_quantize)
    p = command('profile', help='params and MACs per layer type vs YOLOv3-tiny')
    p.add_argument('--model', nargs='*', default=[f'{MODELS}/detector_fp32.pt',
                                                  f'{MODELS}/detector_pruned.pt'],
                   help='.pt models to profile beside the references')
    p.set_defaults(run=_profile)
    return ap


def register(sub: 'argparse._SubParsersAction[Any]') -> None:
    """Add ``uav-tilt vision ...``: everything after ``vision`` goes to :func:`main`."""
    p = sub.add_parser('vision', add_help=False, prefix_chars='\0',
                       help='detector data set, training, evaluation, compression, profile')
    p.add_argument('args', nargs=argparse.REMAINDER,
                   help='a sub-command and its options (`uav-tilt vision --help`)')
    p.set_defaults(func=lambda a: main(a.args), full_parser=parser)


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv``, run the sub-command, print its JSON result; returns 0, or 2 with one
    line on stderr for a bad input (an option's value, a file or folder it reads)."""
    ap = parser()
    a = ap.parse_args(argv)
    if getattr(a, 'grow_scales', None) and not a.init:
        ap.error('--grow-scales needs --init (the model to grow)')
    for option in ('img_size', 'crop'):    # the network's input: whole stride-32 cells
        values = getattr(a, option, None)
        if values and any(v <= 0 or v % 32 for v in values):
            ap.error(f'--{option.replace("_", "-")} must be positive multiples of 32, '
                     f'got {values}')
    if getattr(a, 'distance_m', None):
        from uav_tilt_vision.training.dataset import check_distance
        try:
            check_distance(a.distance_m)
        except ConfigError as err:
            ap.error(f'--distance-m: {err}')
    if a.threads:
        import torch
        torch.set_num_threads(a.threads)
    try:
        result = a.run(a)
    except (OSError, ConfigError) as err:     # a bad path or set, not a bug: no traceback
        print(f'{ap.prog}: error: {err}', file=sys.stderr)
        return 2
    print(json.dumps(result, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
