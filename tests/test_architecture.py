"""The structure of the code: which layer imports which, that every learner's settings are
read by that learner, and that every Table IV learner trains under both protocols."""

from __future__ import annotations

import ast
import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import yaml

import pes
from pes.algos import ALGOS, TABLE4_ALGOS, build_train_config, learner_class
from pes.cli import main
from pes.errors import ConfigError
from pes.learn.config import LearnerConfig
from pes.learn.protocol import PES
from tests.learning import FAST

SRC = Path(pes.__file__).resolve().parent


def imports_of(path: Path) -> set[str]:
    """Every ``pes...`` module a file imports, at any depth of its code (function bodies too)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.startswith("pes"))
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("pes"):
            found.add(node.module)
            found.update(f"{node.module}.{a.name}" for a in node.names)
    return found


def module_name(path: Path) -> str:
    parts = path.relative_to(SRC.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def test_the_simulator_imports_no_layer_above_it_and_learn_no_method():
    above_sim = ("pes.learn", "pes.algos", "pes.experiments", "pes.record", "pes.cli")
    for path in sorted((SRC / "sim").rglob("*.py")):
        bad = sorted(m for m in imports_of(path) if m.startswith(above_sim))
        assert not bad, f"{path.name} imports {bad}"
    above_learn = ("pes.algos", "pes.experiments", "pes.record", "pes.cli", "pes.torchrl")
    for path in sorted((SRC / "learn").rglob("*.py")):
        bad = sorted(m for m in imports_of(path) if m.startswith(above_learn))
        assert not bad, f"learn/{path.name} imports {bad}"


def test_no_import_cycles_between_modules():
    """The graph of module-level imports among PES's modules has no cycle (a package's
    ``__init__`` importing its children aside)."""
    modules = {module_name(p): p for p in SRC.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text())
        targets: set[str] = set()
        for node in tree.body:  # module level only: what runs at import
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("pes"):
                for alias in node.names:
                    full = f"{node.module}.{alias.name}"
                    targets.add(full if full in modules else node.module)
            elif isinstance(node, ast.Import):
                targets.update(a.name for a in node.names if a.name in modules)
        # a module importing its own ancestors' packages is Python's parent-first loading
        graph[name] = {t for t in targets if t in modules and not name.startswith(t + ".")}
    state: dict[str, int] = {}

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycle = trail[trail.index(nxt) :] + [nxt] if nxt in trail else [node, nxt]
                raise AssertionError(f"import cycle: {' -> '.join(cycle)}")
            if nxt not in state:
                visit(nxt, [*trail, nxt])
        state[node] = 2

    for name in sorted(graph):
        if name not in state and name != "pes":
            visit(name, [name])


def tracking(config: LearnerConfig) -> tuple[LearnerConfig, set[str]]:
    """A copy of ``config`` that records which of its fields are read."""
    fields = {f.name for f in dataclasses.fields(config)}
    reads: set[str] = set()

    class Tracked(type(config)):
        def __getattribute__(self, name):
            if name in fields:
                reads.add(name)
            return super().__getattribute__(name)

    copy = Tracked.__new__(Tracked)
    copy.__dict__.update(config.__dict__)
    return copy, reads


@pytest.mark.parametrize("algo", list(ALGOS))
def test_every_learner_reads_every_key_of_its_config(algo):
    """Build the learner, act, record and update for a few dozen steps, build its policy: every
    field of its config dataclass must have been read (no key that does nothing)."""
    values = dict(FAST, warmup=64, batch_size=32, eval_episodes=0)
    if ALGOS[algo].on_policy:
        values = dict(FAST, batch_size=32, rollout_steps=8, eval_episodes=0)
    if algo == "cbc-tp":
        values["tp_batch_size"] = 32
    cfg = build_train_config(algo, "tiny", values, protocol="pes")
    cfg.learner, reads = tracking(cfg.learner)
    cls = ALGOS[algo]
    env_cfg = cls.adapt_env(cfg.env_config())
    learner = cls(cfg, env_cfg, torch.device("cpu"))
    env = pes.make_env(env_cfg, num_envs=cfg.num_envs, seed=0)
    obs, info = env.reset()
    learner.episode_reset(torch.ones(cfg.num_envs, dtype=torch.bool))
    gen = torch.Generator().manual_seed(0)
    updates = 0
    for _ in range(60):
        actions, evader = learner.act(obs, info, 0.1, gen)
        obs2, reward, terminated, truncated, info2 = env.step(actions, evader)
        learner.record(info, actions, evader, reward, terminated, info2)
        done = terminated | truncated
        if bool(done.any()):
            learner.episode_reset(done)
        obs, info = obs2, info2
        if learner.ready() and learner.update_credit() > 0:
            learner.update(gen)
            updates += 1
    assert updates > 0
    cls.build_policy(cfg, env_cfg, "cpu")
    cls.fixed_swarm(cfg)
    unread = {f.name for f in dataclasses.fields(cfg.learner)} - reads
    assert not unread, f"{algo} never reads {sorted(unread)}"


COMPARED = (*TABLE4_ALGOS, "mappo")
"""The learners of Table IV and MAPPO, the reference learner beside them."""


@pytest.mark.parametrize("protocol", ["pes", "paper"])
@pytest.mark.parametrize("algo", COMPARED)
def test_every_table4_learner_trains_under_both_protocols(algo, protocol, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["train", "--algo", algo, "--preset", "tiny", "--protocol", protocol, "--json"]
    sets = ["episodes=8", "eval_episodes=0", "compile_env=false", "tensorboard=false"]
    for text in sets:
        argv += ["--set", text]
    assert main([*argv, "--out", str(out)]) == 0
    recorded = yaml.safe_load((out / "config.yaml").read_text())
    assert recorded["protocol"]["name"] == ("pes+custom" if protocol == "pes" else "paper")
    assert (out / "policy.pt").is_file()


def test_the_quick_presets_of_table4_share_one_protocol_and_one_run():
    """Table IV compares methods: every learner's quick preset trains under the same protocol,
    against the same opponent, on the same budget of experience (env steps, which no episode,
    time or CPU limit cuts short)."""
    configs = [build_train_config(algo, "quick") for algo in COMPARED]
    for cfg in configs:
        assert cfg.protocol == PES and cfg.protocol.name == "pes"
        assert cfg.env == configs[0].env and cfg.env_config() == configs[0].env_config()
        assert cfg.env_steps == configs[0].env_steps > 0
        assert cfg.time_limit == cfg.cpu_limit == 0.0
        assert cfg.episodes >= cfg.env_steps  # an episode is one env step or more


def test_the_quick_presets_hold_what_their_searches_found():
    """A learner whose equal search (``pes tune``) is complete trains the search's best settings
    in its quick preset; one whose search is not finished keeps the values of the searched
    settings that its trial t00 began from (the settings under search do not change under it).
    The search over the current space (``results/tuning_current/<algo>``) stands before the
    earlier one (``results/tuning/<algo>``). Settings the learner no longer searches (fixed by
    its method's standard form, as MAAC's target entropy) are not compared."""
    results = Path(__file__).resolve().parents[1] / "results"
    searched = []
    for algo in (*TABLE4_ALGOS, "cbc"):
        reports = [results / d / algo / "tuning.json" for d in ("tuning_current", "tuning")]
        report = next((r for r in reports if r.is_file()), None)
        if report is None:
            continue
        summary = json.loads(report.read_text())
        first = {r["id"]: r["values"] for r in summary["results"]}.get("t00")
        want = summary["best"] if summary["complete"] else first
        if want is None:
            continue
        want = {k: v for k, v in want.items() if k in learner_class(algo).TUNE_SPACE}
        preset = build_train_config(algo, "quick", protocol=summary["protocol"]).learner
        assert {key: getattr(preset, key) for key in want} == want, algo
        searched.append(algo)
    assert {"cbc-tp", "maddpg"} <= set(searched)


def test_a_key_the_method_does_not_read_is_an_error_naming_the_method():
    with pytest.raises(ConfigError, match="unknown key 'charge_exits' for maddpg"):
        build_train_config("maddpg", "tiny", {"charge_exits": True})
    with pytest.raises(ConfigError, match="unknown maddpg learner key 'hiden'"):
        build_train_config("maddpg", "tiny", {"learner": {"hiden": 3}})
    with pytest.raises(ConfigError, match="did you mean 'lr_actor'"):
        build_train_config("cbc-tp", "tiny", {"lr_actr": 1e-3})
    nan = float("nan")
    for bad in (
        {"lr_actor": nan},
        {"lr_critic": -1e-3},
        {"lr_tp": nan},
        {"grad_clip": nan},
        {"action_reg": nan},
        {"protocol.noise.sigma": nan},
        {"protocol.demonstrations.bc_weight": float("inf")},
    ):
        key = next(iter(bad)).split(".")[-1]
        with pytest.raises(ConfigError, match=key):
            build_train_config("cbc-tp", "tiny", bad)
    with pytest.raises(ConfigError, match="batch_size"):
        build_train_config("cbc-tp", "tiny", {"batch_size": 10**6})


def test_the_write_your_own_learner_example_trains():
    """docs/algorithms/write_your_own.md's example: one file, registered, trains and evaluates."""
    example = SRC.parents[1] / "examples" / "self_row_ddpg.py"
    proc = subprocess.run([sys.executable, str(example)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "'n_step': 'applied'" in proc.stdout and "evaluation:" in proc.stdout
