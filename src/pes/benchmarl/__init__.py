"""BenchMARL task family for PES: ``PESTask`` (tasks) and ``PESClass`` (how to build them).

Install with ``pip install "pes[benchmarl]"``. The tasks run :class:`pes.torchrl.PESTorchRLEnv`
(one vectorised env of ``num_envs`` games, continuous actions, one group ``"pursuers"``):

============== ===================================================================================
task           scenario (:class:`pes.EnvConfig` overrides on top of the defaults)
============== ===================================================================================
``default``    the paper's scenario as configured by default (5 pursuers, the flee evader)
``damaged``    ``damaged=1``: one random pursuer disabled from the start of every episode
``point_mass`` ``dynamics="point_mass"``: the clipped acceleration applied directly, no attitude
               loop (faster, for ablations)
``easy``       the four corner blocks removed as well as the central one (four buildings left)
               and the evader capped at 8 m/s (slower than the pursuers' 10)
``train``      what PES's own learners train in under the ``pes`` protocol: the default DDPG
               evader, the protocol's training reward and the disturbance, crashes that let a
               pursuer fly on (:meth:`pes.learn.protocol.Protocol.env_overrides`); the
               protocol's other aids (demonstrations, curricula, noise schedule) are PES's
               trainer's and do not apply here
============== ===================================================================================

A task's config is a flat mapping of :class:`pes.EnvConfig` keys (unknown keys fail loudly, as in
PES; keys left out keep the EnvConfig defaults), plus ``sim_compile`` (the simulator's
``torch.compile``). BenchMARL's own algorithm, model and experiment configs apply unchanged.
BenchMARL warns "TaskConfig python dataclass not found": it looks for task dataclasses inside its
own package only; PES checks the keys itself (:meth:`pes.EnvConfig.from_dict`). What BenchMARL
sees:

* observation spec: ``("pursuers", "observation")`` (N, 9N) only; the env also carries the row
  and alive masks, which BenchMARL's models do not take;
* state spec: ``"state"`` (8(N+1),), the global state, used by centralised critics (MAPPO,
  MADDPG, MASAC...);
* info spec: ``("pursuers", "info")`` with ``crashed`` and ``distance``, logged per iteration as
  ``collection/pursuers/info/...``; :meth:`PESClass.log_info` adds ``collection/success_rate``
  (captures among the episodes that ended in the batch);
* ``max_steps``: the episode limit ``max_steps`` of the scenario (500 by default).

Command line (BenchMARL's hydra entry point with the PES tasks registered)::

    python -m pes.benchmarl algorithm=mappo task=pes/default
    python -m pes.benchmarl algorithm=masac task=pes/easy task.num_pursuers=3 \\
        experiment.max_n_frames=200000

From Python::

    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models import MlpConfig
    from pes.benchmarl import PESTask

    Experiment(
        task=PESTask.DEFAULT.get_task(),  # or .get_task({"num_pursuers": 3, ...})
        algorithm_config=MappoConfig.get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=ExperimentConfig.get_from_yaml(),
    ).run()
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

try:
    import torch
    from benchmarl.environments import Task, TaskClass, task_config_registry
    from benchmarl.utils import _read_yaml_config
    from tensordict import TensorDictBase
    from torchrl.data import Composite
    from torchrl.envs import EnvBase
except ImportError as exc:  # pragma: no cover - depends on the optional extra
    raise ImportError("pes.benchmarl needs BenchMARL: pip install 'pes[benchmarl]'") from exc

from pes.learn.protocol import PROTOCOLS
from pes.sim.config import EnvConfig
from pes.torchrl import GROUP, PESTorchRLEnv

ENV_NAME = "pes"
"""The environment's name in BenchMARL (tasks are ``pes/<task>``)."""

TASK_CONFIGS: dict[str, dict[str, Any]] = {
    "default": {},
    "damaged": {"damaged": 1, "damage_step": 0},
    "point_mass": {"dynamics": "point_mass"},
    "easy": {
        "removed_blocks": [[0, 0], [0, 2], [1, 1], [2, 0], [2, 2]],
        "evader_max_speed": 8.0,
    },
    "train": {"evader_policy": "ddpg", **PROTOCOLS["pes"].env_overrides()},
}
"""Each task's config: :class:`pes.EnvConfig` keys over the defaults (see the module docstring)."""

ADAPTER_KEYS = {"sim_compile": False}
"""Task keys that are not scenario keys, with their defaults."""


def task_config(name: str) -> dict[str, Any]:
    """The full config of task ``name``: every :class:`pes.EnvConfig` key (the defaults, then
    the task's overrides) and the adapter keys, as BenchMARL shows and saves it."""
    base = json_ready(dataclasses.asdict(EnvConfig()))
    return {**base, **ADAPTER_KEYS, **copy.deepcopy(TASK_CONFIGS[name])}


def json_ready(value: Any) -> Any:
    """Tuples as lists, recursively (YAML- and OmegaConf-friendly)."""
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_ready(v) for v in value]
    return value


class PESClass(TaskClass):
    """How BenchMARL builds and reads a PES task (see the module docstring)."""

    def _split_config(self) -> tuple[EnvConfig, dict[str, Any]]:
        config = copy.deepcopy(self.config)
        options = {key: config.pop(key, default) for key, default in ADAPTER_KEYS.items()}
        return EnvConfig.from_dict(config), options

    def get_env_fun(
        self,
        num_envs: int,
        continuous_actions: bool,
        seed: int | None,
        device: Any,
    ) -> Callable[[], EnvBase]:
        if not continuous_actions:
            raise ValueError("PES tasks have continuous actions only")
        # Validate now, so that a bad key fails before BenchMARL builds anything.
        env_config, options = self._split_config()
        return lambda: PESTorchRLEnv(
            env_config, num_envs, device, seed, sim_compile=bool(options["sim_compile"])
        )

    def supports_continuous_actions(self) -> bool:
        return True

    def supports_discrete_actions(self) -> bool:
        return False

    def has_render(self, env: EnvBase) -> bool:
        return False

    def max_steps(self, env: EnvBase) -> int:
        return self._split_config()[0].max_steps

    def group_map(self, env: EnvBase) -> dict[str, list[str]]:
        env_config = self._split_config()[0]
        return {GROUP: [f"pursuer_{i}" for i in range(env_config.num_pursuers)]}

    def observation_spec(self, env: EnvBase) -> Composite:
        spec = env.full_observation_spec_unbatched
        group = spec[GROUP]
        return Composite(
            {GROUP: Composite(observation=group["observation"].clone(), shape=group.shape)}
        )

    def info_spec(self, env: EnvBase) -> Composite | None:
        group = env.full_observation_spec_unbatched[GROUP]
        return Composite({GROUP: Composite(info=group["info"].clone(), shape=group.shape)})

    def state_spec(self, env: EnvBase) -> Composite | None:
        return Composite(state=env.full_observation_spec_unbatched["state"].clone())

    def action_spec(self, env: EnvBase) -> Composite:
        return env.full_action_spec_unbatched

    def action_mask_spec(self, env: EnvBase) -> Composite | None:
        return None

    @staticmethod
    def log_info(batch: TensorDictBase) -> dict[str, float]:
        """``collection/success_rate``: captures among the episodes that ended in ``batch``."""
        done = batch.get(("next", "done"))
        if not bool(done.any()):
            return {}
        success = batch.get(("next", "success"))[done]
        return {"collection/success_rate": success.to(torch.float32).mean().item()}

    @staticmethod
    def env_name() -> str:
        return ENV_NAME


class PESTask(Task):
    """The PES tasks for BenchMARL; ``PESTask.X.get_task(config=None)`` gives the task with its
    full default config (:func:`task_config`), or with ``config`` (EnvConfig keys over the
    EnvConfig defaults) instead."""

    DEFAULT = None
    DAMAGED = None
    POINT_MASS = None
    EASY = None
    TRAIN = None

    @staticmethod
    def associated_class():
        return PESClass

    def get_from_yaml(self, path: str | None = None) -> TaskClass:
        """The task with its default config, or with the config read from the YAML ``path``
        (BenchMARL reads task YAML files from its own package, where PES has none)."""
        if path is None:
            config = task_config(self.name.lower())
        else:
            config = dict(_read_yaml_config(str(Path(path))))
            config.pop("defaults", None)
        return self.get_task(config=config)


def register() -> None:
    """Make ``pes/<task>`` known to BenchMARL's task registry and to its hydra config store, so
    that ``task=pes/default`` works in BenchMARL's command line (see ``python -m pes.benchmarl``).
    Idempotent."""
    for task in PESTask:
        task_config_registry[f"{ENV_NAME}/{task.name.lower()}"] = task
    try:
        from hydra.core.config_store import ConfigStore
    except ImportError:  # pragma: no cover - hydra comes with BenchMARL
        return
    store = ConfigStore.instance()
    for name in TASK_CONFIGS:
        store.store(group=f"task/{ENV_NAME}", name=name, node=task_config(name))


register()
