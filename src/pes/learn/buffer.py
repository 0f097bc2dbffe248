"""Replay storage shared by the off-policy learners, and the on-policy rollout (PPO).

:class:`ReplayBuffer` is a ring of ``rows`` time steps of ``num_envs`` environments (time-major,
each field shaped (rows, num_envs, ...)), filled by batched collection one vector step at a
time. Because each environment's transitions stay in order down its column, a transition's
past (TP Net's n-step history) and future (the k positions TP Net must predict) are found by
stepping along the column, guarded by the episode step counter: replay buffer R and trajectory
buffer T of Algorithm 1 are two ways of sampling the same storage, and the global state is
stored once per transition.
"""

from __future__ import annotations

import torch
from torch import Tensor

from pes.errors import ConfigError

FieldSpec = dict[str, tuple[tuple[int, ...], torch.dtype]]


def transition_fields(num_pursuers: int) -> FieldSpec:
    """The fields of one multi-agent transition of ``n = num_pursuers``: the global state
    (n + 1 agents x 8, the evader last) before and after, who is alive before and after, the
    pursuers' actions (n, 2), their rewards (n,) and whether the episode terminated."""
    n = num_pursuers
    return {
        "state": ((n + 1, 8), torch.float32),
        "alive": ((n,), torch.bool),
        "action": ((n, 2), torch.float32),
        "reward": ((n,), torch.float32),
        "next_state": ((n + 1, 8), torch.float32),
        "next_alive": ((n,), torch.bool),
        "terminated": ((), torch.bool),
    }


def transition(
    before: dict[str, Tensor],
    actions: Tensor,
    reward: Tensor,
    terminated: Tensor,
    after: dict[str, Tensor],
) -> dict[str, Tensor]:
    """The :func:`transition_fields` (and ``ep_step``) of one vector step, from the env infos
    ``before`` and ``after`` ``env.step`` (``after``'s ``final_*`` entries: the state that ended
    an episode, not the reset that followed), actions (E, n, 2), reward (E, n), terminated (E,)."""
    return {
        "state": before["state"],
        "alive": before["obs_mask"][:, :, 0],
        "action": actions,
        "reward": reward,
        "next_state": after["final_state"],
        "next_alive": after["final_obs_mask"][:, :, 0],
        "terminated": terminated,
        "ep_step": (after["steps"] - 1).to(torch.int32),
    }


class ReplayBuffer:
    """Time-major ring buffer of transitions from ``num_envs`` environments.

    Args:
        capacity: transitions kept (rounded down to a multiple of ``num_envs``).
        num_envs: environments written per :meth:`add`.
        fields: name -> (per-transition shape, dtype). ``ep_step`` (int32, the step of the
            episode at which the transition starts) is always added.
        device: where the storage lives.
    """

    def __init__(
        self, capacity: int, num_envs: int, fields: FieldSpec, device: torch.device | str = "cpu"
    ) -> None:
        self.rows = capacity // num_envs
        if self.rows < 2:
            raise ConfigError(
                f"buffer capacity {capacity} holds fewer than 2 steps of {num_envs} environments"
            )
        self.num_envs = num_envs
        self.device = torch.device(device)
        spec = dict(fields)
        spec["ep_step"] = ((), torch.int32)
        self.data = {
            name: torch.zeros((self.rows, num_envs, *shape), dtype=dtype, device=self.device)
            for name, (shape, dtype) in spec.items()
        }
        self.next_row = 0
        """Row that the next :meth:`add` writes."""
        self.filled = 0
        """Rows holding data (at most ``rows``)."""

    @property
    def capacity(self) -> int:
        return self.rows * self.num_envs

    def __len__(self) -> int:
        return self.filled * self.num_envs

    @property
    def bytes_per_transition(self) -> int:
        """Bytes of storage per stored transition (all fields)."""
        total = sum(t.element_size() * t[0, 0].numel() for t in self.data.values())
        return int(total)

    def add(self, **values: Tensor) -> None:
        """Write one vector step: every field shaped (num_envs, ...)."""
        for name, store in self.data.items():
            store[self.next_row] = values[name]
        self.next_row = (self.next_row + 1) % self.rows
        self.filled = min(self.filled + 1, self.rows)

    def sample_index(self, batch: int, generator: torch.Generator, past: int = 0, future: int = 0):
        """Random (row, env) indices of transitions whose ``past`` earlier and ``future`` later
        rows are still stored. Returns two (batch,) long tensors."""
        usable = self.filled - past - future
        if usable < 1:
            raise ValueError("not enough data in the buffer to sample")
        age = torch.randint(future, future + usable, (batch,), generator=generator)
        row = (self.next_row - 1 - age) % self.rows
        env = torch.randint(0, self.num_envs, (batch,), generator=generator)
        return row.to(self.device), env.to(self.device)

    def get(self, name: str, row: Tensor, env: Tensor, offset: int = 0) -> Tensor:
        """Field ``name`` at (row + offset, env) for each index."""
        return self.data[name][(row + offset) % self.rows, env]

    def window(
        self, name: str, row: Tensor, env: Tensor, length: int, last: Tensor | None = None
    ) -> Tensor:
        """The last ``length`` values of field ``name`` in each sampled transition's episode,
        oldest first, ending at the transition itself -- or, with ``last`` (B, ...), ending with
        ``last`` after the transition (the window of the next state). Steps before the episode's
        start are zero, like the environment's zero-padded history.

        Returns (B, length, ...).
        """
        ep_step = self.data["ep_step"][row, env]
        shift = 0 if last is None else 1
        parts = []
        for back in range(length - 1 - shift, -1, -1):
            value = self.get(name, row, env, -back)
            keep = (ep_step >= back).view(-1, *([1] * (value.dim() - 1)))
            parts.append(value * keep.to(value.dtype))
        if last is not None:
            parts.append(last)
        return torch.stack(parts, dim=1)

    def same_episode_ahead(self, row: Tensor, env: Tensor, steps: int) -> Tensor:
        """(B,) bool: the next ``steps`` stored transitions of each index belong to its
        episode (so its future positions can serve as TP Net targets)."""
        ep_step = self.data["ep_step"][row, env]
        ok = torch.ones_like(ep_step, dtype=torch.bool)
        for ahead in range(1, steps + 1):
            ok &= self.get("ep_step", row, env, ahead) == ep_step + ahead
        return ok

    def n_step(
        self, row: Tensor, env: Tensor, steps: int, gamma: float
    ) -> tuple[Tensor, Tensor, Tensor]:
        """The windows of n-step TD targets (n-step returns, as D4PG and DDPGfD use) of
        sampled multi-agent transitions (:func:`transition_fields`).

        From each transition at (row, env) the window runs on down the environment's column
        for at most ``steps`` transitions, while the episode goes on and every pursuer stays in
        the game: it ends with the transition that terminates the episode, that is the last
        of it stored (a truncation), or at which a pursuer leaves (``alive`` differs from
        ``next_alive``). The ``steps - 1`` rows after each index must be stored (sample with
        ``future=steps - 1``); ``steps=1`` gives the transition itself.

        Returns the window's discounted reward sum ``sum_j gamma^j r_{t+j}`` (B, N), the row
        of its last transition, whose next state the target bootstraps from (B,), and its
        length m, 1 to ``steps`` (B,).
        """
        data = self.data
        first_step = data["ep_step"][row, env]
        ret = data["reward"][row, env]
        last, length = row, torch.ones_like(row)
        going = torch.ones_like(row, dtype=torch.bool)
        for ahead in range(1, steps):
            stays = (data["alive"][last, env] == data["next_alive"][last, env]).all(-1)
            going = going & ~data["terminated"][last, env] & stays
            nxt = (row + ahead) % self.rows
            going = going & (data["ep_step"][nxt, env] == first_step + ahead)
            ret = ret + (gamma**ahead) * going.unsqueeze(-1) * data["reward"][nxt, env]
            last = torch.where(going, nxt, last)
            length = length + going.long()
        return ret, last, length

    # --- checkpoints ---------------------------------------------------------------------------
    def state_dict(self) -> dict:
        # a copy in host memory, whatever the buffer's device
        data = {k: v[: self.filled].to("cpu", copy=True) for k, v in self.data.items()}
        return {
            "rows": self.rows,
            "num_envs": self.num_envs,
            "next_row": self.next_row,
            "filled": self.filled,
            "data": data,
        }

    def load_state_dict(self, state: dict) -> None:
        if state["rows"] != self.rows or state["num_envs"] != self.num_envs:
            raise ValueError(
                f"buffer of {state['rows']}x{state['num_envs']} rows cannot be loaded into one of "
                f"{self.rows}x{self.num_envs}"
            )
        for k, v in state["data"].items():
            self.data[k][: v.shape[0]] = v.to(self.device)
        self.next_row = int(state["next_row"])
        self.filled = int(state["filled"])


class RolloutBuffer:
    """On-policy storage of one rollout: ``steps`` vector steps of ``num_envs`` environments,
    time-major (each field shaped (steps, num_envs, ...)), filled by :meth:`add` and emptied by
    :meth:`clear` after the update that consumes it.

    A rollout in progress is not checkpointed (:meth:`state_dict` holds only the sizes): a
    resumed run starts a new rollout, as its environments start new episodes.

    Args:
        steps: vector steps per rollout.
        num_envs: environments written per :meth:`add`.
        fields: name -> (per-step shape, dtype).
        device: where the storage lives.
    """

    def __init__(
        self, steps: int, num_envs: int, fields: FieldSpec, device: torch.device | str = "cpu"
    ) -> None:
        if steps < 1:
            raise ConfigError(f"a rollout needs at least 1 step, got {steps}")
        self.steps = steps
        self.num_envs = num_envs
        self.device = torch.device(device)
        self.data = {
            name: torch.zeros((steps, num_envs, *shape), dtype=dtype, device=self.device)
            for name, (shape, dtype) in fields.items()
        }
        self.filled = 0
        """Vector steps stored so far."""

    def __len__(self) -> int:
        return self.filled * self.num_envs

    @property
    def full(self) -> bool:
        return self.filled == self.steps

    def add(self, **values: Tensor) -> None:
        """Write one vector step: every field shaped (num_envs, ...)."""
        if self.full:
            raise RuntimeError("the rollout is full: update and clear() it first")
        for name, store in self.data.items():
            store[self.filled] = values[name]
        self.filled += 1

    def clear(self) -> None:
        self.filled = 0

    def state_dict(self) -> dict:
        """The sizes and the rollout collected so far (a copy in host memory)."""
        data = {k: v[: self.filled].to("cpu", copy=True) for k, v in self.data.items()}
        return {"steps": self.steps, "num_envs": self.num_envs, "filled": self.filled, "data": data}

    def load_state_dict(self, state: dict) -> None:
        """Check the sizes and restore the rollout collected so far."""
        if state["steps"] != self.steps or state["num_envs"] != self.num_envs:
            raise ValueError(
                f"rollout of {state['steps']}x{state['num_envs']} steps cannot be loaded into one "
                f"of {self.steps}x{self.num_envs}"
            )
        self.filled = state["filled"]
        for k, v in state["data"].items():
            self.data[k][: self.filled] = v.to(self.data[k].device)


def gae(
    reward: Tensor,
    value: Tensor,
    next_nonterminal: Tensor,
    last_value: Tensor,
    gamma: float,
    lam: float,
) -> tuple[Tensor, Tensor]:
    """Generalised advantage estimation (Schulman et al., 2016) over a time-major rollout.

    Args:
        reward: (T, ...) rewards (a truncated episode's last reward already holds
            ``gamma * V(final state)``).
        value: (T, ...) V(s_t) as estimated while acting.
        next_nonterminal: (T, ...) 1 where s_{t+1} continues the same agent's episode, 0 where
            the episode ended (or the agent died) at step t.
        last_value: (...) V of the state after the rollout's last step.
        gamma: discount; lam: the GAE lambda.

    Returns:
        advantages (T, ...) and returns ``advantages + value`` (the value targets).
    """
    adv = torch.zeros_like(reward)
    running = torch.zeros_like(last_value)
    next_value = last_value
    for t in range(reward.shape[0] - 1, -1, -1):
        keep = next_nonterminal[t]
        delta = reward[t] + gamma * keep * next_value - value[t]
        running = delta + gamma * lam * keep * running
        adv[t] = running
        next_value = value[t]
    return adv, adv + value
