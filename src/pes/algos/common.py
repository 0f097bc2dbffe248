"""Pieces every learner shares: soft target updates, optimiser steps, seeded generators."""

from __future__ import annotations

import copy

import torch
from torch import Tensor, nn


def target_copy(net: nn.Module) -> nn.Module:
    """A frozen copy of ``net`` to serve as its target network."""
    target = copy.deepcopy(net)
    for p in target.parameters():
        p.requires_grad_(False)
    return target


@torch.no_grad()
def soft_update(target: nn.Module, source: nn.Module, tau: float) -> None:
    """``target <- tau * source + (1 - tau) * target``, parameter by parameter."""
    for t, s in zip(target.parameters(), source.parameters()):
        t.lerp_(s, tau)


def optimise(opt: torch.optim.Optimizer, loss: Tensor, params, clip: float) -> float:
    """One gradient step on ``loss``; returns the gradient norm before clipping."""
    opt.zero_grad(set_to_none=True)
    loss.backward()
    norm = torch.nn.utils.clip_grad_norm_(params, clip if clip > 0 else float("inf"))
    opt.step()
    return float(norm)


def masked_mean(x: Tensor, mask: Tensor) -> Tensor:
    """Mean of ``x`` over the entries where ``mask`` is true (0 if there are none)."""
    w = mask.to(x.dtype)
    return (x * w).sum() / w.sum().clamp(min=1.0)
