"""Detector training and evaluation on a YOLO-format data set (see ``yolo_data``).

``train`` is reproducible from its seed on a given device: seeded initialisation,
seeded loader order and augmentation drawn from (seed, epoch, index).
"""

import json
import math
import os
import random
import subprocess
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable, Sequence, TypeVar, cast

import numpy as np
import torch

from uav_tilt_common.config import ConfigError
from uav_tilt_vision.detector import DEFAULT_ANCHORS, IMG_SIZE, Detector, grow_scales, save_model
from uav_tilt_vision.training.metrics import bootstrap, confidence_intervals, mean_ap
from uav_tilt_vision.training.yolo_data import (HSV_GAINS, YoloDataset, collate,
                                                kmeans_anchors, read_meta)
from uav_tilt_vision.training.yolo_loss import YoloLoss, distill_loss

if TYPE_CHECKING:
    from uav_tilt_vision.backends import OnnxDetector, TorchDetector

T = TypeVar('T')


def progress(iterable: Iterable[T], **kwargs: Any) -> Iterable[T]:
    """tqdm progress bar when tqdm is installed, else the plain iterable."""
    try:
        from tqdm import tqdm
    except ImportError:
        return iterable
    return tqdm(iterable, **kwargs)


def resolve_device(device: str = 'auto') -> torch.device:
    """'auto' -> CUDA when available, else CPU; ConfigError for a device this machine lacks."""
    if device == 'auto':
        device = 'cuda' if torch.cuda.is_available() else 'cpu'
    try:
        dev = torch.device(device)
    except RuntimeError:
        raise ConfigError(f'device {device!r}: not a torch device (auto, cpu, cuda, cuda:N)'
                          ) from None
    if dev.type == 'cuda' and (dev.index or 0) >= torch.cuda.device_count():
        raise ConfigError(f'device {device!r}: this machine has '
                          f'{torch.cuda.device_count()} CUDA devices')
    if dev.type not in ('cpu', 'cuda'):
        raise ConfigError(f'device {device!r}: only cpu and cuda are supported')
    return dev


def git_commit() -> str | None:
    """HEAD commit of the repository holding this file, or None."""
    try:
        res = subprocess.run(['git', 'rev-parse', 'HEAD'], cwd=Path(__file__).parent,
                             capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return res.stdout.strip() if res.returncode == 0 else None


def card_path(weights_path: str | os.PathLike[str]) -> Path:
    """Model card JSON path beside the weights (same stem, .json)."""
    return Path(weights_path).with_suffix('.json')


def num_classes_of(dataset: YoloDataset, meta: dict[str, Any]) -> int:
    """Class count from meta.json 'classes', else the largest label + 1."""
    if meta.get('classes'):
        return len(meta['classes'])
    labels = np.concatenate([dataset.labels(i)[:, 0] for i in range(len(dataset))])
    return int(labels.max()) + 1 if len(labels) else 1


def check_crop(crop: Sequence[int] | None, img_size: Sequence[int]) -> None:
    """ConfigError unless training window ``crop`` (w, h; None: none) fits the input."""
    if crop and not all(0 < c <= s for c, s in zip(crop, img_size)):
        raise ConfigError(f'crop {list(crop)} must fit the {list(img_size)} input')


def train(data_dir: str | os.PathLike[str], out_path: str | os.PathLike[str], epochs: int = 50,
          seed: int = 0, width_mult: float = 0.25, img_size: Sequence[int] = IMG_SIZE,
          batch: int = 16, device: str = 'auto', lr: float = 3e-3, weight_decay: float = 5e-4,
          augment: bool = True, hflip: bool = False, anchors: Any = None,
          eval_dir: str | os.PathLike[str] | None = None, workers: int = 0,
          log: Callable[[str], Any] = print, model: Detector | None = None,
          crop: Sequence[int] | None = None, ema_decay: float = 0.999, scales: int = 2,
          hsv: Sequence[float] = HSV_GAINS, teacher: Detector | None = None,
          distill_gain: float = 1.0, card_extra: dict[str, Any] | None = None,
          bf16: bool = False) -> dict[str, Any]:
    """Train a ``Detector`` and write weights (``save_model``) plus a model card JSON beside them.

    ``anchors`` None = k-means on the training labels (defaults when too few boxes).
    ``scales``: detection heads of a new model (2: YOLOv3-tiny, 3: its stride-8 variant).
    ``model``: fine-tune this model (e.g. a pruned one) instead of a new one; it keeps its
    anchors and input size, and ``width_mult``, ``img_size``, ``anchors`` and ``scales`` are
    then unused.
    ``crop`` (w, h): train on object-centred windows of the input (``yolo_data.random_crop``).
    ``hsv``: hue, saturation and value jitter of the augmentation.
    ``eval_dir``: optional YOLO-format set evaluated at the end (metrics go in the card).
    ``ema_decay``: the weights written (and left in ``model``) are an exponential moving
    average of the trained ones (``ema_average``); 0 keeps the last step's weights.
    ``teacher``: a ``Detector`` with the same heads and anchors (e.g. the unpruned model a
    pruned ``model`` came from) whose outputs the model also learns to match, with
    ``yolo_loss.distill_loss`` weighted by ``distill_gain``.
    ``card_extra``: entries added to the model card (e.g. the lineage of a fine-tuned model).
    ``bf16``: run the networks' forward passes in bfloat16 autocast (weights, optimiser and
    loss stay float32); about 1.5x faster steps on CPUs with AVX-512 BF16.
    Returns the model card dict.
    """
    torch.manual_seed(seed)
    np.random.seed(seed)
    random.seed(seed)
    dev = resolve_device(device)
    torch.backends.cudnn.benchmark = False
    if model is not None:
        img_size = model.img_size
    check_crop(crop, img_size)
    ds = YoloDataset(data_dir, img_size, augment=augment, hflip=hflip, seed=seed,
                     crop=crop if augment else None, hsv=tuple(hsv))
    meta = read_meta(data_dir)
    n_cls = num_classes_of(ds, meta)
    if model is not None and n_cls > model.num_classes:   # its heads cannot score the rest
        raise ConfigError(f'{data_dir} has {n_cls} classes, the model {model.num_classes}')
    if model is None:
        if anchors is None:
            try:
                anchors = kmeans_anchors(ds.label_wh(), num_scales=scales)
            except ValueError:
                anchors = DEFAULT_ANCHORS[scales]
        model = Detector(n_cls, width_mult, anchors=anchors, img_size=img_size, scales=scales)
    # channels_last: oneDNN's convolutions and their gradients run ~1.3x faster on CPU
    # (torch's stubs of Module.to leave out the memory_format it takes)
    model = model.to(dev, memory_format=torch.channels_last)  # type: ignore[call-overload]
    if teacher is not None:
        check_teacher(teacher, model)
        teacher = teacher.to(  # type: ignore[call-overload]
            dev, memory_format=torch.channels_last).eval()
    loss_fn = YoloLoss(model.anchors).to(dev)
    loader = torch.utils.data.DataLoader(
        ds, batch_size=batch, shuffle=True, collate_fn=collate, num_workers=workers,
        generator=torch.Generator().manual_seed(seed), pin_memory=dev.type == 'cuda')
    # no weight decay on BN parameters and biases (1-D tensors)
    params = list(model.parameters())
    groups: list[dict[str, Any]] = [
        {'params': [p for p in params if p.ndim > 1]},
        {'params': [p for p in params if p.ndim <= 1], 'weight_decay': 0}]
    opt = torch.optim.AdamW(groups, lr=lr, weight_decay=weight_decay)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=epochs * len(loader),
                                                pct_start=0.15)
    ema = torch.optim.swa_utils.AveragedModel(model, avg_fn=ema_average(ema_decay),
                                              use_buffers=True)
    history = []
    model.train()
    for epoch in progress(range(epochs), desc='train', unit='epoch'):
        ds.set_epoch(epoch)
        total = 0.0
        parts: dict[str, float] = {}
        for images, targets in loader:
            images = images.to(dev, non_blocking=True, memory_format=torch.channels_last)
            with torch.autocast(dev.type, dtype=torch.bfloat16, enabled=bf16):
                heads = [h.float() for h in model(images)]
                if teacher is not None:
                    with torch.no_grad():
                        teacher_heads = [h.float() for h in teacher(images)]
            loss, comp = loss_fn(heads, targets)
            if teacher is not None:
                d_loss, d_comp = distill_loss(heads, teacher_heads, model.anchors.shape[1])
                loss = loss + distill_gain * d_loss
                comp.update(d_comp)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            ema.update_parameters(model)
            total += loss.item()
            parts = {k: parts.get(k, 0.0) + v for k, v in comp.items()}
        history.append(total / len(loader))
        log(f'epoch {epoch + 1}/{epochs} loss {history[-1]:.4f} '
            + ' '.join(f'{k} {v / len(loader):.4f}' for k, v in parts.items()))
    # the anchors are a constant buffer: float rounding in the average would drift them
    cast(Detector, ema.module).anchors.copy_(model.anchors)
    model.load_state_dict(ema.module.state_dict())
    model = model.to(  # type: ignore[call-overload]
        memory_format=torch.contiguous_format).eval()
    card = {'data_dir': str(data_dir), 'data_seed': meta.get('seed'),
            'classes': meta.get('classes'), 'num_classes': n_cls, 'epochs': epochs,
            'seed': seed, 'width_mult': model.width_mult, 'img_size': list(model.img_size),
            'scales': len(model.strides), 'batch': batch, 'crop': list(crop) if crop else None,
            'hsv': list(hsv),
            'lr': lr, 'ema_decay': ema_decay, 'device': str(dev), 'bf16': bool(bf16),
            'distill_gain': distill_gain if teacher is not None else None,
            'anchors': model.anchors.tolist(), 'channels': model.channels(),
            'params': sum(p.numel() for p in params),
            'final_loss': history[-1] if history else None, 'loss_history': history,
            'metrics': evaluate(model, eval_dir) if eval_dir else None,
            'git_commit': git_commit(), **(card_extra or {})}
    Path(out_path).parent.mkdir(parents=True, exist_ok=True)
    save_model(out_path, model, card)
    card_path(out_path).write_text(json.dumps(card, indent=2))
    return card


def grown(model: Detector, scales: int, data_dir: str | os.PathLike[str]) -> Detector:
    """``model`` with finer heads added up to ``scales`` (``detector.grow_scales``) for the
    objects smaller than any anchor it has: the new anchors cluster (k-means) the set's
    labels of less area than its smallest anchor, the finest new head the smallest."""
    new = scales - len(model.strides)
    if new < 1:
        raise ConfigError(f'cannot grow the model to {scales} scales: it has '
                          f'{len(model.strides)}')
    wh = YoloDataset(data_dir, model.img_size).label_wh()
    smallest = float(model.anchors.prod(-1).min())
    try:
        anchors = kmeans_anchors(wh[wh.prod(1) < smallest], new)
    except ValueError as err:
        raise ConfigError(f'{data_dir}: too few labels smaller than the model\'s anchors '
                          f'to place {new} new heads\' anchors ({err})') from None
    return grow_scales(model, scales, anchors)


def check_teacher(teacher: Detector, model: Detector) -> None:
    """ConfigError unless ``teacher``'s heads and anchors match ``model``'s (distillation)."""
    t_anchors, m_anchors = teacher.anchors.cpu(), model.anchors.cpu()
    # saved anchors are half precision (detector.save_model): 2**-11 relative rounding
    differ = [what for what, same in (
        ('classes', teacher.num_classes == model.num_classes),
        ('input size', teacher.img_size == model.img_size),
        ('anchors', t_anchors.shape == m_anchors.shape
         and torch.allclose(t_anchors, m_anchors, rtol=1e-3, atol=0.0))) if not same]
    if differ:
        raise ConfigError(f'teacher and model differ in {" and ".join(differ)}')


def ema_average(decay: float, ramp_steps: int = 500
                ) -> Callable[[torch.Tensor, torch.Tensor, Any], torch.Tensor]:
    """``AveragedModel`` update: EMA whose decay ramps up as ``decay * (1 - exp(-n / ramp))``
    (YOLOv5's ModelEMA), so that the random initialisation is forgotten quickly.

    Integer buffers (BatchNorm's batch counter) follow the model.
    """
    def avg(averaged: torch.Tensor, current: torch.Tensor, n_averaged: Any) -> torch.Tensor:
        if not averaged.is_floating_point():
            return current
        d = decay * (1.0 - math.exp(-float(n_averaged) / ramp_steps))
        return averaged * d + current * (1.0 - d)
    return avg


def predict_set(model: 'Detector | TorchDetector | OnnxDetector',
                data_dir: str | os.PathLike[str], conf_thres: float = 0.001,
                iou_thres: float = 0.6, batch: int = 16
                ) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """(predictions, labels, ignore regions) of ``model`` on a YOLO-format set, one array
    per image in ``metrics``' layout.

    ``model``: a ``Detector`` or any object whose ``predict(images, conf_thres, iou_thres)``
    maps a list of uint8 RGB images to one (N, 6) array each (``backends``).
    """
    ds = YoloDataset(data_dir)
    preds: list[np.ndarray] = []
    gts: list[np.ndarray] = []
    ignores: list[np.ndarray] = []
    for start in progress(range(0, len(ds), batch), desc='eval', unit='batch'):
        images = [ds.read_rgb(i) for i in range(start, min(start + batch, len(ds)))]
        preds.extend(model.predict(images, conf_thres, iou_thres))
        for k, img in enumerate(images):
            gts.append(ds.ground_truth(start + k, img.shape))
            ignores.append(ds.ground_truth(start + k, img.shape, 'ignore'))
    return preds, gts, ignores


def class_names(res: dict[str, Any], data_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """``res`` with its per-class entries keyed by the set's class names where it has them."""
    names = read_meta(data_dir).get('classes')
    if names:
        res['ap50_per_class'] = {names[c]: ap for c, ap in res['ap50_per_class'].items()}
    return res


def world_groups(data_dir: str | os.PathLike[str], n: int) -> np.ndarray | None:
    """The world each of a rendered set's ``n`` images shows (``dataset``'s
    ``images_per_world``), for ``metrics.bootstrap``; None for a set without it."""
    per_world = read_meta(data_dir).get('images_per_world')
    return np.arange(n) // per_world if per_world else None


def evaluate(model: 'Detector | TorchDetector | OnnxDetector', data_dir: str | os.PathLike[str],
             conf_thres: float = 0.001, iou_thres: float = 0.6,
             batch: int = 16, resamples: int = 0) -> dict[str, Any]:
    """COCO-style mAP of ``model`` on a YOLO-format set (``metrics.mean_ap``).

    AP@0.5 per class is keyed by the class names of the set's meta.json where it has them.
    The set's ignore regions (objects in view but too little visible to label) are COCO's
    crowd regions: detections on them are neither true nor false positives; the result
    counts them in 'ignore_regions'. With ``resamples`` > 0 it adds 'ci95', the 95%
    bootstrap intervals of the metrics over that many resamplings of the set's worlds
    (``world_groups``; of its images where it does not say).
    """
    preds, gts, ignores = predict_set(model, data_dir, conf_thres, iou_thres, batch)
    if not any(len(g) for g in gts):   # mAP is undefined
        raise ConfigError(f'{data_dir}: no labelled objects to score')
    res = {**mean_ap(preds, gts, ignores), 'ignore_regions': sum(len(i) for i in ignores)}
    if resamples > 0:
        res['ci95'] = class_names(
            confidence_intervals(bootstrap(preds, gts, ignores, resamples,
                                           groups=world_groups(data_dir, len(gts)))),
            data_dir)
    return class_names(res, data_dir)
