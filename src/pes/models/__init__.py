"""Trained policies shipped with PES (policy files and their model cards).

* ``evader_ddpg_paper.pt`` / ``evader_ddpg_paper.md``: the default frozen DDPG evader
  (``evader_policy="ddpg"``, ``evader_model="evader-ddpg-paper"``), calibrated to the paper's;
* ``evader_ddpg.pt`` / ``evader_ddpg.md``: the fully trained DDPG evader, far stronger
  (``evader_model="evader-ddpg"``);
* ``cbc_tp.pt`` / ``cbc_tp.md``: a CBC-TP Net swarm (``pes eval --policy cbc-tp``).

Load them with :func:`pes.algos.loading.load_pursuer_policy` /
:func:`pes.algos.loading.load_evader_actor` by name.
"""

from __future__ import annotations

from pathlib import Path

from pes.sim.config import SHIPPED_EVADERS, EnvConfig

MODELS_DIR = Path(__file__).resolve().parent
"""Where the shipped policy files and their model cards live."""
SHIPPED = {name: f"{name.replace('-', '_')}.pt" for name in ("cbc-tp", *SHIPPED_EVADERS)}
"""Shipped policy files by name: the CBC-TP Net swarm and the DDPG evaders of
:data:`pes.sim.config.SHIPPED_EVADERS` (``cbc-tp`` -> ``cbc_tp.pt``)."""


def is_shipped(name: str) -> bool:
    """Whether this installation holds the shipped model ``name`` (a key of :data:`SHIPPED`)."""
    return (MODELS_DIR / SHIPPED[name]).is_file()


def default_evader_policy() -> str:
    """The evader of every evaluation: ``ddpg`` (the default ``EnvConfig.evader_model``) if this
    installation holds that evader, ``flee`` if not."""
    return "ddpg" if is_shipped(EnvConfig().evader_model) else "flee"
