"""Load the policy of a BenchMARL experiment run on PES, for ``pes eval``.

    pes eval --policy OUT/<experiment>/checkpoints/checkpoint_<frames>.pt --episodes 1000 \\
        --disturbance

BenchMARL writes a checkpoint of the whole experiment every ``checkpoint_interval`` frames
(and one at the end with ``checkpoint_at_end``) into ``<experiment>/checkpoints/`` and its
configuration beside them (``<experiment>/config.pkl``): that layout is what ``pes eval``
recognises. :func:`load_benchmarl_policy` rebuilds the experiment from them
with BenchMARL's own ``Experiment.reload_from_file`` (loggers off, in a temporary folder, so
the run's folder is left as it was) and wraps its policy as a
:class:`pes.torchrl.TorchRLPolicy`: the tanh of the mean of MAPPO's and IPPO's Gaussian
(TorchRL's deterministic sample of a ``TanhNormal``), the actor of MADDPG and MASAC without
exploration noise.
"""

from __future__ import annotations

import contextlib
import io
import tempfile
from pathlib import Path

from pes.errors import CheckpointError, ConfigError
from pes.sim.config import EnvConfig
from pes.torchrl import GROUP, TorchRLPolicy


def load_benchmarl_policy(
    path: str | Path, config: EnvConfig, device: str = "cpu"
) -> TorchRLPolicy:
    """The deterministic policy of the BenchMARL checkpoint ``path``, checked against the
    scenario ``config`` it will be evaluated in (the same number of pursuers). The experiment is
    rebuilt on the CPU, whatever device it trained on (its replay buffer stays there); the
    policy's networks then move to ``device`` (``"cpu"``, ``"cuda"``...)."""
    from benchmarl.experiment import Experiment

    path = Path(path)
    patch = {"loggers": [], "create_json": False, "restore_map_location": "cpu"}
    try:
        # BenchMARL writes the rebuilt experiment's config.pkl into its save folder: a
        # temporary one, so that evaluating a run leaves the run's folder as it was.
        with tempfile.TemporaryDirectory() as scratch:
            patch["save_folder"] = scratch
            with contextlib.redirect_stdout(io.StringIO()):  # it prints its whole config
                experiment = Experiment.reload_from_file(str(path), experiment_patch=patch)
    except Exception as exc:  # noqa: BLE001 - any failure to rebuild is the file's fault
        raise CheckpointError(f"cannot load the BenchMARL experiment of {path}: {exc}") from exc
    agents = experiment.group_map.get(GROUP, [])
    if len(agents) != config.num_pursuers:
        raise ConfigError(
            f"{path} was trained with {len(agents)} pursuers, the scenario has "
            f"{config.num_pursuers} (set num_pursuers={len(agents)})"
        )
    return TorchRLPolicy(experiment.policy.to(device))


__all__ = ["load_benchmarl_policy"]
