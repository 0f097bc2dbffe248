"""Every command on a tiny budget, and the user mistakes (one line, exit 2, no traceback)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from pes.cli import main
from pes.record import load_record


def run_json(capsys, *argv: str) -> dict:
    assert main(list(argv)) == 0
    return json.loads(capsys.readouterr().out)


def test_demo(tmp_path, capsys):
    out = run_json(capsys, "demo", "--out", str(tmp_path), "--json", "--set", "max_steps=40")
    assert out["steps"] <= 40 and (tmp_path / "episode.gif").stat().st_size > 10_000
    record = load_record(tmp_path / "episode.json")
    assert len(record["frames"]) == out["steps"] + 1


def test_demo_human_output(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--set", "max_steps=20"]) == 0
    text = capsys.readouterr().out
    assert "GIF" in text and "episode.json" in text


def test_eval_json_keys(capsys):
    out = run_json(
        capsys,
        "eval",
        "--policy",
        "pid-pf",
        "--episodes",
        "6",
        "--num-envs",
        "3",
        "--disturbance",
        "--damaged",
        "1",
        "--seed",
        "4",
        "--json",
        "--set",
        "max_steps=30",
    )
    for key in ("success_rate", "mean_steps", "mean_reward", "episodes"):
        assert key in out
    assert out["episodes"] == 6 and out["damaged"] == 1 and out["disturbance"] is True
    assert out["crash_mode"] == "disable"


def test_eval_with_config_file(tmp_path, capsys):
    path = tmp_path / "scenario.yaml"
    path.write_text("num_pursuers: 4\nmax_steps: 20\n")
    out = run_json(
        capsys, "eval", "--policy", "random", "--episodes", "2", "--config", str(path), "--json"
    )
    assert out["episodes"] == 2


def test_render_gif_and_json(tmp_path, capsys):
    gif = tmp_path / "ep.gif"
    assert main(["render", "--policy", "pid-pf", "--out", str(gif), "--set", "max_steps=15"]) == 0
    assert gif.read_bytes()[:6] in (b"GIF87a", b"GIF89a")
    assert "wrote" in capsys.readouterr().out
    out = run_json(
        capsys,
        "render",
        "--policy",
        "random",
        "--out",
        str(tmp_path / "ep.json"),
        "--episodes",
        "2",
        "--json",
        "--set",
        "max_steps=10",
    )
    assert [f["path"] for f in out["files"]] == [
        str(tmp_path / "ep_0.json"),
        str(tmp_path / "ep_1.json"),
    ]
    assert load_record(tmp_path / "ep_1.json")["outcome"]["steps"] <= 10


def test_render_mp4_and_png(tmp_path, capsys):
    """An MP4 of a run, then a PNG plot redrawn from a saved record."""
    out = run_json(
        capsys,
        "render",
        "--policy",
        "pid-pf",
        "--out",
        str(tmp_path / "ep.mp4"),
        "--every",
        "4",
        "--json",
        "--set",
        "max_steps=12",
    )
    mp4 = tmp_path / "ep.mp4"
    assert out["files"][0]["path"] == str(mp4) and mp4.read_bytes()[4:8] == b"ftyp"
    argv = [
        "render",
        "--policy",
        "pid-pf",
        "--out",
        str(tmp_path / "ep.json"),
        "--set",
        "max_steps=12",
    ]
    assert main(argv) == 0
    capsys.readouterr()
    out = run_json(
        capsys,
        "render",
        "--record",
        str(tmp_path / "ep.json"),
        "--out",
        str(tmp_path / "ep.png"),
        "--json",
    )
    assert out["files"][0]["path"] == str(tmp_path / "ep.png")
    assert (tmp_path / "ep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_render_test_conditions(tmp_path):
    """pes render plays the paper's evaluation scenario, as pes demo: disturbance on unless
    --no-disturbance; --damaged reaches the episode."""
    path = tmp_path / "ep.json"
    argv = ["render", "--policy", "pid-pf", "--out", str(path), "--set", "max_steps=5"]
    assert main([*argv, "--damaged", "2", "--disturbance"]) == 0
    record = load_record(path)
    assert record["config"]["damaged"] == 2 and record["config"]["disturbance"] is True
    assert sum(not alive for alive in record["frames"][0]["alive"]) >= 2
    assert main(argv) == 0
    record = load_record(path)
    assert record["config"]["damaged"] == 0 and record["config"]["disturbance"] is True
    assert main([*argv, "--no-disturbance"]) == 0
    assert load_record(path)["config"]["disturbance"] is False


def test_bench(capsys):
    out = run_json(
        capsys, "bench", "--num-envs", "1", "4", "--steps", "10", "--no-compile", "--json"
    )
    assert [r["num_envs"] for r in out["results"]] == [1, 4]
    assert all(r["env_steps_per_s"] > 0 for r in out["results"])


@pytest.mark.parametrize(
    "argv, message",
    [
        (["eval", "--policy", "pid-pf", "--set", "num_pursuer=3"], "did you mean 'num_pursuers'"),
        (["eval", "--policy", "pid-pf", "--set", "pursuer_max_speed=-3"], "positive"),
        (["eval", "--policy", "pid-pf", "--set", "capture_count=6"], "above num_pursuers"),
        (["eval", "--policy", "pid-pf", "--damaged", "4"], "damaged"),
        (["eval", "--policy", "nobody"], "unknown policy"),
        (["eval", "--policy", "pid-pf", "--config", "missing.yaml"], "not found"),
        (
            [
                "eval",
                "--policy",
                "pid-pf",
                "--set",
                "grid_rows=1",
                "--set",
                "grid_cols=1",
                "--set",
                "block_size=80",
                "--set",
                "removed_blocks=[]",
            ],
            "no free room",
        ),
        (["render", "--policy", "pid-pf", "--out", "x.avi"], ".png or .json"),
        (["render", "--record", "missing.json", "--out", "x.png"], "not found"),
        (["eval", "--policy", "pid-pf", "--device", "cuda:9"], "cuda"),
        # a trained policy is checked before its networks are moved to the device
        (["eval", "--policy", "cbc-tp", "--device", "cuda"], "cuda"),
        (["tune", "--algo", "ppo", "--preset", "tiny", "--no-ray"], "give --env-steps"),
        (["tune", "--algo", "ppo", "--trials", "2", "--halvings", "2"], "halvings must be 0 to 1"),
    ],
)
def test_user_mistakes(argv, message, capsys):
    if any(a.startswith("cuda") for a in argv):
        import torch

        if torch.cuda.is_available():
            pytest.skip("a GPU is present")
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and message in err and len(err.splitlines()) == 1


def test_tune_on_the_tiny_preset(tmp_path, capsys):
    """pes tune end to end: two trials to half the budget, the better one on to all of it."""
    argv = ["tune", "--algo", "ppo", "--preset", "tiny", "--trials", "2", "--halvings", "1"]
    argv += ["--env-steps", "800", "--eval-episodes", "2", "--no-ray", "--out", str(tmp_path)]
    assert main([*argv, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["complete"] and summary["budgets"] == [400, 800]
    assert [r["env_steps"] for r in summary["results"]] == [800, 400]
    assert summary["best"] == summary["results"][0]["values"]
    assert main(argv) == 0  # finds everything done
    assert "2 of 2 trials scored; best: " in capsys.readouterr().out


def test_mistakes_through_the_real_command():
    """The installed command: exit status 2, one line, no traceback."""
    cases = [
        ["eval", "--policy", "pid-pf", "--set", "num_pursuers=zero"],
        ["eval", "--policy", "pid-pf", "--episodes", "0"],
        ["render", "--policy", "pid-pf"],
        ["frobnicate"],
    ]
    for argv in cases:
        proc = subprocess.run(
            [sys.executable, "-m", "pes.cli", *argv], capture_output=True, text=True, timeout=120
        )
        assert proc.returncode == 2, (argv, proc.stderr)
        assert "Traceback" not in proc.stderr


def test_every_command_has_help():
    for command in ["demo", "eval", "render", "bench", "export-onnx"]:
        proc = subprocess.run(
            [sys.executable, "-m", "pes.cli", command, "--help"],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert proc.returncode == 0 and "usage: pes" in proc.stdout


def test_closed_stdout_is_not_a_traceback():
    """``pes eval --json | head`` when head has gone: exit as SIGPIPE would, no traceback."""
    argv = ["eval", "--policy", "random", "--episodes", "2", "--num-envs", "2", "--json"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "pes.cli", *argv, "--set", "max_steps=5"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    proc.stdout.close()  # the reader goes away before the command prints
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 141, err
    assert "Traceback" not in err and "BrokenPipeError" not in err
