"""``python -m pes.benchmarl algorithm=<algo> task=pes/<task> [hydra overrides]``.

BenchMARL's own command line (``benchmarl/run.py``: its config tree, its algorithm, model and
experiment configs) with the PES tasks registered, so ``task=pes/default``, ``pes/damaged``,
``pes/point_mass``, ``pes/easy`` and ``pes/train`` work next to BenchMARL's tasks, and every
EnvConfig key is a task override: ``task.num_pursuers=3``, ``task.disturbance=true``.
"""

from __future__ import annotations

import hydra
from benchmarl.hydra_config import load_experiment_from_hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from pes.benchmarl import register

register()


@hydra.main(version_base=None, config_path="pkg://benchmarl.conf", config_name="config")
def main(cfg: DictConfig) -> None:
    """Run one BenchMARL experiment, as ``benchmarl/run.py`` does."""
    choices = HydraConfig.get().runtime.choices
    print(f"\nAlgorithm: {choices.algorithm}, Task: {choices.task}")
    print("\nLoaded config:\n")
    print(OmegaConf.to_yaml(cfg))
    load_experiment_from_hydra(cfg, task_name=choices.task).run()


if __name__ == "__main__":
    main()
