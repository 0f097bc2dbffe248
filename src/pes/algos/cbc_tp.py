"""CBC-TP Net (paper §III-IV, Algorithm 1) and, with ``use_tp=False``, CBC Net.

The networks, the method's settings and presets, and the learner. CBC-TP Net trains on the
deterministic actor-critic of :mod:`pes.learn.actor_critic`; one update (Algorithm 1, lines
11-21), from the shared replay storage:

1. TP Net: a minibatch of J history windows (n frames) and the evader's next k positions,
   loss eq. (7) (mean squared error in arena units);
2. critic: y_i = r_i + gamma * (1 - terminated) * Q'_i(s', a', p'), a' from the target actor on
   s' and the predicted path p' of s' (eqs. 5-6), masked mean over the pursuers alive in s;
   the training protocol may make it an n-step target and charge pursuers that leave the
   game (:mod:`pes.learn.td`);
3. actor: maximise Q_i(s, a_1..pi(o_i, p)..a_N, p) (eq. 4) for one random alive pursuer i of
   each sample, the others' actions from the buffer (``actor_gradient="one"``), or the mean
   Q_i with every alive pursuer acting (``"all"``), plus a small penalty on the squared
   pre-tanh action;
4. soft target updates with rate tau.

Gradients flow through the LSTMs by backpropagation through time (across the agents for the
actor and critic, across the history for TP Net). The prediction fed to the actor and critic is
TP Net's, detached: TP Net learns only from eq. (7), as Algorithm 1's hierarchy.

The predictions are stored with each transition as TP Net made them while acting (for s and
for s'), in the place of Algorithm 1's p_tar: recomputing them for every minibatch (two history
windows through TP Net per sample) is a large share of an update on a CPU, and TP Net converges
within the warm-up (its loss is ~1e-5 in arena units after a few hundred updates), so the
stored ones are current but for the first transitions. TP Net is trained from the warm-up on,
every ``tp_update_every`` updates; the actor and critic after the warm-up.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor, nn

from pes.errors import ConfigError
from pes.learn.actor_critic import ActorCritic, ActorCriticConfig, DeterministicPolicy
from pes.learn.common import adam, masked_mean, optimise
from pes.learn.config import TrainConfig
from pes.learn.features import frames, pursuer_obs, relative_prediction
from pes.learn.nets import RowScaled, mlp
from pes.learn.presets import QUICK_RUN, TINY_PROTOCOL, TINY_RUN, gpu_preset
from pes.learn.td import TDWindows
from pes.sim.config import EnvConfig


@dataclass
class CBCNetConfig(ActorCriticConfig):
    """CBC Net's settings (the paper's, §V-A and Table II, by default)."""

    hidden: int = 256
    """Units of the actor's and the critic's bidirectional LSTM (each direction)."""
    mlp_hidden: int = 64
    """Units of the MLP after the LSTM."""
    shared: bool = True
    """One actor and one critic for all pursuers (False: one per pursuer, as Algorithm 1)."""
    actor_gradient: str = "one"
    """Actor update: ``one`` (one random alive pursuer per sample takes the current actor's
    action, the others keep their stored ones, as MADDPG) or ``all`` (every alive pursuer
    takes it at once; the actor ascends the mean of their Qs)."""

    POSITIVE: ClassVar[tuple[str, ...]] = (
        *ActorCriticConfig.POSITIVE,
        "hidden",
        "mlp_hidden",
    )

    def check(self) -> None:
        if self.actor_gradient not in ("one", "all"):
            raise ConfigError(f"actor_gradient must be one or all, got '{self.actor_gradient}'")


@dataclass
class CBCTPConfig(CBCNetConfig):
    """CBC-TP Net's settings: CBC Net's and TP Net's."""

    tp_hidden: int = 256
    """Units of each TP Net LSTM layer."""
    tp_layers: int = 2
    """TP Net LSTM layers."""
    horizon: int = 3
    """k: future evader positions TP Net predicts (the actor sees 2k numbers)."""
    lr_tp: float = 1e-3
    """Adam learning rate of TP Net."""
    tp_batch_size: int = 512
    """Minibatch of the TP Net updates (J)."""
    tp_update_every: int = 1
    """Critic/actor updates per TP Net update (TP Net converges long before the others)."""

    POSITIVE: ClassVar[tuple[str, ...]] = (
        *CBCNetConfig.POSITIVE,
        "tp_hidden",
        "tp_layers",
        "horizon",
        "lr_tp",
        "tp_batch_size",
        "tp_update_every",
    )


def prediction_size(lc: CBCNetConfig) -> int:
    """Numbers of the predicted path each pursuer sees: 2k with TP Net, 0 without."""
    return 2 * lc.horizon if isinstance(lc, CBCTPConfig) else 0


PAPER_LEARNER: dict[str, Any] = dict(episodes=4000, num_envs=1, env=dict(evader_policy="ddpg"))
"""The paper's settings (§V-A): the dataclass defaults, 4000 episodes from one environment."""

QUICK_LEARNER: dict[str, Any] = dict(
    hidden=64,
    mlp_hidden=64,
    lr_actor=5e-4,
    lr_critic=1e-3,
    buffer_size=300_000,
    batch_size=256,
    update_every=32,
    warmup=10_000,
)
"""The learner settings of CBC Net's quick preset (a laptop CPU)."""

TINY_LEARNER: dict[str, Any] = dict(
    hidden=32, mlp_hidden=32, buffer_size=20_000, batch_size=64, update_every=8, warmup=500
)

CBC_TUNED: dict[str, Any] = dict(lr_actor=1.53e-3, lr_critic=1.34e-3, batch_size=256, hidden=64)
"""The best of CBC Net's search (results/tuning/cbc, trial t03: 57.5 % of the held-out episodes
after 1,000,000 env steps); the search began at lr_actor 5e-4, lr_critic 1e-3, batch 256,
hidden 64. The search over the wider space (results/tuning_current/cbc: update ratio and gamma
as well) kept it: 50.0 % after 1,000,000 env steps, the next best trial 38.5 %."""

CBC_PRESETS: dict[str, dict[str, Any]] = {
    "paper": PAPER_LEARNER,
    "quick": {**QUICK_RUN, **QUICK_LEARNER, **CBC_TUNED},
    "tiny": {**TINY_RUN, **TINY_LEARNER, "protocol": TINY_PROTOCOL},
}
CBC_PRESETS["gpu"] = gpu_preset(CBC_PRESETS["quick"])
"""CBC Net's presets: ``quick`` trains the shared quick budget (2,000,000 env steps)."""

TP_QUICK = dict(tp_hidden=64, lr_tp=1e-3, tp_batch_size=256, tp_update_every=4)
CBC_TP_TUNED: dict[str, Any] = dict(lr_actor=1.8e-3, lr_critic=2.67e-3, batch_size=512, hidden=32)
"""The best of CBC-TP Net's search (results/tuning/cbc-tp, trial t05: 93.0 % of the held-out
episodes after 1,000,000 env steps); it sets every key of CBC_TUNED, so CBC-TP Net's quick
learner does not depend on CBC Net's search."""
CBC_TP_PRESETS: dict[str, dict[str, Any]] = {
    "paper": PAPER_LEARNER,
    "quick": {**CBC_PRESETS["quick"], **TP_QUICK, **CBC_TP_TUNED},
    "tiny": {**CBC_PRESETS["tiny"], "tp_hidden": 32, "tp_batch_size": 64},
}
CBC_TP_PRESETS["gpu"] = gpu_preset(CBC_TP_PRESETS["quick"])
"""CBC-TP Net's presets: CBC Net's, with TP Net's settings."""


class TPNet(nn.Module):
    """Target prediction (Fig. 3, eq. 7): an LSTM over the last n frames that predicts the
    evader's next k positions.

    Each frame is summarised so that one network serves any number of pursuers: the evader's
    [position, velocity] and, relative to it, the mean [position, velocity] of the alive
    pursuers and the nearest alive pursuer's (12 numbers). The LSTM's last output goes through
    a linear layer to k displacements from the evader's current position.
    """

    FRAME_FEATURES = 12

    def __init__(self, hidden: int = 256, layers: int = 2, horizon: int = 3) -> None:
        super().__init__()
        self.horizon = horizon
        self.lstm = nn.LSTM(self.FRAME_FEATURES, hidden, num_layers=layers, batch_first=True)
        self.head = nn.Linear(hidden, 2 * horizon)

    @staticmethod
    def summarise(frames: Tensor) -> Tensor:
        """(..., n, A, 4) history frames -> (..., n, 12) frame features."""
        evader = frames[..., -1, :]
        rel = frames[..., :-1, :] - evader.unsqueeze(-2)
        present = frames[..., :-1, :].abs().sum(-1) > 0  # dead pursuers and padding are zero
        w = present.unsqueeze(-1).to(frames.dtype)
        mean = (rel * w).sum(-2) / w.sum(-2).clamp(min=1.0)
        gap = (rel[..., :2] ** 2).sum(-1).masked_fill(~present, float("inf"))
        nearest = gap.argmin(-1, keepdim=True)
        near = rel.gather(-2, nearest.unsqueeze(-1).expand(*nearest.shape, 4)).squeeze(-2)
        near = near * present.any(-1, keepdim=True).to(frames.dtype)
        return torch.cat([evader, mean, near], dim=-1)

    def forward(self, frames: Tensor) -> Tensor:
        """(B, n, A, 4) history frames, oldest first -> (B, k, 2) predicted evader positions."""
        out, _ = self.lstm(self.summarise(frames))
        disp = self.head(out[:, -1]).view(-1, self.horizon, 2)
        return frames[:, -1, -1, :2].unsqueeze(1) + disp


class CBCActor(RowScaled):
    """The CBC actor (Fig. 4a): a bidirectional LSTM across the agents of one pursuer's
    observation, with the pursuer itself at the first and the last cell, joined with the
    predicted evader path (relative to the pursuer) and an MLP to the desired acceleration.

    Each cell's input is the observation row (8, scaled by :class:`RowScaled`) and a 1/0 flag
    saying whether the row is real; masked rows are zero, so any number of alive pursuers goes
    through the same network. The last layer starts near zero (as DDPG's), so that the untrained
    swarm hovers instead of flying into the nearest wall.
    """

    def __init__(
        self,
        hidden: int = 256,
        mlp_hidden: int = 64,
        pred_dim: int = 6,
        obstacle_scale: float = 1.0,
        target_scale: float = 1.0,
    ) -> None:
        super().__init__(pred_dim, obstacle_scale, target_scale)
        self.hidden = hidden
        self.lstm = nn.LSTM(9, hidden, batch_first=True, bidirectional=True)
        self.head = mlp([2 * hidden + pred_dim, mlp_hidden, 2])
        nn.init.uniform_(self.head[-1].weight, -3e-3, 3e-3)
        nn.init.uniform_(self.head[-1].bias, -3e-3, 3e-3)

    def pre_activation(self, obs: Tensor, mask: Tensor, pred: Tensor | None) -> Tensor:
        """obs (B, N, 8), mask (B, N), pred (B, pred_dim) or None -> (B, 2) before the tanh."""
        cells = torch.cat([obs * self.scale, mask.unsqueeze(-1).to(obs.dtype)], dim=-1)
        seq = torch.cat([cells, cells[:, :1]], dim=1)  # self first and last
        out, _ = self.lstm(seq)
        h = self.hidden
        feat = torch.cat([out[:, -1, :h], out[:, 0, h:]], dim=-1)
        if self.pred_dim:
            feat = torch.cat([feat, pred * self.target_scale], dim=-1)
        return self.head(feat)

    def forward(self, obs: Tensor, mask: Tensor, pred: Tensor | None) -> Tensor:
        """obs (B, N, 8), mask (B, N), pred (B, pred_dim) or None -> actions (B, 2) in [-1, 1]."""
        return torch.tanh(self.pre_activation(obs, mask, pred))


class CBCCritic(RowScaled):
    """The centralised critic (Fig. 4b): a bidirectional LSTM across all pursuers, each cell
    holding that pursuer's global-state row (8), the evader's [position, velocity, obstacle
    vector] (6), its action (2), the predicted evader path relative to it (2k) and an alive
    flag; an MLP (64) on each cell's output gives that pursuer's Q. Rows are scaled as the
    actor's (:class:`RowScaled`)."""

    def __init__(
        self,
        hidden: int = 256,
        mlp_hidden: int = 64,
        pred_dim: int = 6,
        obstacle_scale: float = 1.0,
        target_scale: float = 1.0,
    ) -> None:
        super().__init__(pred_dim, obstacle_scale, target_scale)
        self.lstm = nn.LSTM(8 + 6 + 2 + pred_dim + 1, hidden, batch_first=True, bidirectional=True)
        self.head = mlp([2 * hidden, mlp_hidden, 1])

    def forward(self, state: Tensor, alive: Tensor, actions: Tensor, pred: Tensor | None) -> Tensor:
        """state (B, A, 8), alive (B, N), actions (B, N, 2), pred (B, k, 2) -> Q (B, N)."""
        n = alive.shape[-1]
        state = state * self.scale
        evader = state[:, -1:, :6].expand(-1, n, -1)
        parts = [state[:, :n], evader, actions * alive.unsqueeze(-1)]
        if self.pred_dim:
            rel = relative_prediction(pred, state, n) * self.target_scale
            parts.append(rel * alive.unsqueeze(-1))
        parts.append(alive.unsqueeze(-1).to(state.dtype))
        out, _ = self.lstm(torch.cat(parts, dim=-1))
        return self.head(out).squeeze(-1)


class PursuerActors(nn.Module):
    """One :class:`CBCActor` shared by all pursuers, or one per pursuer."""

    def __init__(self, lc: CBCNetConfig, num_pursuers: int) -> None:
        super().__init__()
        count = 1 if lc.shared else num_pursuers
        pred_dim = prediction_size(lc)
        self.nets = nn.ModuleList(
            CBCActor(lc.hidden, lc.mlp_hidden, pred_dim, lc.obstacle_scale, lc.target_scale)
            for _ in range(count)
        )

    def pre_activation(self, obs: Tensor, mask: Tensor, pred: Tensor | None) -> Tensor:
        """obs (B, N, N, 8), mask (B, N, N), pred (B, N, 2k) or None -> (B, N, 2) before the
        tanh."""
        b, n = obs.shape[:2]
        if len(self.nets) == 1:
            p = pred.flatten(0, 1) if pred is not None else None
            out = self.nets[0].pre_activation(obs.flatten(0, 1), mask.flatten(0, 1), p)
            return out.view(b, n, 2)
        return torch.stack(
            [
                net.pre_activation(obs[:, i], mask[:, i], pred[:, i] if pred is not None else None)
                for i, net in enumerate(self.nets)
            ],
            dim=1,
        )

    def forward(self, obs: Tensor, mask: Tensor, pred: Tensor | None) -> Tensor:
        """obs (B, N, N, 8), mask (B, N, N), pred (B, N, 2k) or None -> actions (B, N, 2)."""
        return torch.tanh(self.pre_activation(obs, mask, pred))

    def pre_activation_one(
        self, obs: Tensor, mask: Tensor, pred: Tensor | None, agent: Tensor
    ) -> Tensor:
        """One pursuer per sample, before the tanh: obs (B, N, 8), mask (B, N), pred (B, 2k),
        agent (B,) long -> (B, 2)."""
        if len(self.nets) == 1:
            return self.nets[0].pre_activation(obs, mask, pred)
        out = obs.new_zeros(obs.shape[0], 2)
        for i, net in enumerate(self.nets):
            rows = agent == i
            if bool(rows.any()):
                p = pred[rows] if pred is not None else None
                out[rows] = net.pre_activation(obs[rows], mask[rows], p)
        return out


class PursuerCritics(nn.Module):
    """One :class:`CBCCritic` shared by all pursuers, or one per pursuer (pursuer i reads its Q
    from its own critic's cell i)."""

    def __init__(self, lc: CBCNetConfig, num_pursuers: int) -> None:
        super().__init__()
        count = 1 if lc.shared else num_pursuers
        pred_dim = prediction_size(lc)
        self.nets = nn.ModuleList(
            CBCCritic(lc.hidden, lc.mlp_hidden, pred_dim, lc.obstacle_scale, lc.target_scale)
            for _ in range(count)
        )

    def forward(self, state: Tensor, alive: Tensor, actions: Tensor, pred: Tensor | None):
        """-> Q (B, N)."""
        if len(self.nets) == 1:
            return self.nets[0](state, alive, actions, pred)
        return torch.stack(
            [net(state, alive, actions, pred)[:, i] for i, net in enumerate(self.nets)], dim=1
        )


class CBCTPPolicy(DeterministicPolicy):
    """The trained swarm as a :class:`pes.policies.Policy`: TP Net's prediction from
    ``info["history"]``, then the actor on each pursuer's observation."""

    def __init__(self, actor: PursuerActors, tp: TPNet | None) -> None:
        super().__init__(actor)
        self.tp = tp

    def predict(self, info: dict[str, Tensor]) -> Tensor | None:
        """(E, k, 2) predicted normalised evader positions, or None without TP Net."""
        if self.tp is None:
            return None
        return self.tp(info["history"])

    def act(self, obs: Tensor, info: dict[str, Tensor]) -> Tensor:
        pred = self.predict(info)
        self.last_prediction = pred
        rel = None if pred is None else relative_prediction(pred, info["state"], obs.shape[1])
        return self.actor(obs, info["obs_mask"], rel)


class CBCNet(ActorCritic):
    """The CBC Net learner (``--algo cbc``): CBC-TP Net without TP Net (the ablation of §V-C)."""

    name = "cbc"
    Config = CBCNetConfig
    PRESETS = CBC_PRESETS
    TUNE_SPACE: ClassVar[dict[str, tuple]] = {
        **ActorCritic.TUNE_SPACE,
        "hidden": ("choice", [32, 64, 128]),
    }

    @staticmethod
    def make_actor(lc: CBCNetConfig, num_pursuers: int) -> nn.Module:
        return PursuerActors(lc, num_pursuers)

    @staticmethod
    def make_critic(lc: CBCNetConfig, num_pursuers: int) -> nn.Module:
        return PursuerCritics(lc, num_pursuers)

    @staticmethod
    def fixed_swarm(cfg: TrainConfig) -> str | None:
        return None if cfg.learner.shared else "has one network per pursuer"

    def actor_step(
        self, w: TDWindows, pred: Tensor | None, gen: torch.Generator, stats: dict[str, float]
    ) -> Tensor:
        """Actor (eq. 4). ``one``: in each sample one alive pursuer acts with the current actor
        and the others keep their stored actions (MADDPG's per-agent gradient); ``all``: every
        alive pursuer acts with it at once (the base class's centralised gradient), N times the
        gradient samples for one critic pass."""
        if self.lc.actor_gradient == "all" or (self.demonstrating() and self.bc_weight > 0):
            return super().actor_step(w, pred, gen, stats)
        obs, mask, rel = self.observe(w.state, w.alive, pred)
        # the sampler's generator lives on the CPU (one RNG stream whatever the device)
        weights = w.alive.float().cpu() + 1e-6
        pick = torch.multinomial(weights, 1, generator=gen).squeeze(1).to(w.state.device)
        b = torch.arange(len(w.row), device=w.state.device)
        rel = None if rel is None else rel[b, pick]
        pre = self.actor.pre_activation_one(obs[b, pick], mask[b, pick], rel, pick)
        chosen = torch.nn.functional.one_hot(pick, self.n).bool() & w.alive
        new_action = torch.where(chosen.unsqueeze(-1), torch.tanh(pre).unsqueeze(1), w.action)
        pre = pre.unsqueeze(1) * chosen.unsqueeze(-1)
        q_pi = self.frozen_critic(w.state, w.alive, new_action, pred)
        return self.actor_objective(q_pi, pre, chosen, new_action, w, stats)


class CBCTP(CBCNet):
    """The CBC-TP Net learner (``--algo cbc-tp``): CBC Net and TP Net."""

    name = "cbc-tp"
    Config = CBCTPConfig
    PRESETS = CBC_TP_PRESETS

    def __init__(self, cfg: TrainConfig, env_cfg: EnvConfig, device: torch.device) -> None:
        lc = cfg.learner
        self.tp = TPNet(lc.tp_hidden, lc.tp_layers, lc.horizon).to(device)
        self.opt_tp = adam(self.tp.parameters(), lc.lr_tp)
        self.history = env_cfg.history_length
        super().__init__(cfg, env_cfg, device)

    def make_policy(self) -> CBCTPPolicy:
        return CBCTPPolicy(self.actor, self.tp)

    def extra_fields(self) -> dict[str, tuple[tuple[int, ...], torch.dtype]]:
        """TP Net's predictions at s and s', inputs of the actor and the critic."""
        k = self.lc.horizon
        return {"pred": ((k, 2), torch.float32), "next_pred": ((k, 2), torch.float32)}

    @torch.no_grad()
    def extra_record(self, after: dict[str, Tensor]) -> dict[str, Tensor]:
        return {"pred": self.policy.last_prediction, "next_pred": self.tp(after["final_history"])}

    def predictions(self, w: TDWindows) -> tuple[Tensor | None, Tensor | None]:
        return self.buffer.get("pred", w.row, w.env), self.buffer.get("next_pred", w.last, w.env)

    def observe(
        self, state: Tensor, alive: Tensor, pred: Tensor | None
    ) -> tuple[Tensor, Tensor, Tensor | None]:
        obs, mask = pursuer_obs(state, alive)
        return obs, mask, relative_prediction(pred, state, self.n)

    def ready(self) -> bool:
        """Whether updates may start: TP Net as soon as a full window is stored."""
        lc = self.lc
        return len(self.buffer) >= max(lc.tp_batch_size, lc.batch_size) and (
            self.buffer.filled > self.history + lc.horizon + 1
        )

    def auxiliary_update(self, gen: torch.Generator) -> dict[str, float]:
        """One supervised TP Net step (eq. 7) on J windows, every ``tp_update_every`` updates;
        FDE/ADE in arena units."""
        if self.updates % self.lc.tp_update_every:
            return {}
        lc, buf, k = self.lc, self.buffer, self.lc.horizon
        row, env = buf.sample_index(lc.tp_batch_size, gen, past=self.history - 1, future=k)
        valid = buf.same_episode_ahead(row, env, k)
        hist = frames(buf.window("state", row, env, self.history))
        target = torch.stack(
            [buf.get("state", row, env, j)[:, -1, :2] for j in range(1, k + 1)], dim=1
        )
        pred = self.tp(hist)
        err = ((pred - target) ** 2).sum(-1)  # (B, k) squared distance
        loss = masked_mean(err.mean(-1), valid)
        optimise(self.opt_tp, loss, self.tp.parameters(), lc.grad_clip)
        with torch.no_grad():
            dist = err.sqrt()
            fde = masked_mean(dist[:, -1], valid)
            ade = masked_mean(dist.mean(-1), valid)
        return {"tp_loss": float(loss.detach()), "tp_fde": float(fde), "tp_ade": float(ade)}

    def modules(self) -> dict[str, nn.Module]:
        return super().modules() | {"tp": self.tp}

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return super().optimizers() | {"tp": self.opt_tp}

    def policy_modules(self) -> dict[str, nn.Module]:
        return {"actor": self.actor, "tp": self.tp}

    @classmethod
    def build_policy(cls, cfg: TrainConfig, env_cfg: EnvConfig, device) -> tuple[CBCTPPolicy, dict]:
        lc = cfg.learner
        actor = cls.make_actor(lc, env_cfg.num_pursuers).to(device)
        tp = TPNet(lc.tp_hidden, lc.tp_layers, lc.horizon).to(device)
        return CBCTPPolicy(actor, tp), {"actor": actor, "tp": tp}
