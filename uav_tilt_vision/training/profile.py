"""Parameter and MAC shares per layer type (3x3 conv, 1x1 conv, BN, other) via forward hooks.

MACs are per image (one multiply-accumulate per weight use). A conv counts
``out_elements * c_in/groups * k_h * k_w``; an un-fused BatchNorm one MAC per output
element (scale and shift); activations, pooling, padding and upsampling only compare
or copy and count 0 MACs.
"""

import os
from typing import Any, Callable, Iterable, Sequence

import torch
from torch import nn

from uav_tilt_vision.detector import Detector, load_model

TYPES = ('conv3x3', 'conv1x1', 'bn', 'other')


def layer_type(module: nn.Module) -> str:
    """Category of a leaf module."""
    if isinstance(module, nn.Conv2d) and module.kernel_size in ((3, 3), (1, 1)):
        return f'conv{module.kernel_size[0]}x{module.kernel_size[1]}'
    if isinstance(module, nn.modules.batchnorm._BatchNorm):
        return 'bn'
    return 'other'


def layer_macs(module: nn.Module, out: torch.Tensor) -> int:
    """MACs of one call of a leaf module for a single image, given its output."""
    per_image = out.numel() // out.shape[0]
    if isinstance(module, nn.Conv2d):
        k = module.kernel_size[0] * module.kernel_size[1]
        return per_image * module.in_channels // module.groups * k
    if isinstance(module, nn.modules.batchnorm._BatchNorm):
        return per_image
    return 0


def profile_model(model: nn.Module, input_shape: Sequence[int]) -> dict[str, Any]:
    """Profile ``model`` on a zero input of ``input_shape`` (B, C, H, W).

    Returns {'params', 'macs', 'by_type': {type: {'params', 'macs', 'params_share',
    'macs_share'}}, 'layers': [{'name', 'type', 'params', 'macs'}]}.
    """
    layers: list[dict[str, Any]] = []
    handles = []

    def hook(name: str) -> Callable[[nn.Module, Any, torch.Tensor], None]:
        def record(module: nn.Module, _inputs: Any, out: torch.Tensor) -> None:
            layers.append({'name': name, 'type': layer_type(module),
                           'params': sum(p.numel() for p in module.parameters(recurse=False)),
                           'macs': layer_macs(module, out)})
        return record

    for name, module in model.named_modules():
        if not list(module.children()):
            handles.append(module.register_forward_hook(hook(name)))
    was_training = model.training
    model.eval()
    try:
        with torch.no_grad():
            model(torch.zeros(input_shape, device=next(model.parameters()).device))
    finally:
        for h in handles:
            h.remove()
        model.train(was_training)
    total_p = sum(r['params'] for r in layers)
    total_m = sum(r['macs'] for r in layers)
    by_type: dict[str, dict[str, float]] = {}
    for t in TYPES:
        p = sum(r['params'] for r in layers if r['type'] == t)
        m = sum(r['macs'] for r in layers if r['type'] == t)
        by_type[t] = {'params': p, 'macs': m, 'params_share': p / max(total_p, 1),
                      'macs_share': m / max(total_m, 1)}
    return {'params': total_p, 'macs': total_m, 'by_type': by_type, 'layers': layers}


def report(model_paths: Iterable[str | os.PathLike[str]] = ()) -> dict[str, Any]:
    """Summaries (params, MACs, by_type) at 320x256 of the reference YOLOv3-tiny (80 classes),
    its stride-8 variant and each ``Detector`` checkpoint in ``model_paths``."""
    models = [('yolov3_tiny_ref_80cls', Detector(80, 1.0)),
              ('yolov3_tiny_3l_ref_80cls', Detector(80, 1.0, scales=3))]
    models += [(str(path), load_model(path)) for path in model_paths]
    out = {}
    for label, model in models:
        prof = profile_model(model, (1, 3, model.img_size[1], model.img_size[0]))
        out[label] = {k: prof[k] for k in ('params', 'macs', 'by_type')}
    return out
