"""A fine-tuned head moved back towards the pretrained one, in weight space (WiSE-FT).

Wortsman et al. ("Robust fine-tuning of zero-shot models", CVPR 2022) interpolate every weight of a
fine-tuned network with its pretrained start, θ = α·θ_fine-tuned + (1 − α)·θ_pretrained, and keep
most of what fine-tuning gained on its own data while recovering what the start knew elsewhere. For
FishLoc only the head was fine-tuned (backbone and neck frozen, the foot branch on its own copy of
the neck), so only the head's weights are interpolated; everything else stays as it is and must be
the same in both networks. A run that trained the whole network from a FishLoc checkpoint
(`fishloc train --distill-features`) is interpolated whole towards that checkpoint
(`interpolate_network`, `wise_from_checkpoint`): the paper's full form.
"""

from __future__ import annotations

from dataclasses import replace

import torch

from detector.checkpoint import Checkpoint, CheckpointError, load_checkpoint
from detector.nanodet.network import NanoDetPlus
from detector.yolox.network import YoloxNano
from detector.yolox.polar import PolarDetectorConfig, init_network_from_pretrained

HEAD_PREFIX = "head."
OWN_PREFIXES = ("foot.",)  # trained on their own: kept from the fine-tuned network


def interpolate_head(fine_tuned: dict[str, torch.Tensor], pretrained: dict[str, torch.Tensor], alpha: float
                     ) -> dict[str, torch.Tensor]:
    """State dicts -> the fine-tuned state with each `head.*` tensor α·fine-tuned + (1 − α)·pretrained.

    ValueError when α is outside [0, 1], a head tensor is missing or shaped differently, or a
    tensor outside the head (and the foot branch) differs: then more than the head was trained and
    a head-only interpolation would mix two networks."""
    if not 0.0 <= alpha <= 1.0:
        raise ValueError(f"alpha must lie in [0, 1], got {alpha}")
    blended: dict[str, torch.Tensor] = {}
    for name, tensor in fine_tuned.items():
        if name.startswith(OWN_PREFIXES):
            blended[name] = tensor
            continue
        if name not in pretrained or pretrained[name].shape != tensor.shape:
            raise ValueError(f"{name} {tuple(tensor.shape)} has no counterpart of that shape in the "
                             "pretrained network")
        if name.startswith(HEAD_PREFIX) and tensor.is_floating_point():
            blended[name] = alpha * tensor + (1.0 - alpha) * pretrained[name].to(tensor.dtype)
        elif not torch.equal(tensor, pretrained[name]):
            raise ValueError(f"{name} differs from the pretrained network outside the head: more than "
                             "the head was trained")
        else:
            blended[name] = tensor
    return blended


def wise_checkpoint(checkpoint: Checkpoint, pretrained_path: str, alpha: float) -> Checkpoint:
    """`checkpoint` (a polar YOLOX-Nano or NanoDet-Plus-m whose head alone was fine-tuned) with its
    head interpolated towards the COCO network of `pretrained_path`, the ONNX it started from
    (`init_network_from_pretrained`); CheckpointError when that cannot be done."""
    config = checkpoint.config
    if not isinstance(config, PolarDetectorConfig):
        raise CheckpointError("the head interpolation needs a polar checkpoint")
    fine_tuned = checkpoint.build()
    if not isinstance(fine_tuned, YoloxNano | NanoDetPlus):
        raise CheckpointError("the head interpolation needs a YOLOX-Nano or NanoDet-Plus-m network")
    try:
        pretrained = init_network_from_pretrained(pretrained_path, config).state_dict()
        state = interpolate_head(fine_tuned.state_dict(), pretrained, alpha)
    except (ValueError, OSError) as error:
        raise CheckpointError(f"{pretrained_path}: {error}") from None
    return replace(checkpoint, model_state=state, training_state={})


def interpolate_network(fine_tuned: dict[str, torch.Tensor], start: dict[str, torch.Tensor], alpha: float
                        ) -> dict[str, torch.Tensor]:
    """State dicts -> each floating tensor α·fine-tuned + (1 − α)·start, every other tensor the
    fine-tuned one's. ValueError when α is outside [0, 1] or the two networks' tensors differ in
    names or shapes."""
    if not 0.0 <= alpha <= 1.0:
        raise ValueError(f"alpha must lie in [0, 1], got {alpha}")
    if set(fine_tuned) != set(start):
        differ = sorted(set(fine_tuned) ^ set(start))
        raise ValueError(f"the two networks' weights differ in names: {', '.join(differ[:4])}")
    blended: dict[str, torch.Tensor] = {}
    for name, tensor in fine_tuned.items():
        if start[name].shape != tensor.shape:
            raise ValueError(f"{name} is {tuple(tensor.shape)} in one network and {tuple(start[name].shape)} "
                             "in the other")
        blended[name] = (alpha * tensor + (1.0 - alpha) * start[name].to(tensor.dtype)
                         if tensor.is_floating_point() else tensor)
    return blended


def wise_from_checkpoint(checkpoint: Checkpoint, start_path: str, alpha: float) -> Checkpoint:
    """`checkpoint` with every weight interpolated towards the checkpoint at `start_path`, the one
    its run started from (`--init-from`): the same network, view and graph options, weights
    only; CheckpointError when that cannot be done (a file that does not load, another network)."""
    start = load_checkpoint(start_path)
    if start.config != checkpoint.config:
        raise CheckpointError(f"{start_path} is another network or view ({start.config.to_dict()}) than "
                              f"the one interpolated ({checkpoint.config.to_dict()})")
    try:
        state = interpolate_network(checkpoint.model_state, start.model_state, alpha)
    except ValueError as error:
        raise CheckpointError(f"{start_path}: {error}") from None
    return replace(checkpoint, model_state=state, training_state={})
