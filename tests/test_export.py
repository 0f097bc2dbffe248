"""ONNX export of CBC-TP / CBC policies: onnxruntime against PyTorch, the CLI, the example."""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

import pes
from pes.algos import ALGOS, build_train_config
from pes.algos.loading import load_pursuer_policy
from pes.cli import main
from pes.learn.checkpoint import POLICY_FORMAT, VERSION, save_atomic
from pes.learn.features import other_index
from pes.strict import to_dict
from tests.conftest import optional

optional("onnxruntime")
from pes.algos.cbc_tp_onnx import export_onnx, onnx_session, other_rows  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
TOL = 5e-5
"""Largest action difference allowed between onnxruntime and PyTorch: float32 rounding, which
grows with the pursuers the bidirectional LSTM runs across (the swarm shipped on 2026-11-30:
4.7e-6, 7.8e-6 and 1.4e-5 with 3, 5 and 8 pursuers; docs/export.md)."""


def _cli_json(*argv: str) -> dict:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(list(argv)) == 0
    return json.loads(out.getvalue())


@pytest.fixture(scope="module")
def shipped_onnx(tmp_path_factory) -> tuple[Path, dict]:
    """The shipped cbc-tp swarm exported through the CLI (once for this module)."""
    path = tmp_path_factory.mktemp("onnx") / "cbc_tp.onnx"
    return path, _cli_json("export-onnx", "cbc-tp", str(path), "--json")


def _random_batch(n: int, batch: int, history: int, seed: int):
    """Random observations and infos as the environment shapes them, about a fifth of the
    pursuers dead (at least one sample with all but one dead), with the policy's ``info``
    built independently of the exported graph's own masking."""
    gen = torch.Generator().manual_seed(seed)
    alive = torch.rand(batch, n, generator=gen) >= 0.2
    alive[0] = False
    alive[0, n - 1] = True
    mask = alive[:, other_index(n)] & alive.unsqueeze(-1)  # (B, N, N)
    obs = 0.5 * torch.randn(batch, n, n, 8, generator=gen) * mask.unsqueeze(-1)
    hist = 0.5 * torch.randn(batch, history, n + 1, 4, generator=gen)
    hist[:, :, :n] *= alive[:, None, :, None]
    state = torch.zeros(batch, n + 1, 8)
    state[:, :n] = obs[:, :, 0]  # the self rows; zero for dead pursuers, as the env's state
    state[:, n, :4] = hist[:, -1, n]
    info = {"obs_mask": mask, "history": hist, "state": state}
    return obs, alive, info


def _compare(policy, session, n: int, batch: int = 1000, seed: int = 0) -> dict[str, float]:
    obs, alive, info = _random_batch(n, batch, 10, seed)
    with torch.no_grad():
        expected = policy.act(obs, info) * alive.unsqueeze(-1)
    names = {i.name for i in session.get_inputs()}
    feed = {"obs": obs.numpy(), "alive": alive.numpy(), "history": info["history"].numpy()}
    out = session.run(None, {k: v for k, v in feed.items() if k in names})
    err = {"actions": float((torch.from_numpy(out[0]) - expected).abs().max())}
    assert out[0].shape == (batch, n, 2)
    assert not out[0][~alive.numpy()].any()  # dead pursuers get no command
    assert float(expected.abs().max()) > 0.05  # the comparison is not between near-zero actions
    if policy.last_prediction is not None:
        err["prediction"] = float((torch.from_numpy(out[1]) - policy.last_prediction).abs().max())
    return err


def test_other_rows_matches_the_observation_order():
    for n in (1, 2, 5, 8):
        assert torch.equal(other_rows(n), other_index(n))


@pytest.mark.parametrize("n", [3, 5, 8])
def test_onnx_matches_pytorch_on_random_inputs(shipped_onnx, n):
    path, summary = shipped_onnx
    policy, _ = load_pursuer_policy("cbc-tp", pes.EnvConfig(num_pursuers=n))
    err = _compare(policy, onnx_session(path), n, seed=n)
    assert err["actions"] < TOL and err["prediction"] < TOL, err


def test_export_summary_and_graph_signature(shipped_onnx):
    path, summary = shipped_onnx
    assert summary["path"] == str(path) and summary["bytes"] == path.stat().st_size
    assert not Path(f"{path}.data").exists()  # one self-contained file
    assert summary["algo"] == "cbc-tp" and summary["num_pursuers"] == "dynamic"
    assert summary["inputs"] == {
        "obs": ["batch", "num_pursuers", "num_pursuers", 8],
        "alive": ["batch", "num_pursuers"],
        "history": ["batch", 10, "num_pursuers + 1", 4],
    }
    assert summary["outputs"] == {
        "actions": ["batch", "num_pursuers", 2],
        "prediction": ["batch", 3, 2],
    }
    assert summary["max_abs_error"] < TOL


def test_onnx_acts_as_pytorch_in_the_simulator(shipped_onnx):
    """Along a real trajectory (one pursuer damaged, 4 environments), onnxruntime's actions are
    PyTorch's."""
    path, _ = shipped_onnx
    config = pes.EnvConfig(num_pursuers=4, damaged=1, crash_mode="disable", max_steps=40)
    env = pes.make_env(config, num_envs=4, seed=3)
    policy, _ = load_pursuer_policy("cbc-tp", config)
    session = onnx_session(path)
    obs, info = env.reset(seed=3)
    worst = 0.0
    for _ in range(30):
        alive = info["obs_mask"][:, :, 0]
        with torch.no_grad():
            expected = policy(obs, info) * alive.unsqueeze(-1)
        feed = {"obs": obs.numpy(), "alive": alive.numpy(), "history": info["history"].numpy()}
        actions = torch.from_numpy(session.run(["actions"], feed)[0])
        worst = max(worst, float((actions - expected).abs().max()))
        obs, _, _, _, info = env.step(actions)
    assert worst < TOL


def _policy_file(path: Path, algo: str, **values) -> Path:
    """An untrained policy file of ``algo`` with a last layer large enough that the actions are
    far from zero (the trainer's initialisation starts them near 0)."""
    cfg = build_train_config(algo, "tiny", values)
    policy, modules = ALGOS[cfg.algo].build_policy(cfg, cfg.env_config(), "cpu")
    torch.manual_seed(0)
    for net in policy.actor.nets:
        torch.nn.init.normal_(net.head[-1].weight, std=0.5)
    save_atomic(
        {
            "format": POLICY_FORMAT,
            "version": VERSION,
            "algo": cfg.algo,
            "train_config": to_dict(cfg),
            "env_config": to_dict(cfg.env_config()),
            "policy": {k: m.state_dict() for k, m in modules.items()},
            "meta": {},
        },
        path,
    )
    return path


def test_cbc_policy_with_one_network_per_pursuer(tmp_path):
    """CBC (no TP Net, no history input) with per-pursuer actors: the pursuer axis is fixed."""
    spec = _policy_file(tmp_path / "cbc.pt", "cbc", shared=False, env={"num_pursuers": 4})
    summary = export_onnx(spec, tmp_path / "cbc.onnx")
    assert summary["algo"] == "cbc" and summary["num_pursuers"] == 4
    assert summary["inputs"] == {"obs": ["batch", 4, 4, 8], "alive": ["batch", 4]}
    assert list(summary["outputs"]) == ["actions"]
    policy, _ = load_pursuer_policy(spec, pes.EnvConfig(num_pursuers=4))
    err = _compare(policy, onnx_session(tmp_path / "cbc.onnx"), 4)
    assert err["actions"] < TOL, err


def test_export_errors_are_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"\x80\x03garbage" * 10)
    cases = {
        "no checkpoint": [str(tmp_path / "missing.pt")],
        "corrupted": [str(bad)],
        "'evader-ddpg' model": ["evader-ddpg"],  # another architecture: the shipped evader
    }
    for message, spec in cases.items():
        assert main(["export-onnx", *spec, str(tmp_path / "x.onnx")]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1 and "Traceback" not in err
    assert main(["export-onnx", "cbc-tp", str(tmp_path / "x.pt")]) == 2
    assert "must end in .onnx" in capsys.readouterr().err
    assert not (tmp_path / "x.onnx").exists()


def test_example_flies_the_exported_policy(shipped_onnx):
    path, _ = shipped_onnx
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "src"), str(ROOT)]))
    proc = subprocess.run(
        [
            sys.executable,
            str(ROOT / "examples" / "onnx_policy.py"),
            str(path),
            "--episodes",
            "2",
            "--num-pursuers",
            "6",
            "--max-steps",
            "25",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert lines[0].startswith("episode 0 (seed 0): 6 pursuers")
    assert lines[-1].startswith("success ") and "/2, mean steps" in lines[-1]
