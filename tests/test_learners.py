"""The shared learning machinery: features rebuilt from the stored global state, the replay
buffer, the networks across swarm sizes, checkpoints, resumption after SIGKILL, learning."""

from __future__ import annotations

import csv
import json
import os
import random
import signal
import subprocess
import sys
import time

import pytest
import torch

import pes
from pes.algos import ALGOS, build_train_config, train
from pes.algos.cbc_tp import CBCTP, CBCActor, CBCCritic, TPNet
from pes.algos.evader_ddpg import EvaderDDPG
from pes.algos.loading import load_pursuer_policy
from pes.algos.ppo import PPO
from pes.cli import main
from pes.errors import CheckpointError, ConfigError
from pes.learn.buffer import ReplayBuffer, transition_fields
from pes.learn.checkpoint import save_atomic
from pes.learn.features import frames, pursuer_obs
from pes.learn.td import exit_charge
from pes.learn.trainer import init_networks
from pes.sim.bench import machine_info
from pes.sim.layout import make_layout
from tests.conftest import optional
from tests.learning import FAST, assert_learns


def test_observations_rebuilt_from_global_state():
    cfg = pes.EnvConfig(max_steps=30, damaged=2, crash_mode="disable")
    env = pes.make_env(cfg, num_envs=4, seed=3)
    obs, info = env.reset()
    for _ in range(12):
        rebuilt, mask = pursuer_obs(info["state"], info["obs_mask"][:, :, 0])
        assert torch.equal(mask, info["obs_mask"])
        torch.testing.assert_close(rebuilt, obs, rtol=0, atol=1e-6)
        obs, _, _, _, info = env.step(torch.rand(4, 5, 2) * 2 - 1)


def test_buffer_windows_match_the_environment_history():
    """History windows cut from the time-major buffer equal the env's own history, across
    episode ends (zero padding) and ring wrap-around."""
    cfg = pes.EnvConfig(max_steps=7, history_length=4)
    env = pes.make_env(cfg, num_envs=3, seed=0)
    buf = ReplayBuffer(3 * 9, 3, {"state": ((6, 8), torch.float32)})
    obs, info = env.reset()
    gen = torch.Generator().manual_seed(0)
    checked = 0
    for _ in range(30):
        before = info
        obs, _, _, _, info = env.step(torch.zeros(3, 5, 2))
        buf.add(state=before["state"], ep_step=(info["steps"] - 1).int())
        expect = before["history"]
        row = torch.full((3,), (buf.next_row - 1) % buf.rows)
        got = frames(buf.window("state", row, torch.arange(3), 4))
        torch.testing.assert_close(got, expect, rtol=0, atol=0)
        # the next-state window ends with the (pre-reset) next state
        nxt = frames(buf.window("state", row, torch.arange(3), 4, last=info["final_state"]))
        torch.testing.assert_close(nxt, info["final_history"], rtol=0, atol=0)
        checked += 1
    assert checked == 30 and buf.filled == buf.rows
    row, env_i = buf.sample_index(64, gen, past=3, future=2)
    ok = buf.same_episode_ahead(row, env_i, 2)
    assert ok.any() and (~ok).any()


def test_buffer_bytes_per_transition_and_state_roundtrip():
    learner = CBCTP(build_train_config("cbc-tp", "paper", FAST), pes.EnvConfig(), "cpu")
    per = learner.buffer.bytes_per_transition
    assert per < 600  # one global state (and next state), not N observations
    assert per * 1_000_000 < 1e9
    buf = ReplayBuffer(40, 4, {"x": ((2,), torch.float32)})
    for i in range(13):
        buf.add(x=torch.full((4, 2), float(i)), ep_step=torch.full((4,), i, dtype=torch.int32))
    clone = ReplayBuffer(40, 4, {"x": ((2,), torch.float32)})
    clone.load_state_dict(buf.state_dict())
    assert clone.next_row == buf.next_row and torch.equal(clone.data["x"], buf.data["x"])


def test_n_step_windows_stop_where_the_episode_ends_or_a_pursuer_leaves():
    """One environment's column: an episode that terminates at its step 3, one truncated after
    step 1 (the next row starts a new episode), then one where pursuer 1 leaves at step 1."""
    buf = ReplayBuffer(16, 1, transition_fields(2))
    ep_steps = [0, 1, 2, 3, 0, 1, 0, 1, 2, 3]
    terminated = [0, 0, 0, 1, 0, 0, 0, 0, 0, 0]
    next_alive = [[1, 1]] * 7 + [[1, 0]] + [[1, 0]] * 2
    alive = [[1, 1]] * 8 + [[1, 0]] * 2
    for i, step in enumerate(ep_steps):
        buf.add(
            state=torch.zeros(1, 3, 8),
            alive=torch.tensor([alive[i]], dtype=torch.bool),
            action=torch.zeros(1, 2, 2),
            reward=torch.tensor([[float(i + 1), 10.0 * (i + 1)]]),
            next_state=torch.zeros(1, 3, 8),
            next_alive=torch.tensor([next_alive[i]], dtype=torch.bool),
            terminated=torch.tensor([bool(terminated[i])]),
            ep_step=torch.tensor([step], dtype=torch.int32),
        )
    row = torch.tensor([0, 2, 3, 4, 5, 6, 7])
    env = torch.zeros_like(row)
    ret, last, length = buf.n_step(row, env, 3, 0.5)
    # row 0: three steps; row 2: stops at the termination (row 3); row 4: at the truncation
    # (row 6 starts a new episode); row 6: at the exit of pursuer 1 (row 7)
    assert last.tolist() == [2, 3, 3, 5, 5, 7, 7]
    assert length.tolist() == [3, 2, 1, 2, 1, 2, 1]
    expected = [1 + 0.5 * 2 + 0.25 * 3, 3 + 0.5 * 4, 4, 5 + 0.5 * 6, 6, 7 + 0.5 * 8, 8]
    assert torch.allclose(ret[:, 0], torch.tensor(expected))
    assert torch.allclose(ret[:, 1], 10 * torch.tensor(expected))
    one_ret, one_last, one_length = buf.n_step(row, env, 1, 0.5)
    assert torch.equal(one_last, row) and torch.equal(one_ret, buf.get("reward", row, env))
    assert one_length.tolist() == [1] * 7
    # the learners whose update is not CBC-TP's or MADDPG's refuse them
    with pytest.raises(ConfigError, match="n_step"):
        build_train_config("maac", "tiny", {"n_step": 0})


@pytest.mark.parametrize("n", [1, 3, 5, 8])
def test_one_network_serves_any_swarm_size(n):
    torch.manual_seed(0)
    actor, critic, tp = CBCActor(16, 16, 6), CBCCritic(16, 16, 6), TPNet(16, 2, 3)
    env = pes.make_env(pes.EnvConfig(num_pursuers=n, capture_count=min(3, n)), 2, seed=1)
    obs, info = env.reset()
    pred = tp(info["history"])
    assert pred.shape == (2, 3, 2)
    a = actor(obs.flatten(0, 1), info["obs_mask"].flatten(0, 1), torch.zeros(2 * n, 6))
    assert a.shape == (2 * n, 2) and a.abs().max() <= 1
    q = critic(info["state"], info["obs_mask"][:, :, 0], a.view(2, n, 2), pred)
    assert q.shape == (2, n) and torch.isfinite(q).all()


def test_tp_net_ignores_pursuer_order():
    torch.manual_seed(0)
    tp = TPNet(16, 2, 3)
    hist = torch.randn(4, 10, 6, 4)
    perm = hist[:, :, [3, 0, 4, 1, 2, 5]]
    torch.testing.assert_close(tp(hist), tp(perm))


def test_checkpoint_errors(tmp_path):
    cfg = pes.EnvConfig()
    missing = tmp_path / "none.pt"
    with pytest.raises(CheckpointError, match="no checkpoint"):
        load_pursuer_policy(missing, cfg)
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"\x80\x03garbage" * 10)
    with pytest.raises(CheckpointError, match="corrupted"):
        load_pursuer_policy(bad, cfg)
    other = tmp_path / "other.pt"
    save_atomic({"weights": torch.zeros(3)}, other)
    with pytest.raises(CheckpointError, match="not a PES"):
        load_pursuer_policy(other, cfg)


def _tiny(out, protocol_name="paper", **values):
    cfg = build_train_config("cbc-tp", "tiny", dict(FAST, **values), protocol=protocol_name)
    return train(cfg, out, progress=False)


def test_a_run_names_its_cpu_by_model_family_and_vector_instructions():
    """Two CPUs that a virtual machine names alike ("AMD EPYC") are told apart by their
    family and model numbers and their widest vector instructions."""
    from pes.sim.bench import cpu_model

    def info(model: str, flags: str) -> str:
        first = f"processor\t: 0\nmodel name\t: AMD EPYC\ncpu family\t: 25\nmodel\t\t: {model}\n"
        return first + f"flags\t\t: fpu sse2 {flags}\n\nprocessor\t: 1\nmodel\t\t: 99\n"

    assert cpu_model(info("1", "avx avx2")) == "AMD EPYC (family 25, model 1, AVX2)"
    assert cpu_model(info("17", "avx avx2 avx512f")) == "AMD EPYC (family 25, model 17, AVX-512)"
    assert cpu_model("model name\t: Apple M2\n") == "Apple M2"
    assert cpu_model("processor\t: 0\nBogoMIPS\t: 50.00\n") is None


def test_train_writes_a_run_and_the_policy_evaluates(tmp_path, capsys):
    summary = _tiny(tmp_path / "run", episodes=16, eval_episodes=4)
    for name in ("config.yaml", "progress.csv", "checkpoint.pt", "policy.pt", "summary.json"):
        assert (tmp_path / "run" / name).is_file(), name
    assert summary["eval"]["episodes"] == 4
    assert summary["torch_threads"] == torch.get_num_threads()  # recorded with the CPU time
    assert summary["cpus"] == [machine_info()["cpu"]]  # and the CPU that spent it
    header = (tmp_path / "run" / "progress.csv").read_text().splitlines()[0]
    assert "success_rate" in header and "tp_fde" in header and "updates_per_s" in header
    # pes eval takes the run folder, the policy file or the checkpoint
    for spec in ("run", "run/policy.pt", "run/checkpoint.pt"):
        argv = [
            "eval",
            "--policy",
            str(tmp_path / spec),
            "--episodes",
            "2",
            "--json",
            "--set",
            "max_steps=20",
        ]
        assert main(argv) == 0
        assert json.loads(capsys.readouterr().out)["episodes"] == 2
    # starting again into the same folder without --resume is refused
    with pytest.raises(ConfigError, match="--resume"):
        _tiny(tmp_path / "run", episodes=16)


def test_all_pursuer_actor_gradient_trains(tmp_path):
    summary = _tiny(tmp_path / "all", episodes=8, eval_episodes=0, actor_gradient="all")
    assert summary["updates"] > 0 and (tmp_path / "all" / "policy.pt").is_file()
    with pytest.raises(ConfigError, match="actor_gradient"):
        build_train_config("cbc-tp", "tiny", {"actor_gradient": "some"})


def test_exits_are_charged_their_last_reward_for_the_steps_to_come(tmp_path):
    # Sample 0: pursuer 1 crashes (disabled), three fly on. Sample 1: pursuer 0 crashes and
    # the episode fails with two left: all three alive in s leave. Sample 2: a capture.
    reward = torch.tensor([[-1.0, -4.0, -1.0, -1.0], [-3.5, -1.5, -1.0, 0.0], [4.0, 4.0, 4.0, 4.0]])
    alive = torch.tensor([[1, 1, 1, 1], [1, 1, 1, 0], [1, 1, 1, 1]], dtype=torch.bool)
    next_alive = torch.tensor([[1, 0, 1, 1], [0, 1, 1, 0], [1, 1, 1, 1]], dtype=torch.bool)
    terminated = torch.tensor([False, True, True])
    charge = exit_charge(reward, alive, next_alive, terminated, 0.95, 3, crash_reward=-2.0)
    factor = 0.95 / 0.05
    expected = torch.tensor(
        [[0.0, -2.0 * factor, 0.0, 0.0], [-1.5 * factor, -1.5 * factor, -factor, 0.0], [0.0] * 4]
    )
    assert torch.allclose(charge, expected)
    run = tmp_path / "exits"
    summary = _tiny(
        run,
        episodes=8,
        eval_episodes=0,
        # exits end the n-step windows, and are charged at their last transition
        protocol={"n_step": 3, "crash_curriculum": {"disable_at": 0.0, "charge_exits": True}},
    )
    assert summary["updates"] > 0


def test_evader_speed_curriculum_rises_with_success(tmp_path):
    """Every episode is a capture (one pursuer within 500 m for one step), so every log row
    raises the evader's cap by a step, up to the configured top speed."""
    easy = dict(max_steps=20, capture_count=1, capture_radius=500.0, capture_hold=1)
    run = dict(
        episodes=40,
        log_every=8,
        eval_episodes=0,
        protocol={"speed_curriculum": {"start": 9.0, "step": 1.0, "success": 0.5}},
        env=dict(easy, evader_max_speed=11.0),
    )

    def speeds(out) -> list[float]:
        rows = (out / "progress.csv").read_text().splitlines()
        col = rows[0].split(",").index("evader_speed")
        return [float(r.split(",")[col]) for r in rows[1:]]

    _tiny(tmp_path / "cur", **run)
    assert speeds(tmp_path / "cur") == [9.0, 10.0, 11.0, 11.0, 11.0]
    # Rows that PID(PF) demonstrated (the first two vector steps, 16 one-step episodes) measure
    # the demonstrator: they leave the cap where it is.
    demo = dict(run, protocol=dict(run["protocol"], demonstrations={"transitions": 16}))
    _tiny(tmp_path / "demo", **demo)
    assert speeds(tmp_path / "demo") == [9.0, 9.0, 9.0, 10.0, 11.0]
    for bad in ({"start": 13.0}, {"step": 0.0}):
        with pytest.raises(ConfigError, match="curriculum"):
            build_train_config("cbc-tp", "tiny", {"protocol.speed_curriculum": bad})
    env = pes.make_env(pes.EnvConfig(), num_envs=2, seed=0)
    with pytest.raises(ConfigError, match="evader speed"):
        env.set_evader_max_speed(12.5)


def test_crashes_disable_once_training_success_reaches_the_threshold(tmp_path, monkeypatch):
    """Every episode is a capture (as above), so the first log row the learner played
    switches the crash rule: the environments are rebuilt with crashes that disable, the
    switch is logged and kept in the checkpoint, and a resumed run plays by the new rule."""
    import pes.learn.trainer as trainer  # noqa: PLC0415

    modes: list[str] = []
    make_env = trainer.make_env

    def recording_make_env(env_cfg, **kwargs):
        modes.append(env_cfg.crash_mode)
        return make_env(env_cfg, **kwargs)

    monkeypatch.setattr(trainer, "make_env", recording_make_env)
    easy = dict(max_steps=20, capture_count=1, capture_radius=500.0, capture_hold=1)
    curriculum = {"crash_curriculum": {"disable_at": 0.5, "charge_exits": False}}
    run = dict(log_every=8, eval_episodes=0, env=easy)

    def switched(out) -> list[int]:
        with open(out / "progress.csv", newline="") as f:
            return [int(r["crashes_disable"]) for r in csv.DictReader(f)]

    _tiny(tmp_path / "run", episodes=24, protocol=curriculum, **run)
    assert modes == ["continue", "disable"]
    assert switched(tmp_path / "run") == [0, 1, 1]
    checkpoint = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=False)
    assert checkpoint["progress"]["crashes_disable"] is True
    cfg = build_train_config(
        "cbc-tp", "tiny", dict(FAST, episodes=40, protocol=curriculum, **run), protocol="paper"
    )
    train(cfg, tmp_path / "run", resume=True, progress=False)
    assert modes == ["continue", "disable", "disable"]
    # Rows that PID(PF) demonstrated measure the demonstrator: they do not switch the rule.
    modes.clear()
    demo = {**curriculum, "demonstrations": {"transitions": 16}}
    _tiny(tmp_path / "demo", episodes=32, protocol=demo, **run)
    assert switched(tmp_path / "demo") == [0, 0, 0, 1]
    assert modes == ["continue", "disable"]
    started_disabled = {"protocol": curriculum, "env": dict(crash_mode="disable")}
    for bad in ({"protocol.crash_curriculum.disable_at": 1.5}, started_disabled):
        with pytest.raises(ConfigError, match="crash_curriculum"):
            build_train_config("cbc-tp", "tiny", bad)


def test_init_from_a_checkpoint_copies_every_network(tmp_path):
    _tiny(tmp_path / "src", episodes=8, eval_episodes=0)
    source = torch.load(tmp_path / "src" / "checkpoint.pt", weights_only=True)["modules"]
    cfg = build_train_config(
        "cbc-tp", "tiny", dict(FAST, init_from=str(tmp_path / "src")), protocol="paper"
    )
    learner = CBCTP(cfg, cfg.env_config(), torch.device("cpu"))
    init_networks(learner, cfg)
    for name, module in learner.modules().items():
        for key, value in module.state_dict().items():
            assert torch.equal(value, source[name][key]), (name, key)
    # A run started from it records which checkpoint, with its counters.
    summary = _tiny(tmp_path / "dst", episodes=8, eval_episodes=0, init_from=str(tmp_path / "src"))
    source_summary = json.loads((tmp_path / "src" / "summary.json").read_text())
    record = json.loads((tmp_path / "dst" / "init_from.json").read_text())
    assert record["path"] == str((tmp_path / "src" / "checkpoint.pt").resolve())
    assert record["progress"]["episodes"] == source_summary["episodes"]
    assert summary["episodes"] >= 8
    other = build_train_config("maddpg", "tiny", dict(FAST, init_from=str(tmp_path / "src")))
    with pytest.raises(CheckpointError, match="holds a cbc-tp run"):
        train(other, tmp_path / "other", progress=False)


def test_init_from_a_policy_file_gives_the_acting_networks(tmp_path):
    """A policy file gives the actor, its target copy and TP Net; the critic starts fresh."""
    _tiny(tmp_path / "src", episodes=8, eval_episodes=0)
    policy_file = tmp_path / "src" / "policy.pt"
    source = torch.load(policy_file, weights_only=True)["policy"]
    cfg = build_train_config(
        "cbc-tp", "tiny", dict(FAST, init_from=str(policy_file)), protocol="paper"
    )
    learner = CBCTP(cfg, cfg.env_config(), torch.device("cpu"))
    fresh_critic = {k: v.clone() for k, v in learner.critic.state_dict().items()}
    record = init_networks(learner, cfg)
    assert record["loaded"] == ["actor", "actor_target", "tp"]
    for name in record["loaded"]:
        for key, value in learner.modules()[name].state_dict().items():
            assert torch.equal(value, source[name.removesuffix("_target")][key]), (name, key)
    for key, value in learner.critic.state_dict().items():
        assert torch.equal(value, fresh_critic[key]), key

    summary = _tiny(
        tmp_path / "dst",
        episodes=8,
        eval_episodes=0,
        init_from=str(policy_file),
    )
    assert summary["updates"] > 0


def test_demonstrations_fill_the_buffer_and_are_cloned():
    """PID(PF) plays the first demo_transitions (marked in the buffer); the BC term then pulls
    the actor towards PID(PF)'s actions."""
    values = dict(
        FAST,
        lr_actor=3e-3,
        warmup=400,
        batch_size=128,
        protocol={
            "demonstrations": {"policy": "pid-pf", "transitions": 800, "bc_weight": 5.0},
            "noise": {"sigma": 0.0, "sigma_final": 0.0},
        },
    )
    cfg = build_train_config("cbc-tp", "tiny", values, protocol="paper")
    env_cfg = cfg.env_config()
    learner = CBCTP(cfg, env_cfg, torch.device("cpu"))
    env = pes.make_env(env_cfg, num_envs=cfg.num_envs, seed=0)
    pid = pes.policies.PIDPotentialField(env_cfg)
    gen = torch.Generator().manual_seed(0)
    obs, info = env.reset()
    learner.episode_reset(torch.ones(cfg.num_envs, dtype=torch.bool))
    probes = []
    for step in range(150):
        actions, _ = learner.act(obs, info, 0.0, gen)
        expected = pid(obs, info)
        if step < 100:  # 800 transitions of 8 environments: PID(PF) plays
            torch.testing.assert_close(actions, expected.clamp(-1, 1))
            probes.append((obs, info, expected.clamp(-1, 1)))
        obs2, reward, term, trunc, info2 = env.step(actions)
        learner.record(info, actions, None, reward, term, info2)
        done = term | trunc
        if bool(done.any()):
            learner.episode_reset(done)
            pid.reset(done)
        obs, info = obs2, info2
    flags = learner.buffer.data["demo"][: learner.buffer.filled]
    assert bool(flags[:100].all()) and not bool(flags[100:].any())

    def gap() -> float:
        with torch.no_grad():
            return sum(
                float(((learner.policy.act(o, i) - a) ** 2).mean()) for o, i, a in probes[::10]
            )

    before = gap()
    shares = [learner.update(gen).get("bc_share", 0.0) for _ in range(300)]
    assert 0.5 < shares[-1] < 1.0  # 800 of the 1200 transitions are demonstrations
    assert gap() < 0.75 * before  # without the BC term it grows (x1.8 in 300 updates)
    with pytest.raises(ConfigError, match="demonstrations.policy"):
        build_train_config("maddpg", "tiny", {"protocol.demonstrations.policy": "flee"})
    with pytest.raises(ConfigError, match="demonstrations"):
        build_train_config("cbc-tp", "tiny", {"protocol.demonstrations.transitions": -1})


def test_demonstrations_end_when_the_buffer_is_full():
    """demo_transitions = buffer_size, which whole steps of 8 environments cannot fill exactly
    (1004 -> 125 steps = 1000 transitions): the demonstrator still hands over."""
    values = dict(FAST, buffer_size=1004, protocol={"demonstrations": {"transitions": 1004}})
    cfg = build_train_config("cbc-tp", "tiny", values, protocol="paper")
    env_cfg = cfg.env_config()
    learner = CBCTP(cfg, env_cfg, torch.device("cpu"))
    env = pes.make_env(env_cfg, num_envs=cfg.num_envs, seed=0)
    obs, info = env.reset()
    gen = torch.Generator().manual_seed(0)
    learner.episode_reset(torch.ones(cfg.num_envs, dtype=torch.bool))
    for _ in range(125):
        assert learner.demonstrating()
        actions, _ = learner.act(obs, info, 0.0, gen)
        obs2, reward, term, trunc, info2 = env.step(actions)
        learner.record(info, actions, None, reward, term, info2)
        obs, info = obs2, info2
    assert len(learner.buffer) == 1000 and not learner.demonstrating()


def test_greedy_envs_act_without_noise():
    """The last greedy_envs share of the environments plays the actor's own action; the others
    add OU noise."""
    cfg = build_train_config("cbc-tp", "tiny", dict(FAST, greedy_envs=0.25), protocol="paper")
    env_cfg = cfg.env_config()
    learner = CBCTP(cfg, env_cfg, torch.device("cpu"))
    env = pes.make_env(env_cfg, num_envs=cfg.num_envs, seed=0)
    obs, info = env.reset()
    gen = torch.Generator().manual_seed(0)
    noisy, _ = learner.act(obs, info, 0.5, gen)
    with torch.no_grad():
        clean = learner.policy.act(obs, info).clamp(-1.0, 1.0)
    torch.testing.assert_close(noisy[6:], clean[6:])
    assert float((noisy[:6] - clean[:6]).abs().min(-1).values.mean()) > 0.0
    with pytest.raises(ConfigError, match="greedy_envs"):
        build_train_config("cbc-tp", "tiny", {"greedy_envs": 1.5})
    assert PPO.aids(cfg.protocol)["greedy_envs"].startswith("not applied")


def test_mismatched_checkpoint_is_refused(tmp_path, capsys):
    _tiny(tmp_path / "run", episodes=8, eval_episodes=0)
    with pytest.raises(CheckpointError, match="different settings"):
        cfg = build_train_config("cbc-tp", "tiny", dict(FAST, hidden=48, episodes=16))
        train(cfg, tmp_path / "run", resume=True, progress=False)
    # per-pursuer networks cannot serve another swarm size
    _tiny(tmp_path / "per", episodes=8, eval_episodes=0, shared=False)
    with pytest.raises(CheckpointError, match="per pursuer"):
        load_pursuer_policy(tmp_path / "per", pes.EnvConfig(num_pursuers=4))
    # through the command line: one line, exit 2
    (tmp_path / "broken.pt").write_bytes(b"not a checkpoint")
    assert main(["eval", "--policy", str(tmp_path / "broken.pt"), "--episodes", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "corrupted" in err[0]


@pytest.mark.slow
def test_cbc_tp_learns_on_a_tiny_budget(tmp_path):
    """Fixed seed, ~80 s: the identity-style capture task of tests/learning.py."""
    assert_learns("cbc-tp", tmp_path / "run", episodes=200)


def test_ddpg_evader_trains_and_plays_inside_the_env(tmp_path, capsys):
    cfg = build_train_config("evader-ddpg", "tiny", dict(FAST, episodes=16, eval_episodes=4))
    summary = train(cfg, tmp_path / "ev", progress=False)
    assert summary["eval"]["opponent"] == "pid-pf"
    model = str(tmp_path / "ev" / "policy.pt")
    for compile_step in (False, True):
        env_cfg = pes.EnvConfig(evader_policy="ddpg", evader_model=model, max_steps=30)
        env = pes.make_env(env_cfg, num_envs=2, seed=0, compile=compile_step)
        env.reset()
        for _ in range(3):
            *_, info = env.step(torch.zeros(2, 5, 2))
        assert info["velocities"][:, -1].norm(dim=-1).max() > 0  # the network moves it
    argv = [
        "eval",
        "--policy",
        "pid-pf",
        "--episodes",
        "2",
        "--json",
        "--set",
        "evader_policy=ddpg",
        "--set",
        f"evader_model={model}",
        "--set",
        "max_steps=20",
    ]
    assert main(argv) == 0
    assert json.loads(capsys.readouterr().out)["evader"] == "ddpg"
    # a pursuer checkpoint is not an evader
    _tiny(tmp_path / "pursuers", episodes=8, eval_episodes=0)
    with pytest.raises(CheckpointError, match="not a DDPG evader"):
        pes.make_env(
            pes.EnvConfig(
                evader_policy="ddpg", evader_model=str(tmp_path / "pursuers" / "policy.pt")
            )
        )


def test_the_evader_trains_against_pid_pf_on_its_own_map():
    env_cfg = pes.EnvConfig(removed_blocks=[], pursuer_max_speed=8.0)
    learner = EvaderDDPG(build_train_config("evader-ddpg", "tiny", FAST), env_cfg, "cpu")
    boxes = len(make_layout(env_cfg).boxes)
    assert boxes != len(make_layout(pes.EnvConfig()).boxes)
    assert len(learner.pursuers.boxes) == boxes
    assert learner.pursuers.env_config.pursuer_max_speed == 8.0


def _untimed_rows(path) -> list[dict]:
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    timing = {"wall_s", "cpu_s", "env_steps_per_s", "updates_per_s"}
    return [{k: v for k, v in row.items() if k not in timing} for row in rows]


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["cbc-tp", "ppo"])
def test_sigkill_at_random_moments_resumes_exactly(algo, tmp_path):
    """Kill a real training process with SIGKILL at random moments, resuming after each: the
    log rows, counters and final weights equal those of an uninterrupted run of the same seed
    (timing columns aside). Checkpoints are written every few steps, so some kills land in a
    checkpoint's write; each process is killed once it has written a checkpoint of its own and
    logged one or two rows more (two environments and a row every two episodes: some 24 rows,
    which take 5 or more kills on any machine, as the kills follow the run's progress, not the
    clock)."""
    argv = [sys.executable, "-m", "pes.cli", "train", "--algo", algo, "--preset", "tiny"]
    for text in (
        "compile_env=false",
        "tensorboard=false",
        "episodes=48",
        "num_envs=2",
        "checkpoint_every=0.0005",
        "eval_episodes=0",
        "log_every=2",
        "threads=1",
    ):
        argv += ["--set", text]
    whole = tmp_path / "whole"
    assert subprocess.run([*argv, "--out", str(whole)], capture_output=True).returncode == 0
    out, ckpt = tmp_path / "killed", tmp_path / "killed" / "checkpoint.pt"

    def rows() -> int:
        log = out / "progress.csv"
        return len(log.read_text().splitlines()) if log.is_file() else 0

    rng = random.Random(0)
    kills = 0
    while kills < 12:
        resume = ["--resume"] if ckpt.is_file() else []
        before = ckpt.stat().st_mtime_ns if ckpt.is_file() else 0
        proc = subprocess.Popen([*argv, "--out", str(out), *resume], stdout=subprocess.DEVNULL)
        while proc.poll() is None and (not ckpt.is_file() or ckpt.stat().st_mtime_ns == before):
            time.sleep(0.002)  # until this process has written a checkpoint of its own
        target = rows() + rng.randint(1, 2)
        while proc.poll() is None and rows() < target:
            time.sleep(0.002)
        time.sleep(rng.uniform(0.0, 0.02))
        if proc.poll() is not None:
            break  # it finished first: the run is done
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        kills += 1
    assert kills >= 5, f"the run finished after {kills} kills"
    done = subprocess.run([*argv, "--out", str(out), "--resume"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert _untimed_rows(out / "progress.csv") == _untimed_rows(whole / "progress.csv")
    counters = ("episodes", "env_steps", "updates")
    a, b = (json.loads((run / "summary.json").read_text()) for run in (out, whole))
    assert [a[k] for k in counters] == [b[k] for k in counters]
    mine = torch.load(out / "policy.pt", weights_only=True)["policy"]
    theirs = torch.load(whole / "policy.pt", weights_only=True)["policy"]
    for name, state in theirs.items():
        for key, value in state.items():
            assert torch.equal(mine[name][key], value), (name, key)
    assert not list(out.glob(".*.tmp"))  # a killed writer's temporary files are gone


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupt_stops_the_run_with_its_files_written(sig, tmp_path):
    """Ctrl-C (SIGINT) or SIGTERM: the run stops at its next step with a checkpoint, policy.pt
    and summary.json written, exits with 130 and one line, and --resume finishes it."""
    out = tmp_path / "run"
    argv = [sys.executable, "-m", "pes.cli", "train", "--algo", "cbc-tp", "--preset", "tiny"]
    for text in ("compile_env=false", "tensorboard=false", "episodes=400", "eval_episodes=0"):
        argv += ["--set", text]
    proc = subprocess.Popen(
        [*argv, "--out", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    # Into the training loop: its first log row is written (the first steps load the
    # simulator's compiled kernel, which can take seconds on a busy machine).
    log = out / "progress.csv"
    while proc.poll() is None and not (log.is_file() and len(log.read_text().splitlines()) > 1):
        time.sleep(0.05)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err
    last = err.strip().splitlines()[-1]  # after the progress bar, one line
    assert last.startswith("stopped:") and "--resume" in last and "Traceback" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stopped_by"] == "interrupted" and summary["episodes"] < 400
    assert (out / "checkpoint.pt").is_file() and (out / "policy.pt").is_file()
    done = subprocess.run(
        [*argv, "--set", "episodes=16", "--out", str(out), "--resume"], capture_output=True
    )
    assert done.returncode == 0


def test_a_fresh_run_into_a_used_folder_keeps_no_earlier_logs(tmp_path):
    """A run started without --resume in a folder that holds an earlier run's logs (a trial
    whose checkpoint was lost) writes its CSV and TensorBoard events anew, not beside them."""
    optional("torch.utils.tensorboard")
    values = {"episodes": 8, "threads": 1, "eval_episodes": 0, "tensorboard": True}
    out = tmp_path / "run"
    train(build_train_config("ppo", "tiny", values), out, progress=False)
    assert list((out / "tb").glob("events.out.tfevents.*"))
    (out / "checkpoint.pt").unlink()  # lost, as a trial's checkpoint moved to another machine
    earlier = out / "tb" / "events.out.tfevents.1.earlier-run"  # a name no writer reuses
    earlier.write_bytes(b"")
    train(build_train_config("ppo", "tiny", values), out, progress=False)
    assert not earlier.exists()
    assert len(list((out / "tb").glob("events.out.tfevents.*"))) == 1
    rows = (out / "progress.csv").read_text().splitlines()
    episodes = [int(r.split(",")[0]) for r in rows[1:]]
    assert episodes == sorted(set(episodes))


def test_env_steps_stop_a_run_at_its_experience_budget_and_resume_with_it(tmp_path):
    """``env_steps`` stops a run at the first step that reaches it (steps of ``num_envs``
    environments at once), on every machine alike, and a resumed run at a larger one."""
    values = {"episodes": 10**6, "env_steps": 300, "threads": 1, "eval_episodes": 0}
    cfg = build_train_config("ppo", "tiny", values)
    summary = train(cfg, tmp_path / "run", progress=False)
    step = cfg.num_envs
    assert summary["stopped_by"] == "env_steps"
    assert 300 <= summary["env_steps"] < 300 + step
    longer = build_train_config("ppo", "tiny", dict(values, env_steps=700))
    resumed = train(longer, tmp_path / "run", resume=True, progress=False)
    assert resumed["stopped_by"] == "env_steps"
    assert 700 <= resumed["env_steps"] < 700 + step
    assert resumed["cpus"] == summary["cpus"] == [machine_info()["cpu"]]  # one machine, once
    # a checkpoint written before runs recorded their CPUs: the earlier part's CPU is unknown
    ckpt = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=False)
    del ckpt["progress"]["cpus"]
    save_atomic(ckpt, tmp_path / "run" / "checkpoint.pt")
    further = build_train_config("ppo", "tiny", dict(values, env_steps=900))
    again = train(further, tmp_path / "run", resume=True, progress=False)
    assert again["cpus"] == ["unrecorded CPU", machine_info()["cpu"]]


def test_cpu_limit_stops_a_run_by_its_cpu_time_and_resumes_with_it(tmp_path):
    """``cpu_limit`` counts the process's CPU time (what a run shares with nothing else), is
    kept by the checkpoint and stops the resumed run at the same total; ``cpu_scale`` stretches
    it for a slower CPU."""
    limit = 0.05  # minutes: 3 s of CPU time
    values = {"episodes": 10**6, "cpu_limit": limit, "threads": 1, "eval_episodes": 0}
    cfg = build_train_config("ppo", "tiny", values)
    summary = train(cfg, tmp_path / "run", progress=False)
    assert summary["stopped_by"] == "cpu_limit"
    assert 60 * limit <= summary["cpu_s"] < 60 * limit + 30
    longer = build_train_config("ppo", "tiny", dict(values, cpu_limit=2 * limit))
    resumed = train(longer, tmp_path / "run", resume=True, progress=False)
    assert resumed["stopped_by"] == "cpu_limit" and resumed["env_steps"] > summary["env_steps"]
    assert 120 * limit <= resumed["cpu_s"] < 120 * limit + 30
    # On a CPU 1.5 times slower than the limit's reference the same limit buys 1.5x the time.
    slower = build_train_config("ppo", "tiny", dict(values, cpu_limit=2 * limit, cpu_scale=1.5))
    scaled = train(slower, tmp_path / "run", resume=True, progress=False)
    assert scaled["stopped_by"] == "cpu_limit" and scaled["cpu_scale"] == 1.5
    assert 180 * limit <= scaled["cpu_s"] < 180 * limit + 30
    assert scaled["env_steps"] > resumed["env_steps"]


@pytest.mark.parametrize("algo", sorted(ALGOS))
def test_the_gpu_preset_keeps_the_quick_settings_and_runs_on_a_cpu(algo, tmp_path):
    """Every learner's ``gpu`` preset: its quick preset's learning settings, thousands of
    environments on ``cuda``, a replay learner's update ratio unchanged (each env step replayed
    as often), ten times the budget; and it trains on a CPU at tiny sizes."""
    quick, gpu = (build_train_config(algo, preset) for preset in ("quick", "gpu"))
    assert gpu.device == "cuda" and gpu.num_envs >= 1024
    assert gpu.env_steps == 10 * quick.env_steps and gpu.episodes >= quick.episodes
    q, g = quick.learner, gpu.learner
    for key in ("gamma", "lr_actor", "lr_critic", "hidden", "mlp_hidden", "tau", "ppo_epochs"):
        assert getattr(g, key, None) == getattr(q, key, None), key
    if ALGOS[algo].on_policy:
        assert g.rollout_steps * gpu.num_envs >= 100_000
    else:
        assert g.batch_size / g.update_every == q.batch_size / q.update_every
    sizes = dict(device="cpu", num_envs=8, episodes=3, env_steps=0, eval_episodes=2)
    sizes |= {"compile_env": False, "tensorboard": False, "env.max_steps": 60}
    if ALGOS[algo].on_policy:
        sizes |= dict(rollout_steps=16, batch_size=32)
    else:
        sizes |= dict(batch_size=32, warmup=200, buffer_size=2000, update_every=8)
    if algo == "cbc-tp":
        sizes |= dict(tp_batch_size=32)
    if "demonstrations" in build_train_config(algo, "gpu").protocol.active():
        sizes["protocol.demonstrations.transitions"] = 200
    summary = train(build_train_config(algo, "gpu", sizes), tmp_path / algo, progress=False)
    assert summary["episodes"] >= 3 and summary["updates"] > 0
