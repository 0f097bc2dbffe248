"""PPO baseline (Table IV): proximal policy optimisation (Schulman et al., 2017) with GAE,
on-policy, collected from ``num_envs`` environments at once, with the implementation details
of CleanRL's continuous PPO (Huang et al., 2022) as settings; MAPPO (:mod:`pes.algos.mappo`)
is this learner with a centralised value.

Each pursuer acts on its own Table I observation: a Gaussian actor with a state-independent
log std on the flattened observation. Its value is V(o_i) (``central_value=False``: the
paper's independent PPO, IPPO) or V(o_i, s) on its observation and the global state, the
evader's velocity included (``central_value=True``: MAPPO's agent-specific global state).
With ``shared=True`` (the default) all pursuers share one actor and one value network, and
every pursuer's samples train them (parameter sharing); ``shared=False`` gives each pursuer
its own pair.

One update (``update()``, once per full rollout of ``rollout_steps`` vector steps):

1. advantages by GAE (gamma, ``gae_lambda``) per pursuer, cut where the episode ends or the
   pursuer dies; a truncated episode bootstraps from V of its final observation;
2. with ``value_norm``, the value network predicts returns standardised by their running mean
   and variance (MAPPO's ValueNorm), which this rollout's returns update first;
3. ``ppo_epochs`` passes over the rollout in minibatches of ``batch_size`` transitions (each
   with its N pursuer samples): the clipped surrogate (``clip_coef``) with per-minibatch
   normalised advantages, minus ``ent_coef`` times the entropy, and the value loss (squared
   error, or Huber with ``huber_delta``) against the GAE returns; optional early stop at
   ``target_kl``;
4. with ``obs_norm``, the running mean and variance of the networks' inputs take in this
   rollout's (after the update, so that a rollout is scored with the statistics it was
   collected with); with ``anneal_lr``, the learning rates fall linearly to 0 over the run's
   ``env_steps``.

Actions are sampled from N(mean, exp(log_std)) and clipped to [-1, 1] for the environment
(the log-probabilities are those of the unclipped samples, as CleanRL's). Evaluation acts with
the clipped mean. Dead pursuers (``crash_mode="disable"``) are zero rows with a 0 flag in
everyone's input, and their samples are left out of every loss.

Demonstrations (the protocol's ``demonstrations``): the scripted demonstrator plays the run's
first ``transitions`` transitions, as for the replay learners; an on-policy update cannot learn
from them, so they are a behaviour-cloning warm start instead: ``bc_epochs`` passes of the
actor's mean toward the demonstrator's actions and of the value toward the demonstrations'
returns, once, before the first rollout of its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor, nn

from pes.errors import ConfigError
from pes.learn.buffer import RolloutBuffer, gae
from pes.learn.common import ActorPolicy, adam, gaussian_log_prob, masked_mean, optimise
from pes.learn.config import LearnerConfig, TrainConfig
from pes.learn.features import pursuer_obs
from pes.learn.learner import Learner
from pes.learn.nets import PerAgent, RowScaled, Tanh
from pes.learn.presets import QUICK_RUN, TINY_PROTOCOL, TINY_RUN, gpu_preset
from pes.learn.td import exit_charge
from pes.policies import SCRIPTED
from pes.sim.config import EnvConfig


@dataclass
class PPOConfig(LearnerConfig):
    """PPO's settings: gamma and the minibatch from the paper (§V-A), the rest from the PPO
    paper (Schulman et al., 2017, MuJoCo settings) and CleanRL's implementation, as the paper
    gives none for its baselines (docs/algorithms/ppo.md compares them)."""

    gamma: float = 0.95
    """Discount factor."""
    lr_actor: float = 3e-4
    """Adam learning rate of the actor."""
    lr_critic: float = 3e-4
    """Adam learning rate of the value function."""
    hidden: int = 64
    """Units of each of the two hidden layers of the actor's and the value function's MLPs."""
    shared: bool = True
    """One actor and one value function for all pursuers (False: one pair per pursuer)."""
    central_value: bool = False
    """The value reads the global state beside the pursuer's observation (MAPPO)."""
    obstacle_scale: float = 20.0
    """Factor on the obstacle-vector columns of the observation rows (``RowScaled``)."""
    target_scale: float = 5.0
    """Factor on the vector to the evader in the observation rows."""
    rollout_steps: int = 2048
    """Vector steps per rollout (a rollout holds ``rollout_steps * num_envs`` transitions, each
    with N pursuer samples)."""
    ppo_epochs: int = 10
    """Passes over each rollout."""
    batch_size: int = 512
    """Minibatch in transitions."""
    gae_lambda: float = 0.95
    """Lambda of generalised advantage estimation."""
    clip_coef: float = 0.2
    """Clipping range of the probability ratio."""
    ent_coef: float = 0.0
    """Weight of the entropy bonus in the actor loss."""
    target_kl: float = 0.0
    """Stop a rollout's epochs once the approximate KL exceeds this (0 = never)."""
    log_std_init: float = -0.5
    """Initial log standard deviation of the Gaussian policy (in action units)."""
    grad_clip: float = 1.0
    """Gradient norm clip (0 = none)."""
    value_norm: bool = False
    """Standardise the value targets by the returns' running mean and variance."""
    huber_delta: float = 0.0
    """The value loss: the squared error (0), or the Huber loss that turns linear at this
    distance (in the value's units: standardised returns with ``value_norm``)."""
    obs_norm: bool = False
    """Standardise the networks' inputs by their running mean and variance."""
    anneal_lr: bool = False
    """Learning rates fall linearly to 0 over the run's ``env_steps``."""
    bc_epochs: int = 10
    """Passes of the behaviour-cloning warm start over the demonstrations (when the protocol
    has them)."""

    POSITIVE: ClassVar[tuple[str, ...]] = (
        "lr_actor",
        "lr_critic",
        "hidden",
        "rollout_steps",
        "ppo_epochs",
        "batch_size",
    )
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = (
        "obstacle_scale",
        "target_scale",
        "ent_coef",
        "target_kl",
        "grad_clip",
        "bc_epochs",
        "huber_delta",
    )

    def check(self) -> None:
        for name in ("gae_lambda", "clip_coef"):
            if not 0.0 < getattr(self, name) <= 1.0:
                raise ConfigError(f"ppo: {name} must be in (0, 1], got {getattr(self, name)}")


PPO_TUNED: dict[str, Any] = dict(lr_actor=6.12e-4, lr_critic=7.8e-4, ent_coef=1e-3, hidden=128)
"""The best of PPO's search (results/tuning/ppo, trial t03: 0.0 % of the held-out episodes after
1,000,000 env steps, the best mean reward); the search began at lr_actor 3e-4, lr_critic 1e-3,
ent_coef 0, hidden 64."""

STANDARD: dict[str, Any] = dict(value_norm=True, obs_norm=True, anneal_lr=True)
"""The implementation details of CleanRL's PPO and Yu et al.'s MAPPO that the quick presets
of both on-policy learners turn on: standardised value targets and inputs, and annealed
learning rates."""

PPO_PRESETS: dict[str, dict[str, Any]] = {
    "paper": dict(episodes=4000, num_envs=1, env=dict(evader_policy="ddpg")),
    # 64 environments x 64 steps per rollout, 4 minibatches, 10 epochs
    "quick": dict(
        QUICK_RUN,
        num_envs=64,
        lr_actor=3e-4,
        lr_critic=1e-3,
        rollout_steps=64,
        batch_size=1024,
    )
    | PPO_TUNED
    | STANDARD,
    "tiny": dict(
        TINY_RUN,
        hidden=32,
        rollout_steps=16,
        batch_size=32,
        ppo_epochs=4,
        bc_epochs=2,
        protocol=TINY_PROTOCOL,
    )
    | STANDARD,
}
PPO_PRESETS["gpu"] = gpu_preset(PPO_PRESETS["quick"])


class RunningNorm(nn.Module):
    """Running mean and variance of ``dim`` features (Chan et al.'s parallel update over
    every batch given to :meth:`update`); ``forward`` standardises and clips to ±``clip``,
    ``denormalise`` undoes it. Before any update it is the identity. Its statistics are
    buffers: they travel with the weights."""

    def __init__(self, dim: int, clip: float = 10.0) -> None:
        super().__init__()
        self.clip = clip
        self.register_buffer("mean", torch.zeros(dim))
        self.register_buffer("var", torch.ones(dim))
        self.register_buffer("count", torch.zeros(()))

    @torch.no_grad()
    def update(self, x: Tensor) -> None:
        """Take in the rows of ``x`` (..., dim)."""
        x = x.reshape(-1, self.mean.shape[0]).double()
        if x.shape[0] == 0:
            return
        n, mean, var = x.shape[0], x.mean(0), x.var(0, unbiased=False)
        total = self.count + n
        delta = mean - self.mean
        if self.count == 0:
            new_mean, new_var = mean, var
        else:
            new_mean = self.mean + delta * n / total
            m2 = self.var * self.count + var * n + delta**2 * self.count * n / total
            new_var = m2 / total
        self.mean.copy_(new_mean)
        self.var.copy_(new_var)
        self.count.copy_(total)

    def forward(self, x: Tensor) -> Tensor:
        if self.count == 0:
            return x
        return ((x - self.mean) / (self.var + 1e-8).sqrt()).clamp(-self.clip, self.clip)

    def denormalise(self, x: Tensor) -> Tensor:
        if self.count == 0:
            return x
        return x * (self.var + 1e-8).sqrt() + self.mean


def orthogonal_mlp(sizes: list[int], out_gain: float) -> nn.Sequential:
    """Linear layers with tanh between them, orthogonally initialised (gain sqrt(2), the last
    ``out_gain``) with zero biases, as CleanRL's PPO."""
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layer = nn.Linear(sizes[i], sizes[i + 1])
        last = i == len(sizes) - 2
        nn.init.orthogonal_(layer.weight, out_gain if last else math.sqrt(2))
        nn.init.zeros_(layer.bias)
        layers.append(layer)
        if not last:
            layers.append(Tanh())
    return nn.Sequential(*layers)


class FlatInput(RowScaled):
    """One pursuer's network input: its N Table I rows scaled as :class:`RowScaled`, each with
    its real-row flag (9N numbers), and with ``central`` the global state's N + 1 rows (scaled
    alike: the evader's velocity included) and the N alive flags after them; standardised by a
    :class:`RunningNorm` (the identity until :meth:`update`)."""

    def __init__(self, lc: PPOConfig, num_pursuers: int, central: bool) -> None:
        super().__init__(0, lc.obstacle_scale, lc.target_scale)
        self.central = central
        n = num_pursuers
        self.dim = 9 * n + (8 * (n + 1) + n if central else 0)
        self.norm = RunningNorm(self.dim)

    def features(self, obs: Tensor, mask: Tensor, state: Tensor | None = None) -> Tensor:
        """obs (B, N, 8), mask (B, N), state (B, N + 1, 8) -> (B, dim), not standardised."""
        x = torch.cat([obs * self.scale, mask.unsqueeze(-1).to(obs.dtype)], dim=-1).flatten(-2)
        if self.central:
            alive = (state[..., :-1, :].abs().sum(-1) > 0).to(obs.dtype)
            x = torch.cat([x, (state * self.scale).flatten(-2), alive], dim=-1)
        return x

    def forward(self, obs: Tensor, mask: Tensor, state: Tensor | None = None) -> Tensor:
        return self.norm(self.features(obs, mask, state))


class GaussianActor(nn.Module):
    """A diagonal Gaussian policy: mean from a tanh MLP on one pursuer's observation, log std a
    free parameter (independent of the state)."""

    def __init__(self, lc: PPOConfig, num_pursuers: int) -> None:
        super().__init__()
        self.input = FlatInput(lc, num_pursuers, central=False)
        self.mean = orthogonal_mlp([self.input.dim, lc.hidden, lc.hidden, 2], 0.01)
        self.log_std = nn.Parameter(torch.full((2,), lc.log_std_init))

    def forward(self, obs: Tensor, mask: Tensor) -> Tensor:
        """obs (B, N, 8), mask (B, N) -> (B, 4): mean (2) and log std (2)."""
        mean = self.mean(self.input(obs, mask))
        return torch.cat([mean, self.log_std.expand_as(mean)], dim=-1)


class ValueNet(nn.Module):
    """V(o_i) or, with ``central_value``, V(o_i, s): a tanh MLP on :class:`FlatInput`."""

    def __init__(self, lc: PPOConfig, num_pursuers: int) -> None:
        super().__init__()
        self.input = FlatInput(lc, num_pursuers, central=lc.central_value)
        self.body = orthogonal_mlp([self.input.dim, lc.hidden, lc.hidden, 1], 1.0)

    def forward(self, obs: Tensor, mask: Tensor, state: Tensor) -> Tensor:
        """obs (B, N, 8), mask (B, N), state (B, N + 1, 8) -> (B, 1)."""
        return self.body(self.input(obs, mask, state))


class PPOActors(nn.Module):
    """The pursuers' Gaussian actors (shared or one each), on observations (B, N, N, 8)."""

    def __init__(self, lc: PPOConfig, num_pursuers: int) -> None:
        super().__init__()
        self.nets = PerAgent(lambda: GaussianActor(lc, num_pursuers), num_pursuers, lc.shared)

    def forward(self, obs: Tensor, mask: Tensor) -> tuple[Tensor, Tensor]:
        """obs (B, N, N, 8), mask (B, N, N) -> mean and log std, each (B, N, 2)."""
        out = self.nets(obs, mask)
        return out[..., :2], out[..., 2:]

    def mean_action(self, obs: Tensor, mask: Tensor) -> Tensor:
        """(B, N, 2) deterministic actions: the mean, clipped to [-1, 1]."""
        return self(obs, mask)[0].clamp(-1.0, 1.0)


class PPO(Learner):
    """The PPO learner (independent learners, parameter-shared by default)."""

    name = "ppo"
    Config = PPOConfig
    PRESETS = PPO_PRESETS
    TUNE_SPACE: ClassVar[dict[str, tuple]] = {
        "lr_actor": ("log", 1e-4, 1e-3),
        "lr_critic": ("log", 3e-4, 3e-3),
        "ent_coef": ("choice", [0.0, 1e-3, 1e-2]),
        "hidden": ("choice", [64, 128, 256]),
        "gamma": ("choice", [0.95, 0.98, 0.99]),
        "rollout_steps": ("choice", [32, 64, 128]),
        "ppo_epochs": ("choice", [4, 10]),
        "batch_size": ("choice", [512, 1024, 2048]),
    }
    on_policy = True
    AIDS: ClassVar[dict[str, str]] = {
        "noise": "not applied: PPO explores by its Gaussian policy's own spread (log_std_init, "
        "ent_coef)",
        "n_step": "not applied: PPO's targets are GAE returns over the whole rollout (gae_lambda)",
        "greedy_envs": "not applied: an on-policy update needs every sample drawn from the policy",
        "demonstrations": "adapted: the demonstrator plays the first transitions as for the "
        "replay learners, and they warm-start the actor (behaviour cloning) and the value "
        "(their returns) for bc_epochs passes before the first rollout of its own",
        "charge_exits": "",
    }

    def __init__(self, cfg: TrainConfig, env_cfg: EnvConfig, device: torch.device) -> None:
        super().__init__(cfg, env_cfg, device)
        self.lc = lc = cfg.learner
        self.n = n = env_cfg.num_pursuers
        self.max_steps = env_cfg.max_steps
        crash = cfg.protocol.crash_curriculum
        self.exits = (
            (env_cfg.capture_count, env_cfg.crash_reward)
            if crash is not None and crash.charge_exits
            else None
        )
        self.actor = PPOActors(lc, n).to(device)
        self.value = PerAgent(lambda: ValueNet(lc, n), n, lc.shared).to(device)
        self.return_norm = RunningNorm(1).to(device)
        self.huber_delta = lc.huber_delta
        self.policy = ActorPolicy(self.actor)
        self.opt_actor = adam(self.actor.parameters(), lc.lr_actor, eps=1e-5)
        self.opt_critic = adam(self.value.parameters(), lc.lr_critic, eps=1e-5)
        fields = {
            "state": ((n + 1, 8), torch.float32),
            "alive": ((n,), torch.bool),
            "action": ((n, 2), torch.float32),  # the unclipped Gaussian sample
            "reward": ((n,), torch.float32),
            "next_nonterminal": ((n,), torch.float32),
        }
        self.buffer = RolloutBuffer(
            lc.rollout_steps,
            cfg.num_envs,
            fields | {"logp": ((n,), torch.float32), "value": ((n,), torch.float32)},
            device,
        )
        # The run's updates, for annealing: rollouts of its env_steps (else of its episodes
        # played to the step limit).
        steps = cfg.env_steps or cfg.episodes * env_cfg.max_steps
        self.total_updates = max(1, math.ceil(steps / (lc.rollout_steps * cfg.num_envs)))
        demos = cfg.protocol.demonstrations
        self.demo, self.demos = None, None
        self.bc_pending = False
        if demos is not None and demos.transitions > 0:
            self.demo = SCRIPTED[demos.policy](env_cfg)
            demo_steps = math.ceil(demos.transitions / cfg.num_envs)
            self.demos = RolloutBuffer(demo_steps, cfg.num_envs, fields, device)
        self._acting: dict[str, Tensor] = {}
        self._last_value: Tensor | None = None

    @staticmethod
    def fixed_swarm(cfg: TrainConfig) -> str | None:
        return "has MLPs whose inputs are sized"

    @classmethod
    def build_policy(cls, cfg: TrainConfig, env_cfg: EnvConfig, device):
        actor = PPOActors(cfg.learner, env_cfg.num_pursuers).to(device)
        return ActorPolicy(actor), {"actor": actor}

    # --- acting ----------------------------------------------------------------------------------
    def values(
        self, state: Tensor, alive: Tensor, obs: Tensor | None = None, mask: Tensor | None = None
    ) -> Tensor:
        """V for every pursuer, in reward units: state (B, A, 8), alive (B, N) -> (B, N); the
        pursuers' observations (B, N, N, 8) and row masks (B, N, N) are rebuilt from the state
        unless given."""
        if obs is None:
            obs, mask = pursuer_obs(state, alive)
        shared_state = state.unsqueeze(1).expand(-1, self.n, -1, -1)
        v = self.value(obs, mask, shared_state).squeeze(-1)
        if self.lc.value_norm:
            v = self.return_norm.denormalise(v.unsqueeze(-1)).squeeze(-1)
        return v

    def demonstrating(self) -> bool:
        """Whether the demonstrator plays the next step (the protocol's ``demonstrations``)."""
        return self.demos is not None and not self.demos.full

    @torch.no_grad()
    def act(self, obs: Tensor, info: dict[str, Tensor], noise_scale: float, gen):
        """(E, N, 2) sampled actions clipped to [-1, 1] (``noise_scale`` is unused: PPO explores
        by its policy's own spread), or the demonstrator's while it plays; no evader actions."""
        if self.demonstrating():
            return self.demo(obs, info).clamp(-1.0, 1.0), None
        mean, log_std = self.actor(obs, info["obs_mask"])
        eps = torch.randn(mean.shape, generator=gen).to(mean.device)
        sample = mean + eps * log_std.exp()
        self._acting = {
            "action": sample,
            "logp": gaussian_log_prob(sample, mean, log_std),
            "value": self.values(info["state"], info["obs_mask"][:, :, 0], obs, info["obs_mask"]),
        }
        return sample.clamp(-1.0, 1.0), None

    @torch.no_grad()
    def record(self, before, actions, evader_actions, reward, terminated, after) -> None:
        """Store one vector step. An agent's episode continues unless its environment finished
        or it died in this step; a truncated episode's reward gains gamma * V(final obs)."""
        truncated = ~terminated & (after["steps"] >= self.max_steps)
        next_alive = after["final_obs_mask"][:, :, 0]
        next_nonterminal = (~(terminated | truncated)).unsqueeze(-1) & next_alive
        reward = reward.clone()
        gamma = self.lc.gamma
        if bool(truncated.any()):
            bootstrap = self.values(after["final_state"], next_alive)
            keep = truncated.unsqueeze(-1) & next_alive
            reward += gamma * bootstrap * keep.float()
        if self.exits is not None:  # a pursuer leaving owes what the TD learners charge it
            alive = before["obs_mask"][:, :, 0]
            reward += exit_charge(reward, alive, next_alive, terminated, gamma, *self.exits)
        step = dict(
            state=before["state"],
            alive=before["obs_mask"][:, :, 0],
            reward=reward,
            next_nonterminal=next_nonterminal.float(),
        )
        store = self.buffer
        if self.demonstrating():
            store, self.bc_pending = self.demos, True
            step["action"] = actions
        else:
            step.update(self._acting)
        store.add(**step)
        if store.full:
            self._last_value = self.values(after["state"], after["obs_mask"][:, :, 0])

    def episode_reset(self, done: Tensor) -> None:
        """The demonstrator's controllers start afresh in the environments ``done`` (E,)."""
        if self.demo is not None:
            self.demo.reset(done)

    def on_restart(self) -> None:
        """A rollout does not span a restart of the environments: it starts afresh."""
        self.buffer.clear()

    # --- learning --------------------------------------------------------------------------------
    def ready(self) -> bool:
        """An update consumes a full rollout (or, once, the full demonstrations)."""
        return self.buffer.full or (self.bc_pending and self.demos.full)

    def _advantages(self, data: dict[str, Tensor], value: Tensor) -> tuple[Tensor, Tensor]:
        """GAE advantages and returns (T, E, N) of a rollout whose values were ``value``."""
        lc = self.lc
        return gae(
            data["reward"],
            value,
            data["next_nonterminal"],
            self._last_value,
            lc.gamma,
            lc.gae_lambda,
        )

    def _inputs(self, data: dict[str, Tensor]) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """A rollout's (T, E, ...) fields as flat rows: obs (R, N, N, 8), mask (R, N, N),
        state (R, N, A, 8) and alive (R, N)."""
        alive = data["alive"].flatten(0, 1)
        state = data["state"].flatten(0, 1)
        obs, mask = pursuer_obs(state, alive)
        return obs, mask, state.unsqueeze(1).expand(-1, self.n, -1, -1), alive

    def _target(self, ret: Tensor, alive: Tensor) -> Tensor:
        """The value network's targets: the returns, standardised with ``value_norm`` by the
        running statistics once these returns are taken in."""
        if not self.lc.value_norm:
            return ret
        self.return_norm.update(ret[alive].unsqueeze(-1))
        return self.return_norm(ret.unsqueeze(-1)).squeeze(-1)

    def _value_loss(self, v: Tensor, target: Tensor, live: Tensor) -> Tensor:
        """The value loss over the live samples: squared error, or Huber (``huber_delta``)."""
        if self.huber_delta > 0:
            loss = nn.functional.huber_loss(v, target, reduction="none", delta=self.huber_delta)
        else:
            loss = (v - target) ** 2
        return masked_mean(loss, live)

    def _anneal(self) -> None:
        if not self.lc.anneal_lr:
            return
        frac = max(0.0, 1.0 - self.updates / self.total_updates)
        for opt, lr in ((self.opt_actor, self.lc.lr_actor), (self.opt_critic, self.lc.lr_critic)):
            for group in opt.param_groups:
                group["lr"] = frac * lr

    def _update_input_norms(self, obs: Tensor, mask: Tensor, state: Tensor, live: Tensor) -> None:
        """Take the live samples' inputs into every network's running input statistics."""
        if not self.lc.obs_norm:
            return
        o, m, s = obs[live], mask[live], state[live]
        for net in self.actor.nets.nets:
            net.input.norm.update(net.input.features(o, m))
        for net in self.value.nets:
            net.input.norm.update(net.input.features(o, m, s))

    def update(self, gen: torch.Generator) -> dict[str, float]:
        """``ppo_epochs`` passes of clipped-surrogate and value updates over the rollout, which
        is then cleared (or, once, the warm start on the demonstrations); returns the mean
        metrics."""
        if self.bc_pending and self.demos.full:
            return self._warm_start(gen)
        cfg, data = self.lc, self.buffer.data
        self._anneal()
        adv, ret = self._advantages(data, data["value"])
        obs, mask, state, alive = self._inputs(data)
        flat = {
            "action": data["action"].flatten(0, 1),
            "logp": data["logp"].flatten(0, 1),
            "adv": adv.flatten(0, 1),
            "target": self._target(ret.flatten(0, 1), alive),
        }
        sums: dict[str, float] = {}
        steps = 0
        for _ in range(cfg.ppo_epochs):
            stop = False
            for idx in self._minibatches(alive.shape[0], gen):
                live = alive[idx]
                if not bool(live.any()):
                    continue
                batch = {k: v[idx] for k, v in flat.items()}
                stats = self._minibatch(obs[idx], mask[idx], state[idx], live, batch)
                for k, v in stats.items():
                    sums[k] = sums.get(k, 0.0) + v
                steps += 1
                if cfg.target_kl > 0 and stats["approx_kl"] > cfg.target_kl:
                    stop = True
                    break
            if stop:
                break
        self._update_input_norms(obs, mask, state, alive)
        self.buffer.clear()
        self.updates += 1
        out = {k: v / max(steps, 1) for k, v in sums.items()}
        out["q_mean"] = float(masked_mean(data["value"], data["alive"]))
        return out

    def _minibatches(self, rows: int, gen: torch.Generator):
        order = torch.randperm(rows, generator=gen).to(self.device)
        for start in range(0, rows, self.lc.batch_size):
            yield order[start : start + self.lc.batch_size]

    def _minibatch(self, obs, mask, state, live, batch) -> dict[str, float]:
        """One gradient step of the actor and of V on a minibatch (B transitions, N pursuers)."""
        cfg = self.lc
        mean, log_std = self.actor(obs, mask)
        logp = gaussian_log_prob(batch["action"], mean, log_std)
        log_ratio = logp - batch["logp"]
        ratio = log_ratio.exp()
        adv = batch["adv"]
        live_adv = adv[live]
        adv = (adv - live_adv.mean()) / (live_adv.std(unbiased=False) + 1e-8)
        surrogate = torch.min(ratio * adv, ratio.clamp(1 - cfg.clip_coef, 1 + cfg.clip_coef) * adv)
        entropy = (log_std + 0.5 * math.log(2 * math.pi * math.e)).sum(-1)
        actor_loss = -masked_mean(surrogate, live) - cfg.ent_coef * masked_mean(entropy, live)
        optimise(self.opt_actor, actor_loss, self.actor.parameters(), cfg.grad_clip)
        v = self.value(obs, mask, state).squeeze(-1)
        critic_loss = self._value_loss(v, batch["target"], live)
        optimise(self.opt_critic, critic_loss, self.value.parameters(), cfg.grad_clip)
        with torch.no_grad():
            approx_kl = masked_mean((ratio - 1) - log_ratio, live)
            clipped = ((ratio - 1).abs() > cfg.clip_coef).float()
            return {
                "actor_loss": float(actor_loss),
                "critic_loss": float(critic_loss),
                "entropy": float(masked_mean(entropy, live)),
                "approx_kl": float(approx_kl),
                "clip_frac": float(masked_mean(clipped, live)),
                "noise": float(masked_mean(log_std.exp().mean(-1), live)),
            }

    def _warm_start(self, gen: torch.Generator) -> dict[str, float]:
        """``bc_epochs`` passes over the demonstrations: the actor's mean toward the
        demonstrator's actions (squared error), the value toward their GAE returns."""
        data = self.demos.data
        obs, mask, state, alive = self._inputs(data)
        self._update_input_norms(obs, mask, state, alive)  # the first inputs it sees
        with torch.no_grad():
            value = self.values(data["state"].flatten(0, 1), alive).view_as(data["reward"])
        _, ret = self._advantages(data, value)
        target = self._target(ret.flatten(0, 1), alive)
        action = data["action"].flatten(0, 1)
        bc_sum, v_sum, steps = 0.0, 0.0, 0
        for _ in range(self.lc.bc_epochs):
            for idx in self._minibatches(alive.shape[0], gen):
                live = alive[idx]
                if not bool(live.any()):
                    continue
                mean, _ = self.actor(obs[idx], mask[idx])
                bc_loss = masked_mean(((mean - action[idx]) ** 2).sum(-1), live)
                optimise(self.opt_actor, bc_loss, self.actor.parameters(), self.lc.grad_clip)
                v = self.value(obs[idx], mask[idx], state[idx]).squeeze(-1)
                critic_loss = self._value_loss(v, target[idx], live)
                optimise(self.opt_critic, critic_loss, self.value.parameters(), self.lc.grad_clip)
                bc_sum, v_sum = (
                    bc_sum + float(bc_loss.detach()),
                    v_sum + float(critic_loss.detach()),
                )
                steps += 1
        self.bc_pending = False
        self.updates += 1  # as the trainer counts it (a resumed run starts from that count)
        return {"bc_loss": bc_sum / max(steps, 1), "critic_loss": v_sum / max(steps, 1)}

    # --- saving ----------------------------------------------------------------------------------
    def modules(self) -> dict[str, nn.Module]:
        return {"actor": self.actor, "value": self.value, "return_norm": self.return_norm}

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"actor": self.opt_actor, "value": self.opt_critic}

    def policy_modules(self) -> dict[str, nn.Module]:
        """What a deployed policy needs: the actor."""
        return {"actor": self.actor}

    def state_dict(self) -> dict[str, Any]:
        """The demonstrator's controller state, the demonstrations gathered so far and whether
        the warm start is still to come."""
        if self.demos is None:
            return {}
        return {
            "demo": self.demo.state_dict(),
            "demos": self.demos.state_dict(),
            "bc_pending": self.bc_pending,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if self.demos is not None and "demos" in state:
            if "demo" in state:  # a checkpoint older than this record: the controllers start afresh
                self.demo.load_state_dict(state["demo"])
            self.demos.load_state_dict(state["demos"])
            self.bc_pending = state["bc_pending"]
