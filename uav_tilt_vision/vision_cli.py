"""``uav-tilt vision dataset|train|eval|compress|quantize|profile``; also ``python -m`` it.

Every sub-command prints one JSON object on stdout (progress bars go to stderr).
"""

import argparse
import json
import sys
from typing import Any, Sequence

from uav_tilt_common import resources
from uav_tilt_common.config import ConfigError

MODELS = 'models'


def log_stderr(line: str) -> None:
    """Progress lines go to stderr: stdout is the JSON result."""
    print(line, file=sys.stderr, flush=True)


def _dataset(a):
    from uav_tilt_vision.dataset import DISTANCE_M, generate
    meta = generate(a.out, a.n, a.seed, a.split, a.jobs, renderer=a.renderer,
                    distance_m=a.distance_m or DISTANCE_M)
    return {k: meta[k] for k in ('seed', 'split', 'n', 'classes', 'boxes_per_class',
                                 'renderer', 'distance_m')}


def _train(a):
    from uav_tilt_vision.detector import IMG_SIZE, load_model, resize_input
    from uav_tilt_vision.train import card_path, grown, train
    from uav_tilt_vision.yolo_data import HSV_GAINS
    extra: dict[str, Any] = {'teacher': a.teacher} if a.teacher else {}
    model = load_model(a.init) if a.init else None
    if model is not None and a.img_size and tuple(a.img_size) != model.img_size:
        extra['resized_from'] = list(model.img_size)
        model = resize_input(model, a.img_size)
    if model is not None and a.grow_scales:   # main() refuses --grow-scales without --init
        extra['grown_from_scales'] = len(model.strides)
        model = grown(model, a.grow_scales, a.data)
    if a.init:  # a continued run: its card names the stage it started from
        prior = json.loads(card_path(a.init).read_text())
        extra['init'] = {k: prior.get(k)
                         for k in ('epochs', 'seed', 'lr', 'crop', 'hsv', 'init', 'teacher',
                                   'bf16')}
        extra['total_epochs'] = a.epochs + prior.get('total_epochs', prior['epochs'])
        extra.update({k: prior[k] for k in ('source', 'pruning_ratio') if k in prior})
    card = train(a.data, a.out, a.epochs, a.seed, a.width_mult, batch=a.batch, lr=a.lr,
                 img_size=a.img_size or IMG_SIZE, workers=a.workers,
                 device=a.device, eval_dir=a.eval_data, crop=a.crop, scales=a.scales,
                 hsv=a.hsv or HSV_GAINS,
                 model=model, teacher=load_model(a.teacher) if a.teacher else None,
                 distill_gain=a.distill_gain, card_extra=extra, bf16=a.bf16, log=log_stderr)
    return {k: v for k, v in card.items() if k != 'loss_history'}


def _eval(a):
    from uav_tilt_vision.backends import load_detector
    from uav_tilt_vision.train import evaluate
    det = load_detector(resources.resolve(a.model, '--model'), a.backend)
    return {**evaluate(det, a.data, resamples=a.bootstrap), 'model': a.model,
            'backend_used': det.backend}


def _compress(a):
    from uav_tilt_vision.compress import compress
    return compress(a.model, a.data, a.out_dir, a.ratio, a.finetune_epochs, a.seed,
                    a.calib_images, a.eval_data, crop=a.crop, distill_gain=a.distill_gain,
                    bf16=a.bf16, device=a.device, workers=a.workers, log=log_stderr)


def _quantize(a):
    from uav_tilt_vision.compress import quantize
    return quantize(a.model, a.data, a.calib_images, a.eval_data)


def _profile(a):
    from uav_tilt_vision.profile import report
    return report(resources.resolve(m, '--model') for m in a.model)


def parser() -> argparse.ArgumentParser:
    """The argparse parser of the vision sub-commands."""
    ap = argparse.ArgumentParser(prog='uav-tilt vision', description=__doc__)
    ap.add_argument('--threads', type=int, default=0, help='torch CPU threads (0: default)')
    sub = ap.add_subparsers(dest='command', required=True)
    d = sub.add_parser('dataset', help='render a labelled, domain-randomised image set')
    d.add_argument('--out', required=True)
    d.add_argument('--n', type=int, required=True)
    d.add_argument('--seed', type=int, default=0)
    d.add_argument('--split', choices=('train', 'heldout'), default='train')
    d.add_argument('--jobs', type=int, default=1, help='render processes')
    d.add_argument('--renderer', choices=('gl', 'tiny'), default='gl',
                   help="the camera's renderer (train on the plant's: gl)")
    d.add_argument('--distance-m', type=float, nargs=2, metavar=('MIN', 'MAX'),
                   help='camera distance range, log-uniform (default dataset.DISTANCE_M: the '
                        'mission\'s ranges)')
    d.set_defaults(run=_dataset)
    t = sub.add_parser('train', help='train the fp32 detector; writes weights + model card')
    t.add_argument('--data', required=True)
    t.add_argument('--out', default=f'{MODELS}/detector_fp32.pt')
    t.add_argument('--epochs', type=int, default=16)
    t.add_argument('--seed', type=int, default=0)
    t.add_argument('--width-mult', type=float, default=0.5)
    t.add_argument('--scales', type=int, default=3, choices=(2, 3, 4),
                   help='detection heads: 2 = YOLOv3-tiny, 3 = with a stride-8 head, '
                        '4 = and a stride-4 head')
    t.add_argument('--batch', type=int, default=16)
    t.add_argument('--img-size', type=int, nargs=2, metavar=('W', 'H'),
                   help='network input, multiples of 32 (default detector.IMG_SIZE; with '
                        '--init: that model\'s, or this one, weights and anchors kept)')
    t.add_argument('--workers', type=int, default=0, help='data loader processes')
    t.add_argument('--lr', type=float, default=3e-3)
    t.add_argument('--device', default='auto')
    t.add_argument('--eval-data', help='held-out set whose mAP goes in the model card')
    t.add_argument('--crop', type=int, nargs=2, metavar=('W', 'H'),
                   help='train on object-centred W x H windows (multiples of 32)')
    t.add_argument('--init', help='continue from this checkpoint (its card is cited)')
    t.add_argument('--grow-scales', type=int, choices=(3, 4),
                   help='add finer heads to the --init model up to this many scales (their '
                        'anchors: k-means on the labels smaller than its smallest anchor); '
                        'its other weights are kept')
    t.add_argument('--teacher', help='also learn to match this model\'s outputs (distillation; '
                                     'same classes, input size and anchors)')
    t.add_argument('--distill-gain', type=float, default=1.0,
                   help='weight of the distillation loss (with --teacher)')
    t.add_argument('--hsv', type=float, nargs=3, metavar=('H', 'S', 'V'),
                   help='hue, saturation, value jitter of the augmentation (fractions; '
                        'default yolo_data.HSV_GAINS)')
    t.add_argument('--bf16', action='store_true',
                   help='bfloat16 autocast for the forward passes (faster on CPUs with '
                        'AVX-512 BF16 and on GPUs)')
    t.set_defaults(run=_train)
    e = sub.add_parser('eval', help='COCO mAP of a model on a YOLO-format set')
    e.add_argument('--data', required=True)
    e.add_argument('--model', default=f'{MODELS}/detector_fp32.pt')
    e.add_argument('--backend', default='auto', choices=('auto', 'torch', 'onnxruntime'))
    e.add_argument('--bootstrap', type=int, default=0, metavar='N',
                   help='add 95%% confidence intervals (ci95) from N resamplings of the '
                        'set\'s worlds')
    e.set_defaults(run=_eval)
    c = sub.add_parser('compress', help='prune + fine-tune, then int8 ONNX (static QDQ)')
    c.add_argument('--model', default=f'{MODELS}/detector_fp32.pt')
    c.add_argument('--data', required=True, help='training set (fine-tuning, calibration)')
    c.add_argument('--out-dir', default=MODELS)
    c.add_argument('--ratio', type=float, default=0.5, help='channel pruning ratio')
    c.add_argument('--finetune-epochs', type=int, default=4)
    c.add_argument('--seed', type=int, default=0)
    c.add_argument('--calib-images', type=int, default=128)
    c.add_argument('--eval-data', help='held-out set evaluated for every stage')
    c.add_argument('--crop', type=int, nargs=2, metavar=('W', 'H'),
                   help='fine-tune on object-centred W x H windows')
    c.add_argument('--distill-gain', type=float, default=1.0,
                   help='fine-tune also matching the unpruned model\'s outputs with this '
                        'weight (0: labels only)')
    c.add_argument('--bf16', action='store_true',
                   help='bfloat16 autocast for the fine-tuning\'s forward passes')
    c.add_argument('--device', default='auto', help='fine-tuning device (auto: a GPU if any)')
    c.add_argument('--workers', type=int, default=0, help='data loader processes')
    c.set_defaults(run=_compress)
    q = sub.add_parser('quantize', help='int8 ONNX of a pruned model only (compress step 3)')
    q.add_argument('--model', default=f'{MODELS}/detector_pruned.pt')
    q.add_argument('--data', required=True, help='training set (calibration)')
    q.add_argument('--calib-images', type=int, default=128)
    q.add_argument('--eval-data', help='held-out set to evaluate the int8 model on')
    q.set_defaults(run=_quantize)
    p = sub.add_parser('profile', help='params and MACs per layer type vs YOLOv3-tiny')
    p.add_argument('--model', nargs='*', default=[f'{MODELS}/detector_fp32.pt',
                                                  f'{MODELS}/detector_pruned.pt'],
                   help='.pt models to profile beside the references')
    p.set_defaults(run=_profile)
    return ap


def register(sub: 'argparse._SubParsersAction[Any]') -> None:
    """Add ``uav-tilt vision ...``: everything after ``vision`` goes to :func:`main`."""
    p = sub.add_parser('vision', add_help=False, prefix_chars='\0',
                       help='detector data set, training, evaluation, compression, profile')
    p.add_argument('args', nargs=argparse.REMAINDER)
    p.set_defaults(func=lambda a: main(a.args))


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv``, run the sub-command, print its JSON result; returns 0, or 2 with one
    line on stderr when a file or folder it reads is missing."""
    ap = parser()
    a = ap.parse_args(argv)
    if getattr(a, 'grow_scales', None) and not a.init:
        ap.error('--grow-scales needs --init (the model to grow)')
    if getattr(a, 'img_size', None) and any(v <= 0 or v % 32 for v in a.img_size):
        ap.error(f'--img-size must be positive multiples of 32, got {a.img_size}')
    if getattr(a, 'distance_m', None) and not 0.0 < a.distance_m[0] <= a.distance_m[1]:
        ap.error(f'--distance-m must be 0 < MIN <= MAX, got {a.distance_m}')
    if getattr(a, 'bootstrap', 0) < 0:
        ap.error(f'--bootstrap must be 0 or more, got {a.bootstrap}')
    if a.threads:
        import torch
        torch.set_num_threads(a.threads)
    try:
        result = a.run(a)
    except (FileNotFoundError, ConfigError) as err:     # bad input, not a bug: no traceback
        print(f'{ap.prog}: error: {err}', file=sys.stderr)
        return 2
    print(json.dumps(result, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
