"""TorchRL interface: ``PESTorchRLEnv``, the batched simulator as a multi-agent ``EnvBase``.

Install with ``pip install "pes[torchrl]"``. One instance holds ``num_envs`` games stepped
together as tensors on one device (no Python loop over environments); ``batch_size`` is
``[num_envs]``. The pursuers form one agent group, ``"pursuers"``, following the layout of
TorchRL's ``VmasEnv`` (docs/torchrl.md has the table with shapes and an example):

=================================== ============== =============================================
key                                 shape          meaning
=================================== ============== =============================================
``("pursuers", "observation")``     (E, N, 9N)     pursuer i's N rows of Table I (8 numbers
                                                   each, self first, zero where masked),
                                                   flattened, then the N row-mask bits as 0/1
``("pursuers", "obs_mask")``        (E, N, N) bool which of pursuer i's rows are real
``("pursuers", "mask")``            (E, N) bool    alive: neither damaged nor disabled
``("pursuers", "info", "crashed")`` (E, N, 1)      1.0 on a step in which the pursuer crashed
``("pursuers", "info", "distance")`` (E, N, 1)     pursuer-evader distance (m)
``("pursuers", "action")``          (E, N, 2)      desired horizontal acceleration as a fraction
                                                   of the maximum, in [-1, 1] (clipped to norm 1)
``("pursuers", "reward")``          (E, N, 1)      eqs. (8)-(9) + crash + capture; 0 if dead
``"state"``                         (E, 8(N+1))    the global state for centralised critics
``"success"``                       (E, 1) bool    the episode ended in a capture
``"done"``, ``"terminated"``,       (E, 1) bool    capture or too few pursuers left
``"truncated"``                                    (terminated); ``max_steps`` (truncated)
=================================== ============== =============================================

Done flags are per environment only, as in ``VmasEnv``: every pursuer of a game starts and
ends together. A pursuer that dies mid-episode (``crash_mode="disable"``, ``damaged=K``) stays
in the tensors: its observation and reward are zero and ``("pursuers", "mask")`` is False, so
learners can mask it; its actions are ignored.

Auto-reset and TorchRL's partial reset
--------------------------------------
The simulator resets finished games inside ``step`` (docs/interfaces.md) and keeps the last
observation of the finished episode in ``info["final_obs"]``. TorchRL instead expects ``_step``
to return that last observation and a later ``_reset`` with a ``"_reset"`` mask to start the
next episode. This adapter reconciles the two without stepping anything twice:

* ``_step`` returns the finished episode's last observation (``final_obs``, ``final_state``,
  ...) as ``"next"``, and keeps the simulator's post-reset observation of every game aside.
  Games that finished in this step are marked *auto-reset*: the simulator already started
  their next episode.
* ``_reset`` hands out the kept observation of auto-reset games as their first observation
  (no work), and starts a new episode only for games asked to reset that were not auto-reset
  (a reset while an episode runs, or ``env.reset()`` at the start of a rollout) with the
  simulator's own masked reset pass (:func:`pes.sim.scenario.reset_pass`). Games not in the
  ``"_reset"`` mask are left untouched.

So ``env.rollout(T, break_when_any_done=False)`` costs one simulator step per step, and the
episodes a game goes through are the same as those of :func:`pes.make_env` with the same seed.
Stepping a finished game without resetting it, which TorchRL does not do, continues its next
episode. ``env.set_seed(s)`` re-seeds every game (game i with seed ``s + i``, as the simulator)
and the next ``reset()`` returns those first observations.

Arguments: ``config`` (an :class:`pes.EnvConfig`, a dict of its keys, or None), ``num_envs``,
``device`` (``"cpu"`` or ``"cuda"``), ``seed``, ``sim_compile`` (:func:`pes.make_env`'s
``compile``: the simulator's step and auto-reset fused by ``torch.compile``) and
``check_actions`` (:func:`pes.make_env`'s, as it is). The evader runs its configured policy
inside the simulator (``evader_policy="external"`` is refused). The simulator's option is not called
``compile`` here because TorchRL's ``EnvBase`` takes that keyword itself (torchrl >= 0.12:
``compile=True`` compiles TorchRL's own ``step_and_maybe_reset`` around this environment).
"""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor

try:
    from tensordict import TensorDict, TensorDictBase
    from torchrl.data import Bounded, Categorical, Composite, Unbounded
    from torchrl.envs import EnvBase
except ImportError as exc:  # pragma: no cover - depends on the optional extra
    raise ImportError(
        "pes.torchrl needs TorchRL: pip install 'pes[torchrl]' (torchrl>=0.11)"
    ) from exc

from pes.errors import ConfigError
from pes.sim import scenario
from pes.sim.config import EnvConfig
from pes.sim.env import PursuitEvasionEnv, make_env, resolve_device
from pes.sim.scenario import OBS_FEATURES

GROUP = "pursuers"
"""Name of the agent group of the pursuers."""


def flatten_observation(obs: Tensor, obs_mask: Tensor) -> Tensor:
    """Each pursuer's Table I rows flattened, followed by its row mask as 0/1.

    Args:
        obs: (E, N, N, 8) as returned by :meth:`PursuitEvasionEnv.step`.
        obs_mask: (E, N, N) bool.

    Returns:
        (E, N, 9N) float32: ``[rows.flatten(), mask]``. The mask bits tell a zero row of a
        masked pursuer from real zeros.
    """
    return torch.cat([obs.flatten(-2), obs_mask.to(obs.dtype)], dim=-1)


class PESTorchRLEnv(EnvBase):
    """``num_envs`` pursuit-evasion games as one batched TorchRL environment; see the module
    docstring for the keys, the shapes and how resets work."""

    def __init__(
        self,
        config: EnvConfig | dict[str, Any] | None = None,
        num_envs: int = 1,
        device: str | torch.device = "cpu",
        seed: int | None = None,
        *,
        sim_compile: bool = False,
        check_actions: bool = True,
    ) -> None:
        sim = make_env(
            config,
            num_envs,
            device,
            seed,
            compile=sim_compile,
            check_actions=check_actions,
            wait_kernels=True,  # every step of a training on the same path
        )
        if sim.config.evader_policy == "external":
            raise ConfigError(
                "PESTorchRLEnv has one agent group, the pursuers: evader_policy='external' is "
                "not supported here (choose flee, random or ddpg)"
            )
        super().__init__(device=sim.device, batch_size=torch.Size([num_envs]))
        self._sim_seed, self._sim_compile = seed, sim_compile
        self.sim: PursuitEvasionEnv = sim
        """The batched simulator underneath (its ``state``, ``positions``, ``layout``...)."""
        self.config = sim.config
        self.group_map = {GROUP: sim.agents}
        """TorchRL's multi-agent convention: group name -> agent names."""
        # The simulator's observation of its current state, for every game, and which games
        # it reset by itself in the last step (see "Auto-reset" in the module docstring).
        self._views: dict[str, Tensor] | None = None
        self._auto_reset = torch.zeros(num_envs, dtype=torch.bool, device=sim.device)
        self._make_specs()

    # --- facts ------------------------------------------------------------------------------
    @property
    def num_envs(self) -> int:
        return self.sim.num_envs

    @property
    def num_pursuers(self) -> int:
        return self.sim.num_pursuers

    @property
    def observation_size(self) -> int:
        """Length of one pursuer's observation vector, 9N."""
        n = self.num_pursuers
        return n * OBS_FEATURES + n

    def _make_specs(self) -> None:
        n, e, dev = self.num_pursuers, self.num_envs, self.device
        group_obs = Composite(
            observation=Unbounded((e, n, self.observation_size), device=dev),
            obs_mask=Categorical(2, (e, n, n), dtype=torch.bool, device=dev),
            mask=Categorical(2, (e, n), dtype=torch.bool, device=dev),
            info=Composite(
                crashed=Unbounded((e, n, 1), device=dev),
                distance=Unbounded((e, n, 1), device=dev),
                shape=(e, n),
                device=dev,
            ),
            shape=(e, n),
            device=dev,
        )
        self.observation_spec = Composite(
            {
                GROUP: group_obs,
                "state": Unbounded((e, (n + 1) * OBS_FEATURES), device=dev),
                "success": Categorical(2, (e, 1), dtype=torch.bool, device=dev),
            },
            shape=(e,),
            device=dev,
        )
        self.action_spec = Composite(
            {
                GROUP: Composite(
                    action=Bounded(-1.0, 1.0, (e, n, 2), device=dev), shape=(e, n), device=dev
                )
            },
            shape=(e,),
            device=dev,
        )
        self.reward_spec = Composite(
            {GROUP: Composite(reward=Unbounded((e, n, 1), device=dev), shape=(e, n), device=dev)},
            shape=(e,),
            device=dev,
        )
        self.done_spec = Composite(
            {
                key: Categorical(2, (e, 1), dtype=torch.bool, device=dev)
                for key in ("done", "terminated", "truncated")
            },
            shape=(e,),
            device=dev,
        )

    # --- EnvBase ------------------------------------------------------------------------------
    def _set_seed(self, seed: int | None) -> None:
        self._sim_seed = seed
        obs, info = self.sim.reset(seed=seed)
        self._remember(obs, info)
        # The seeded first episodes are handed out by the next reset().
        self._auto_reset = torch.ones_like(self._auto_reset)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        if self._views is None or self.sim.state is None:
            obs, info = self.sim.reset()
            self._remember(obs, info)
        else:
            wanted = torch.ones_like(self._auto_reset)
            if tensordict is not None and "_reset" in tensordict:
                wanted = tensordict.get("_reset").reshape(self.num_envs).to(self.device)
            todo = wanted & ~self._auto_reset
            if bool(todo.all()):
                obs, info = self.sim.reset()
                self._remember(obs, info)
            elif bool(todo.any()):
                self._reset_some(todo)
        # Reassigned, never written in place: a step's "done" may share memory with it.
        self._auto_reset = torch.zeros_like(self._auto_reset)
        views = self._views
        zeros = torch.zeros(self.num_envs, 1, dtype=torch.bool, device=self.device)
        positions = self.sim.positions
        n = self.num_pursuers
        distance = (positions[:, :n] - positions[:, n:]).norm(dim=-1)
        group = self._group(
            views["obs"],
            views["obs_mask"],
            self.sim.alive.clone(),  # a view of the state, which resets rewrite in place
            crashed=torch.zeros_like(distance),
            distance=distance,
        )
        return TensorDict(
            {
                GROUP: group,
                "state": views["state"].flatten(1),
                "success": zeros,
                "done": zeros.clone(),
                "terminated": zeros.clone(),
                "truncated": zeros.clone(),
            },
            batch_size=self.batch_size,
            device=self.device,
        )

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        actions = tensordict.get((GROUP, "action"))
        obs, reward, terminated, truncated, info = self.sim.step(actions)
        self._remember(obs, info)
        done = terminated | truncated
        self._auto_reset = done.clone()
        group = self._group(
            info["final_obs"],
            info["final_obs_mask"],
            info["alive"],
            crashed=info["crashed"].to(reward.dtype),
            distance=info["distances"],
            reward=reward,
        )
        return TensorDict(
            {
                GROUP: group,
                "state": info["final_state"].flatten(1),
                "success": info["success"].unsqueeze(-1),
                "done": done.unsqueeze(-1),
                "terminated": terminated.unsqueeze(-1),
                "truncated": truncated.unsqueeze(-1),
            },
            batch_size=self.batch_size,
            device=self.device,
        )

    # --- helpers -------------------------------------------------------------------------------
    def _group(
        self,
        obs: Tensor,
        obs_mask: Tensor,
        alive: Tensor,
        *,
        crashed: Tensor,
        distance: Tensor,
        reward: Tensor | None = None,
    ) -> TensorDict:
        """The ``"pursuers"`` sub-tensordict, batch (E, N)."""
        fields: dict[str, Any] = {
            "observation": flatten_observation(obs, obs_mask),
            "obs_mask": obs_mask,
            "mask": alive,
            "info": TensorDict(
                {"crashed": crashed.unsqueeze(-1), "distance": distance.unsqueeze(-1)},
                batch_size=alive.shape,
                device=self.device,
            ),
        }
        if reward is not None:
            fields["reward"] = reward.unsqueeze(-1)
        return TensorDict(fields, batch_size=alive.shape, device=self.device)

    def _remember(self, obs: Tensor, info: dict[str, Tensor]) -> None:
        """Keep the simulator's observation of its current state (after any auto-reset)."""
        self._views = {
            "obs": obs,
            "obs_mask": info["obs_mask"],
            "state": info["state"],
            "evader_obs": info["evader_obs"],
        }

    def _reset_some(self, todo: Tensor) -> None:
        """Start the next episode of the games ``todo`` (E,) bool, in place, leaving the others
        untouched: the simulator's own masked reset pass, in as many passes as it needs."""
        # Copies: the tensors handed out by earlier steps must not change under the caller.
        views = {k: v.clone() for k, v in self._views.items()}
        state = self.sim.state
        pending = todo
        while bool(pending.any()):
            pending = scenario.reset_pass(
                self.sim.scenario, state, views, pending, self.sim.reset_capacity
            )
        self._views = views

    def to(self, device: str | torch.device) -> PESTorchRLEnv:
        """Move the environment, the simulator's state included, to ``device``."""
        device = resolve_device(device)
        if device != self.sim.device:
            old = self.sim
            self.sim = make_env(
                self.config,
                self.num_envs,
                device,
                self._sim_seed,
                compile=self._sim_compile,
                check_actions=old.check_actions,
                wait_kernels=True,
            )
            if old.state is not None:
                self.sim.set_state(old.state)
            if self._views is not None:
                self._views = {k: v.to(device) for k, v in self._views.items()}
            self._auto_reset = self._auto_reset.to(device)
        return super().to(device)

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(num_envs={self.num_envs}, num_pursuers={self.num_pursuers}, "
            f"device={self.device})"
        )


class TorchRLPolicy:
    """A TorchRL policy of the ``"pursuers"`` group as a :class:`pes.policies.Policy`, so that
    :func:`pes.evaluate.evaluate` (and ``pes eval``) measure it with PES's own protocol.

    ``module`` is a ``TensorDictModule`` (or sequence) that reads ``("pursuers",
    "observation")`` (E, N, 9N) -- as :class:`PESTorchRLEnv` gives it -- and writes
    ``("pursuers", "action")`` (E, N, 2). It runs in TorchRL's deterministic exploration mode
    (the mean or mode of a stochastic policy, no exploration noise); actions are clipped to
    [-1, 1]. The module runs on the device of its parameters (the CPU if it has none); the
    observations go there and the actions come back to theirs. Recurrent policies, whose
    hidden state the tensordict would carry between steps, are not supported: a module that
    reads keys other than the observation and the alive mask is a one-line error.
    """

    row_wise = True  # see pes.policies.Policy

    READS = {(GROUP, "observation"), (GROUP, "mask"), (GROUP, "obs_mask"), ("state",)}
    """The keys the adapter fills: the observation, the alive and row masks, the global state."""

    def __init__(self, module: Any) -> None:
        keys = [k if isinstance(k, tuple) else (k,) for k in module.in_keys]
        extra = [k for k in keys if k not in self.READS]
        if extra:
            raise ConfigError(
                f"this TorchRL policy reads {extra}: only stateless policies of "
                f"({GROUP!r}, 'observation') can be evaluated"
            )
        self.module = module
        params = next(iter(module.parameters()), None) if hasattr(module, "parameters") else None
        self.device = params.device if params is not None else torch.device("cpu")

    def tensordict(self, obs: Tensor, info: dict[str, Tensor]) -> TensorDict:
        """The module's input for the simulator's ``obs`` (E, N, N, 8) and ``info``, on the
        module's device: what :class:`PESTorchRLEnv` gives a policy (the keys of ``READS``)."""
        alive = info["obs_mask"][:, :, 0]
        group = TensorDict(
            {
                "observation": flatten_observation(obs, info["obs_mask"]),
                "obs_mask": info["obs_mask"],
                "mask": alive,
            },
            batch_size=alive.shape,
        )
        td = TensorDict(
            {GROUP: group, "state": info["state"].flatten(1)}, batch_size=alive.shape[:1]
        )
        return td if obs.device == self.device else td.to(self.device)

    def __call__(self, obs: Tensor, info: dict[str, Tensor]) -> Tensor:
        from torchrl.envs.utils import ExplorationType, set_exploration_type

        with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
            out = self.module(self.tensordict(obs, info))
        return out.get((GROUP, "action")).to(obs.device).clamp(-1.0, 1.0)

    def reset(self, mask: Tensor | None = None) -> None:
        """Stateless between steps."""
