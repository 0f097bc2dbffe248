"""The maintenance scripts under scripts/ that pick, ship and study trained policies."""

from __future__ import annotations

import importlib.util
import json
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from pes.algos import build_train_config, train
from pes.algos.loading import load_pursuer_policy
from pes.learn.checkpoint import POLICY_FORMAT
from pes.models import MODELS_DIR
from pes.sim.config import EnvConfig
from tests.learning import FAST

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = ROOT / "scripts"


def _script(name: str):
    spec = importlib.util.spec_from_file_location(name, SCRIPTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _tiny_run(out: Path, **values) -> None:
    cfg = build_train_config("cbc-tp", "tiny", FAST | {"episodes": 16, "eval_episodes": 0} | values)
    train(cfg, out, progress=False)


def test_ship_file_of_a_checkpoint_keeps_the_acting_networks(tmp_path):
    _tiny_run(tmp_path / "run", seed=3)
    target = tmp_path / "shipped.pt"
    _script("ship_model").ship_file(str(tmp_path / "run" / "checkpoint.pt"), target)
    obj = torch.load(target, weights_only=True)
    assert obj["format"] == POLICY_FORMAT and set(obj["policy"]) == {"actor", "tp"}
    meta = obj["meta"]
    assert meta["from_checkpoint"] and meta["seed"] == 3 and meta["episodes"] >= 16
    assert meta["torch"] == str(torch.__version__)
    _, cfg = load_pursuer_policy(target, EnvConfig())
    assert cfg.seed == 3


def test_the_swarm_s_model_card_quotes_its_evaluation_and_the_reproduction():
    """The committed card of the shipped swarm is what ``ship_model.py --card-only`` writes
    from results/shipped_cbc_tp.json and the reproduction's results/quick/evals.json, so it
    quotes the numbers those files hold."""
    ship = _script("ship_model")
    record = json.loads((ROOT / "results" / "shipped_cbc_tp.json").read_text())
    args = ship.build_parser().parse_args(shlex.split(record["eval_command"])[2:])
    text = ship.card(args, record)
    assert "## The `quick` preset trained from scratch" in text
    assert text == (MODELS_DIR / "cbc_tp.md").read_text()


def test_pick_evader_prefers_the_paper_s_steps_to_a_crash_heavy_match():
    """A snapshot caught as rarely as the paper's evader but in short, crash-ended episodes is
    farther from the paper's pair (27.3 %, 482 steps) than one caught a little less often in
    long episodes (the measured snapshots 46 and 70 of results/evader_snapshots.json)."""
    pick = _script("pick_evader")
    crashy = {"success_rate": 0.273, "mean_steps": 202.0}
    long = {"success_rate": 0.243, "mean_steps": 444.0}
    args = (pick.PAPER_PID_PF_SUCCESS, pick.PAPER_PID_PF_STEPS, 500)
    assert pick.distance(long, *args) < pick.distance(crashy, *args)
    assert pick.distance({"success_rate": 0.273, "mean_steps": 482.0}, *args) == 0.0


def test_pick_swarm_screens_snapshots_and_confirms_the_best(tmp_path):
    _tiny_run(tmp_path / "run", snapshots=True, log_every=8)
    snaps = sorted((tmp_path / "run" / "snapshots").glob("ep*.pt"))
    assert len(snaps) >= 2
    out = tmp_path / "pick.json"
    argv = [sys.executable, str(SCRIPTS / "pick_swarm.py"), str(tmp_path / "run")]
    small = ["--screen", "2", "--episodes", "2", "--num-envs", "2", "--top", "2"]
    proc = subprocess.run(
        [*argv, *small, "--out", str(out)], capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr
    report = json.loads(out.read_text())
    screened = [c["policy"] for c in report["candidates"]]
    assert screened == [str(p) for p in snaps] + [str(tmp_path / "run" / "policy.pt")]
    confirmed = [c for c in report["candidates"] if "confirm" in c]
    assert len(confirmed) == 2 and report["chosen"] in [c["policy"] for c in confirmed]
    assert report["protocol"]["screen"]["seed"] != 0
    assert report["protocol"]["confirm"]["seed"] != report["protocol"]["screen"]["seed"]
    # picking on the reporting seed is refused
    proc = subprocess.run(
        [*argv, "--seed", "0", "--out", str(out)], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode != 0 and "seed 0" in proc.stderr


def test_pick_swarm_ranks_policies_over_the_step_bound_last():
    ranked = _script("pick_swarm").ranked

    def row(name, success, steps):
        return {"policy": name, "screen": {"success_rate": success, "mean_steps": steps}}

    rows = [row("slow", 0.97, 230.0), row("fast", 0.94, 190.0), row("faster", 0.94, 180.0)]
    assert [r["policy"] for r in ranked(rows, "screen")] == ["slow", "faster", "fast"]
    bounded = ranked(rows, "screen", max_steps=200.0)
    assert [r["policy"] for r in bounded] == ["faster", "fast", "slow"]


def test_behaviour_times_the_phases_of_a_capture_in_order():
    stats = _script("behaviour").measure("pid-pf", episodes=16, seed=0, evader_speed=12.0)
    captures = stats["captures"][0]
    assert captures >= 1  # PID(PF) catches the default evader in about a quarter of episodes
    first_near, three_within_5, three_within_2, capture, at_wall = stats["phases"]
    # a capture needs three pursuers within 2 m for 5 steps: each phase follows the one before
    assert 0 <= first_near <= three_within_2 and 0 <= three_within_5 <= three_within_2
    assert three_within_2 + 4 <= capture < 500
    assert 0.0 <= at_wall <= 1.0


def test_crash_sites_records_every_crash_of_the_measured_episodes(tmp_path, capsys):
    """An untrained swarm crashes often: the script keeps one record per crash of the episodes
    the evaluation counts (not of those the environments play past their share)."""
    _tiny_run(tmp_path / "run")
    out = tmp_path / "crashes.json"
    argv = [str(tmp_path / "run"), "--episodes", "12", "--num-envs", "5", "--out", str(out)]
    assert _script("crash_sites").main(argv) == 0
    summary = json.loads(out.read_text())
    evaluation = summary["evaluation"]
    assert summary["crashes"] == round(evaluation["mean_crashes"] * evaluation["episodes"]) > 0
    assert 0.0 <= summary["share_evader_hidden"] <= 1.0
    assert sum(map(sum, summary["map_10m_north_up"])) == summary["crashes"]
    assert json.loads(capsys.readouterr().out) == summary


def test_host_speed_replays_a_run_row_for_row_and_compares_its_cpu_time(tmp_path):
    """benchmarks/host_speed.py trains a run again from its config.yaml: the same training, row
    for row, so that the ratio of the CPU times measures the machine alone."""
    spec = importlib.util.spec_from_file_location("host_speed", ROOT / "benchmarks/host_speed.py")
    host_speed = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(host_speed)
    demonstrations = {"protocol.demonstrations.transitions": 200}
    _tiny_run(tmp_path / "run", threads=1, episodes=24, log_every=2, **demonstrations)
    then = host_speed.log_rows(tmp_path / "run" / "progress.csv")
    here = host_speed.replay(tmp_path / "run", int(then[-1]["env_steps"]), tmp_path / "again")
    result = host_speed.compare(then, here)
    assert result["replayed"] and result["same_work"], (then, here)
    # from the first row where the demonstrator no longer played: before it, the CPU time is
    # the demonstrator's collection more than the learner's updates
    own = [row for row in then if not row["demonstrating"]]
    assert 2 <= len(own) < len(then) and own[-1] is then[-1]
    assert result["env_steps"] == [int(own[0]["env_steps"]), int(then[-1]["env_steps"])]
    assert result["cpu_s_then"] > 0 and result["cpu_s_here"] > 0 and result["cpu_ratio"] > 0
    other = [dict(row, success_rate=row["success_rate"] + 0.5) for row in here]
    result = host_speed.compare(then, other)  # another training doing the same work
    assert not result["replayed"] and result["same_work"]
    other = [dict(row, updates=row["updates"] + 1) for row in here]
    assert not host_speed.compare(then, other)["same_work"]
    with pytest.raises(SystemExit, match="after the demonstrations"):
        host_speed.compare([dict(row, demonstrating=1.0) for row in then], here)


def test_host_speed_compares_two_seeds_over_the_env_steps_both_logged():
    """``--against``: two runs of the same settings log rows at different env steps; their CPU
    time per env step is compared over the stretch both cover after the demonstrations."""
    spec = importlib.util.spec_from_file_location("host_speed", ROOT / "benchmarks/host_speed.py")
    host_speed = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(host_speed)

    def rows(steps, seconds_per_step, demonstrating=100):
        return [
            {
                "env_steps": float(n),
                "updates": n / 16,
                "cpu_s": 50.0 + seconds_per_step * n,
                "success_rate": 0.0,
                "demonstrating": float(n <= demonstrating),
            }
            for n in steps
        ]

    then = rows([100, 200, 400, 600, 800], 0.5)
    here = rows([100, 150, 350, 550, 650, 900], 0.6, demonstrating=150)
    result = host_speed.against(then, here)
    assert result["env_steps"] == [350, 800]
    assert result["cpu_s_then"] == pytest.approx(0.5 * 450)
    assert result["cpu_s_here"] == pytest.approx(0.6 * 450)
    assert result["cpu_ratio"] == pytest.approx(1.2)
    assert result["updates_per_env_step"] == [0.0625, 0.0625]
    with pytest.raises(SystemExit, match="share no stretch"):
        host_speed.against(then, rows([100, 900, 1000], 0.6, demonstrating=850))
    with pytest.raises(SystemExit, match="no row after the demonstrations"):
        host_speed.against(then, rows([100, 200], 0.6, demonstrating=300))
