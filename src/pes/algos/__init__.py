"""The methods: one file per method, each with its settings (a
:class:`pes.learn.config.LearnerConfig`), its presets and its learner
(:class:`pes.learn.learner.Learner`), on the shared machinery of :mod:`pes.learn`.

``ALGOS`` (:mod:`pes.algos.registry`) maps each ``pes train --algo`` name to its learner class;
adding a method is one file and one line there (docs/algorithms/write_your_own.md).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pes.algos.loading import load_evader_actor
from pes.algos.registry import ALGOS, PURSUER_ALGOS, TABLE4_ALGOS, learner_class
from pes.learn import config, trainer
from pes.sim.evader import register_model_loader

register_model_loader(load_evader_actor)


def build_train_config(
    algo: str,
    preset: str = "quick",
    values: dict[str, Any] | None = None,
    protocol: str | None = None,
) -> config.TrainConfig:
    """The configuration of ``algo`` under its ``preset`` and the training ``protocol`` (by
    default ``paper`` for the paper preset and the method's default otherwise), with
    ``values`` on top (see :func:`pes.learn.config.build_train_config`)."""
    cls = learner_class(algo)
    if protocol is None and not isinstance((values or {}).get("protocol"), str):
        protocol = "paper" if preset == "paper" else cls.default_protocol
    return config.build_train_config(algo, cls.Config, cls.PRESETS, preset, protocol, values)


def train(cfg: config.TrainConfig, out: str | Path, resume: bool = False, progress: bool = True):
    """Train the method ``cfg.algo`` into the folder ``out`` (:func:`pes.learn.trainer.train`)."""
    return trainer.train(cfg, out, learner_class(cfg.algo), resume=resume, progress=progress)


__all__ = [
    "ALGOS",
    "PURSUER_ALGOS",
    "TABLE4_ALGOS",
    "build_train_config",
    "learner_class",
    "train",
]
