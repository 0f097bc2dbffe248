"""MAAC baseline (Table IV): the multi-actor attention critic (Iqbal & Sha, ICML 2019), adapted to
continuous actions as a soft actor-critic (Haarnoja et al., 2018) with squashed Gaussian
policies, off-policy on the shared replay storage.

Critic (:class:`AttentionCritic`, MAAC's Fig. 1 and eq. 2, Q_i(o, a) = f_i(g_i(o_i, a_i), x_i)):
every pursuer j has an encoding e_j = g(s_j, a_j) of its state and action, where s_j is its
global-state row (Table I self row), the evader's [position, velocity, obstacle vector] and an
alive flag. Pursuer i's Q is ``head(e_i, x_i)``, with x_i the multi-head attention of its query
(from e_i) over the keys and values of the *other alive* pursuers' encodings. The original's
code, written for discrete actions, encodes agent i's state alone and outputs one Q per action;
with continuous actions agent i's own action enters through e_i, as the paper's eq. 2 writes
it. Encoders and heads are per pursuer with ``shared=False`` (as the original; the attention
weights are always shared), one for all with ``shared=True`` (the default).

One update (every ``update_every`` transitions after ``warmup``):

1. critics (two, with target copies, as SAC v2; MAAC has one): y_i = r_i + gamma * (1 -
   terminated) * alive'_i * (min_k Q'_k,i(s', a') - alpha * log pi(a'_i | o'_i)), a' sampled
   from the current policies on s'; squared error masked to the pursuers alive in s, plus
   ``attend_reg`` times the squared attention logits (as the original);
2. actors: every alive pursuer samples a new action (reparameterised); pursuer i's loss is
   alpha * log pi(a_i | o_i) - min_k Q_k,i(s, a), where the others' new actions enter Q_i
   detached (they are MAAC's "current policies of the other agents"), so the gradient is
   dQ_i/da_i only;
3. the temperature alpha, towards ``target_entropy`` per pursuer (``auto_alpha``);
4. soft target updates (``tau``).

Dead pursuers: zero rows with a 0 flag everywhere, left out of the others' attention (a pursuer
with no other alive pursuer attends to nothing: x_i = 0), and out of every loss.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor, nn

from pes.errors import ConfigError
from pes.learn.buffer import ReplayBuffer, transition, transition_fields
from pes.learn.common import (
    ActorPolicy,
    adam,
    gaussian_log_prob,
    masked_mean,
    optimise,
    soft_update,
    target_copy,
)
from pes.learn.config import OffPolicyConfig, TrainConfig
from pes.learn.features import pursuer_obs
from pes.learn.learner import Learner
from pes.learn.nets import FlatObsMLP, PerAgent, RowScaled, mlp
from pes.learn.presets import QUICK_RUN, TINY_PROTOCOL, TINY_RUN, gpu_preset
from pes.learn.td import sample_windows, td_target
from pes.policies import SCRIPTED
from pes.sim.config import EnvConfig


@dataclass
class MAACConfig(OffPolicyConfig):
    """MAAC's settings: the paper's (§V-A) where they apply, MAAC's own 128 units and 4 heads."""

    hidden: int = 128
    """Units of the actors' hidden layers and of the critics' encoders and attention."""
    shared: bool = True
    """One actor and one set of critic encoders and heads for all pursuers."""
    obstacle_scale: float = 20.0
    """Factor on the obstacle-vector columns of the observation rows (``RowScaled``)."""
    target_scale: float = 5.0
    """Factor on the vector to the evader in the observation rows."""
    attention_heads: int = 4
    """Attention heads of the critic (``hidden`` must be a multiple)."""
    alpha: float = 0.05
    """Initial entropy temperature (SAC's 0.2 explored too long in the learning test)."""
    auto_alpha: bool = True
    """Tune the temperature towards ``target_entropy`` (SAC v2); False keeps ``alpha``."""
    target_entropy: float = -2.0
    """Target entropy per pursuer (nats; -2 = minus the action dimension)."""
    lr_alpha: float = 1e-3
    """Adam learning rate of the temperature."""
    attend_reg: float = 1e-3
    """Weight of the squared attention logits in the critic loss (as the original)."""

    POSITIVE: ClassVar[tuple[str, ...]] = (*OffPolicyConfig.POSITIVE, "hidden", "attention_heads")
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = (
        *OffPolicyConfig.NON_NEGATIVE,
        "obstacle_scale",
        "target_scale",
        "alpha",
        "lr_alpha",
        "attend_reg",
    )

    def check(self) -> None:
        if self.hidden % self.attention_heads:
            raise ConfigError(
                f"maac: hidden ({self.hidden}) must be a multiple of attention_heads "
                f"({self.attention_heads})"
            )


MAAC_TUNED: dict[str, Any] = dict(
    lr_actor=3.93e-4, lr_critic=5.69e-4, hidden=128, batch_size=256, update_every=32, gamma=0.98
)
"""The best of MAAC's search over the update ratio, batch and discount as well as the learning
rates and width (results/tuning_current/maac, trial t04: 38.0 % of the held-out episodes after
1,000,000 env steps; the search began at the earlier search's lr_actor 1.08e-3, lr_critic
7.87e-4, hidden 64 with batch 256, one update per 64 transitions and gamma 0.95, 20.5 % there).
The target entropy is not searched: the presets follow SAC's rule, -dim(A) = -2 per pursuer."""

MAAC_PRESETS: dict[str, dict[str, Any]] = {
    "paper": dict(episodes=4000, num_envs=1, env=dict(evader_policy="ddpg")),
    "quick": dict(QUICK_RUN, buffer_size=300_000, warmup=10_000) | MAAC_TUNED,
    "tiny": dict(
        TINY_RUN,
        hidden=32,
        attention_heads=2,
        buffer_size=20_000,
        batch_size=64,
        update_every=8,
        warmup=500,
        protocol=TINY_PROTOCOL,
    ),
}
MAAC_PRESETS["gpu"] = gpu_preset(MAAC_PRESETS["quick"])


LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0
"""Range of the actors' log standard deviation (pre-tanh)."""


class SquashedGaussianActor(nn.Module):
    """The pursuers' policies: a = tanh(u), u ~ N(mean(o_i), std(o_i)), mean and log std from a
    :class:`FlatObsMLP` on pursuer i's observation (one shared, or one per pursuer)."""

    def __init__(self, lc: MAACConfig, num_pursuers: int) -> None:
        super().__init__()
        n = num_pursuers
        self.nets = PerAgent(
            lambda: FlatObsMLP(n, lc.hidden, 4, 2, lc.obstacle_scale, lc.target_scale),
            n,
            lc.shared,
        )

    def forward(self, obs: Tensor, mask: Tensor) -> tuple[Tensor, Tensor]:
        """obs (B, N, N, 8), mask (B, N, N) -> pre-tanh mean and log std, each (B, N, 2)."""
        out = self.nets(obs, mask)
        return out[..., :2], out[..., 2:].clamp(LOG_STD_MIN, LOG_STD_MAX)

    def sample(self, obs: Tensor, mask: Tensor, gen: torch.Generator) -> tuple[Tensor, Tensor]:
        """Reparameterised actions (B, N, 2) in (-1, 1) and their log-probabilities (B, N)."""
        return self.squash(*self(obs, mask), gen)

    @staticmethod
    def squash(mean: Tensor, log_std: Tensor, gen: torch.Generator) -> tuple[Tensor, Tensor]:
        """Actions (B, N, 2) sampled from the policy with pre-tanh ``mean`` and ``log_std`` (each
        (B, N, 2)), and their log-probabilities (B, N)."""
        eps = torch.randn(mean.shape, generator=gen).to(mean.device)
        u = mean + eps * log_std.exp()
        # log pi(a) = log N(u) - sum log(1 - tanh(u)^2), written stably
        correction = 2.0 * (math.log(2.0) - u - nn.functional.softplus(-2.0 * u))
        return torch.tanh(u), gaussian_log_prob(u, mean, log_std) - correction.sum(-1)

    def mean_action(self, obs: Tensor, mask: Tensor) -> Tensor:
        """(B, N, 2) deterministic actions: tanh of the mean."""
        return torch.tanh(self(obs, mask)[0])


def small_softmax(logits: Tensor) -> Tensor:
    """Softmax over the last dimension, written out: for the few keys of an attention over
    agents (N - 1 = 4) it takes a fifth of the time of ``torch.softmax`` on a CPU, whose kernel
    vectorises along that dimension."""
    e = (logits - logits.amax(-1, keepdim=True)).exp()
    return e / e.sum(-1, keepdim=True)


class AttentionCritic(RowScaled):
    """MAAC's attention critic for continuous actions: Q_i(s, a) of every pursuer in one pass.

    Rows are scaled as the CBC networks' (:class:`RowScaled`)."""

    def __init__(self, lc: MAACConfig, num_pursuers: int) -> None:
        super().__init__(0, lc.obstacle_scale, lc.target_scale)
        h, n = lc.hidden, num_pursuers
        self.heads = lc.attention_heads
        row = 8 + 6 + 1  # own state row, the evader's, alive flag

        def encoder(inputs: int):
            return lambda: nn.Sequential(nn.Linear(inputs, h), nn.LeakyReLU())

        self.encoder = PerAgent(encoder(row + 2), n, lc.shared)
        self.query = nn.Linear(h, h, bias=False)
        self.key = nn.Linear(h, h, bias=False)
        self.value = nn.Sequential(nn.Linear(h, h), nn.LeakyReLU())
        self.head = PerAgent(lambda: mlp([2 * h, h, 1]), n, lc.shared)

    def forward(
        self, state: Tensor, alive: Tensor, actions: Tensor, own_actions: Tensor | None = None
    ) -> tuple[Tensor, Tensor]:
        """Q of every pursuer.

        Args:
            state: (B, A, 8) global states; alive: (B, N) bool.
            actions: (B, N, 2) the actions the other pursuers' keys and values see.
            own_actions: (B, N, 2) the action in each pursuer's own encoding, which makes its
                query and enters its head (default ``actions``); the actor update passes its
                new actions here and their detached copy as ``actions``.

        Returns:
            Q (B, N) and the squared attention logits averaged over the attended pairs (a
            scalar, for the regulariser).
        """
        b, n = alive.shape
        flag = alive.unsqueeze(-1).to(state.dtype)
        scaled = state * self.scale
        rows = torch.cat([scaled[:, :n], scaled[:, -1:, :6].expand(-1, n, -1), flag], dim=-1)
        rows = rows * flag
        sa = self.encoder(torch.cat([rows, actions * flag], dim=-1))  # (B, N, h)
        enc = sa if own_actions is None else self.encoder(torch.cat([rows, own_actions * flag], -1))
        d = enc.shape[-1] // self.heads

        def split(x: Tensor) -> Tensor:  # (B, N, h) -> (B, H, N, d)
            return x.view(b, n, self.heads, d).transpose(1, 2)

        q, k, v = split(self.query(enc)), split(self.key(sa)), split(self.value(sa))
        logits = q @ k.transpose(-1, -2) / math.sqrt(d)  # (B, H, N, N)
        others = ~torch.eye(n, dtype=torch.bool, device=state.device)
        allowed = (alive.unsqueeze(1) & others).unsqueeze(1)  # (B, 1, N, N): key j for query i
        weights = small_softmax(logits.masked_fill(~allowed, -1e9)) * allowed
        attended = (weights @ v).transpose(1, 2).reshape(b, n, -1)
        value = self.head(torch.cat([enc, attended], dim=-1)).squeeze(-1)
        reg = masked_mean(logits**2, allowed.expand_as(logits))
        return value, reg


class Temperature(nn.Module):
    """The entropy temperature alpha, kept as its logarithm."""

    def __init__(self, alpha: float) -> None:
        super().__init__()
        self.log_alpha = nn.Parameter(torch.tensor(math.log(max(alpha, 1e-8))))

    def forward(self) -> Tensor:
        return self.log_alpha.exp()


class MAAC(Learner):
    """The MAAC learner (soft actor-critic with attention critics)."""

    name = "maac"
    Config = MAACConfig
    PRESETS = MAAC_PRESETS
    TUNE_SPACE: ClassVar[dict[str, tuple]] = {
        "lr_actor": ("log", 1e-4, 2e-3),
        "lr_critic": ("log", 3e-4, 3e-3),
        "hidden": ("choice", [32, 64, 128]),
        "batch_size": ("choice", [256, 512, 1024]),
        "update_every": ("choice", [16, 32, 64]),
        "gamma": ("choice", [0.95, 0.98, 0.99]),
    }
    AIDS: ClassVar[dict[str, str]] = {
        "noise": "not applied: MAAC explores by sampling its stochastic policy, at the entropy "
        "its temperature keeps (alpha, target_entropy)",
        "n_step": "",
        "greedy_envs": "",
        "demonstrations": "",
        "charge_exits": "",
    }

    def __init__(self, cfg: TrainConfig, env_cfg: EnvConfig, device: torch.device) -> None:
        super().__init__(cfg, env_cfg, device)
        self.lc = lc = cfg.learner
        protocol = cfg.protocol
        self.n = n = env_cfg.num_pursuers
        self.n_step = protocol.n_step
        crash = protocol.crash_curriculum
        self.exits = (
            (env_cfg.capture_count, env_cfg.crash_reward)
            if crash is not None and crash.charge_exits
            else None
        )
        self.actor = SquashedGaussianActor(lc, n).to(device)
        self.critics = nn.ModuleList(AttentionCritic(lc, n) for _ in range(2)).to(device)
        self.critics_target = target_copy(self.critics)
        self.temperature = Temperature(lc.alpha).to(device)
        self.policy = ActorPolicy(self.actor)
        self.opt_actor = adam(self.actor.parameters(), lc.lr_actor)
        self.opt_critic = adam(self.critics.parameters(), lc.lr_critic)
        self.opt_alpha = adam(self.temperature.parameters(), lc.lr_alpha)
        fields = transition_fields(n)
        demos = protocol.demonstrations
        self.demo, self.demo_transitions = None, 0
        if demos is not None and demos.transitions > 0:
            # the demonstrator's transitions fill the replay buffer; MAAC does not clone them
            self.demo = SCRIPTED[demos.policy](env_cfg)
            self.demo_transitions = demos.transitions
        self.buffer = ReplayBuffer(lc.buffer_size, cfg.num_envs, fields, device)
        # (E, 1, 1) True for the environments that explore, False for the greedy_envs share
        greedy = round(protocol.greedy_envs * cfg.num_envs)
        explore = torch.arange(cfg.num_envs, device=device) < cfg.num_envs - greedy
        self.explore = explore[:, None, None]

    @staticmethod
    def fixed_swarm(cfg: TrainConfig) -> str | None:
        return "has MLPs whose inputs are sized"

    @classmethod
    def build_policy(cls, cfg: TrainConfig, env_cfg: EnvConfig, device):
        actor = SquashedGaussianActor(cfg.learner, env_cfg.num_pursuers).to(device)
        return ActorPolicy(actor), {"actor": actor}

    # --- acting ----------------------------------------------------------------------------------
    @torch.no_grad()
    def act(self, obs: Tensor, info: dict[str, Tensor], noise_scale: float, gen):
        """(E, N, 2) actions sampled from the policies (the mean in the ``greedy_envs`` share of
        the environments), or the demonstrator's while it plays; no evader actions."""
        mean, log_std = self.actor(obs, info["obs_mask"])
        sample = self.actor.squash(mean, log_std, gen)[0]
        if self.demonstrating():
            return self.demo(obs, info).clamp(-1.0, 1.0), None
        return torch.where(self.explore, sample, torch.tanh(mean)), None

    def record(self, before, actions, evader_actions, reward, terminated, after) -> None:
        """Store one vector step: ``before``/``after`` are the infos around ``env.step``."""
        self.buffer.add(**transition(before, actions, reward, terminated, after))

    def demonstrating(self) -> bool:
        """Whether the demonstrator plays the next step (the protocol's ``demonstrations``)."""
        wanted = min(self.demo_transitions, self.buffer.capacity)
        return self.demo is not None and len(self.buffer) < wanted

    def episode_reset(self, done: Tensor) -> None:
        if self.demo is not None:
            self.demo.reset(done)

    def state_dict(self) -> dict[str, Any]:
        return {"demo": self.demo.state_dict() if self.demo is not None else None}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if self.demo is not None:
            self.demo.load_state_dict(state["demo"])

    # --- learning --------------------------------------------------------------------------------
    def ready(self) -> bool:
        return len(self.buffer) >= max(self.lc.warmup, self.lc.batch_size)

    def update_credit(self) -> float:
        return self.cfg.num_envs / self.lc.update_every

    def update(self, gen: torch.Generator) -> dict[str, float]:
        """One update of the critics, the actors and the temperature; returns their metrics."""
        cfg = self.lc
        w = sample_windows(self.buffer, cfg.batch_size, self.n_step, cfg.gamma, gen)
        state, alive, action = w.state, w.alive, w.action
        next_state, next_alive = w.next_state, w.next_alive
        alpha = self.temperature().detach()

        with torch.no_grad():
            next_obs, next_mask = pursuer_obs(next_state, next_alive)
            next_action, next_logp = self.actor.sample(next_obs, next_mask, gen)
            q_next = torch.min(
                *(c(next_state, next_alive, next_action)[0] for c in self.critics_target)
            )
            # the soft value of the window's last next state (the entropy terms of the
            # window's inner steps are left out, as n-step SAC commonly does)
            y = td_target(w, q_next - alpha * next_logp, cfg.gamma, self.exits)
        critic_loss = torch.zeros((), device=state.device)
        for critic in self.critics:
            q, reg = critic(state, alive, action)
            critic_loss = critic_loss + masked_mean((q - y) ** 2, alive) + cfg.attend_reg * reg
        optimise(self.opt_critic, critic_loss, self.critics.parameters(), cfg.grad_clip)

        obs, mask = pursuer_obs(state, alive)
        mean, log_std = self.actor(obs, mask)
        new_action, logp = self.actor.squash(mean, log_std, gen)
        self.critics.requires_grad_(False)
        q_pi = torch.min(
            *(c(state, alive, new_action.detach(), new_action)[0] for c in self.critics)
        )
        self.critics.requires_grad_(True)
        actor_loss = masked_mean(alpha * logp - q_pi, alive)
        optimise(self.opt_actor, actor_loss, self.actor.parameters(), cfg.grad_clip)

        if cfg.auto_alpha:
            entropy_gap = (logp.detach() + cfg.target_entropy) * alive.float()
            alpha_loss = -(self.temperature.log_alpha * entropy_gap).sum() / alive.sum().clamp(
                min=1
            )
            optimise(self.opt_alpha, alpha_loss, self.temperature.parameters(), 0.0)
        soft_update(self.critics_target, self.critics, cfg.tau)
        self.updates += 1
        std = log_std.detach().exp().mean(-1)  # the policy's spread before this update
        return {
            "critic_loss": float(critic_loss.detach()),
            "actor_loss": float(actor_loss.detach()),
            "q_mean": float(masked_mean(q_pi.detach(), alive)),
            "entropy": float(-masked_mean(logp.detach(), alive)),
            "alpha": float(alpha),
            "noise": float(masked_mean(std, alive)),
        }

    # --- saving ----------------------------------------------------------------------------------
    def modules(self) -> dict[str, nn.Module]:
        return {
            "actor": self.actor,
            "critics": self.critics,
            "critics_target": self.critics_target,
            "temperature": self.temperature,
        }

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"actor": self.opt_actor, "critic": self.opt_critic, "alpha": self.opt_alpha}

    def policy_modules(self) -> dict[str, nn.Module]:
        """What a deployed policy needs: the actors."""
        return {"actor": self.actor}
