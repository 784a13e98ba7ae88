"""What both training loops share: the learning-rate schedule and the RNG states a resume restores."""

from __future__ import annotations

import math
import random
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch


def warmup_cosine(step: int, total: int, warmup_steps: int, final_fraction: float) -> float:
    """Learning-rate factor of `step`: linear warm-up, then cosine decay to `final_fraction`."""
    if step < warmup_steps:
        return (step + 1) / warmup_steps
    progress = min(1.0, (step - warmup_steps) / max(1, total - warmup_steps))
    cosine = 0.5 * (1 + math.cos(math.pi * progress))
    return final_fraction + (1 - final_fraction) * cosine


def seed_everything(seed: int) -> None:
    """Seed the global torch, numpy and Python RNGs (a training run's start)."""
    torch.manual_seed(seed)
    np.random.seed(seed)
    random.seed(seed)


def rng_state(generators: Mapping[str, torch.Generator] | None = None) -> dict[str, Any]:
    """The global torch, numpy, Python (and CUDA) RNG states, plus those of named `generators`."""
    state: dict[str, Any] = {
        "torch": torch.get_rng_state(), "numpy": np.random.get_state(), "python": random.getstate(),
        "cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else None}
    for name, generator in (generators or {}).items():
        state[name] = generator.get_state()
    return state


def restore_rng(state: Mapping[str, Any], generators: Mapping[str, torch.Generator] | None = None) -> None:
    """Put back what `rng_state` saved."""
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["python"])
    if state.get("cuda") is not None and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])
    for name, generator in (generators or {}).items():
        generator.set_state(state[name])
