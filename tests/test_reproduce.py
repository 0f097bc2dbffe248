"""`pes reproduce` end to end on the tiny budget, with and without Ray, and its resumption."""

from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image

import pes
from pes.cli import main
from pes.errors import ConfigError
from pes.experiments.report import _curves, episode_config, read_progress, reference_cpu_s
from pes.experiments.reproduce import reproduce
from pes.experiments.trials import BUDGETS, eval_config, make_trials, train_config
from pes.sim.bench import machine_info

METHODS = ["pid-pf", "cbc", "cbc-tp"]


def _not_blank(path) -> bool:
    pixels = np.asarray(Image.open(path).convert("RGB"), dtype=float)
    return pixels.std() > 5.0


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """One sequential run of every target (1 seed, 3 methods) and its summary."""
    out = tmp_path_factory.mktemp("reproduce")
    summary = reproduce("all", budget="tiny", seeds=1, out=out, methods=METHODS, use_ray=False)
    return out, summary


@pytest.mark.slow
def test_all_targets_sequential(sweep):
    out, summary = sweep
    assert summary["runner"] == "sequential"
    assert summary["ran"] == summary["trials"] == 4  # 3 methods + the TP Net trial
    table4 = (out / "table4.md").read_text()
    for label in ("PID(PF)", "CBC Net", "CBC-TP Net", "success rate (paper)", "27.3 %"):
        assert label in table4
    table5 = (out / "table5.md").read_text()
    assert "FDE (PES)" in table5 and "0.196" in table5
    table6 = (out / "table6.md").read_text()
    assert "| 2 |" in table6 and "86.7 %" in table6
    figures = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert figures == [
        "fig11_trajectories_tp.png",
        "fig12_trajectories_damaged.png",
        "fig13_damaged_steps.png",
        "fig6_success_rate.png",
        "fig7_average_reward.png",
        "fig8_episode_steps.png",
        "fig9_10_cbc_tp_vs_cbc.png",
        "learning_curves.png",
    ]
    assert all(_not_blank(out / "figures" / name) for name in figures)
    captions = (out / "figures.md").read_text()
    assert captions.count("![") == len(figures)
    assert sorted(p.name for p in (out / "logs").glob("*.csv")) == ["cbc-s0.csv", "cbc-tp-s0.csv"]
    evals = json.loads((out / "evals.json").read_text())
    assert set(evals["cbc-tp-s0"]["evals"]) == {"table4", "damaged1", "damaged2"}
    table5_rec = evals["tpnet-s0"]["table5"]
    assert len(table5_rec["fde"]) == len(table5_rec["ade"]) == 5
    meta = json.loads((out / "reproduce.json").read_text())
    assert meta["machine"]["cpu_count"] >= 1 and set(meta["finished"]) == {
        s["id"] for s in make_trials(METHODS, 1, "tiny", tpnet=True)
    }
    # Provenance: the protocol, the source commit, every training's resolved configuration.
    assert meta["protocol"] == "pes" and "`pes` protocol" in table4
    assert "commit" in meta and set(meta["trial_commits"]) == set(meta["finished"])
    assert meta["trial_configs"]["cbc-tp-s0"]["algo"] == "cbc-tp"
    assert meta["trial_configs"]["cbc-tp-s0"]["protocol"]["name"].startswith("pes")
    assert meta["trial_configs"]["pid-pf-s0"] is None
    assert "failed: step limit (PES)" in table4 and "crashes per episode (PES)" in table4
    # What each method's training cost, beside its results (PID(PF) does not train).
    cost = next(line for line in table4.splitlines() if line.startswith("| training env steps"))
    assert cost.split(" | ")[1] == "—" and all(c.strip(" |") != "—" for c in cost.split(" | ")[2:])
    assert "| training CPU minutes (PES) |" in table4
    # and on which CPUs those minutes were spent (the learner trials: CBC Net, CBC-TP Net)
    assert f"trials trained on {machine_info()['cpu']} (2))" in table4


@pytest.mark.slow
def test_rerun_skips_finished_trials(sweep):
    out, _ = sweep
    done = {p: p.stat().st_mtime_ns for p in (out / "trials").glob("*/done.json")}
    summary = reproduce("all", budget="tiny", seeds=1, out=out, methods=METHODS, use_ray=False)
    assert summary["ran"] == 0 and summary["skipped"] == 4
    assert {p: p.stat().st_mtime_ns for p in done} == done


@pytest.mark.slow
def test_report_only_runs_nothing_and_shows_outside_reference_runs(sweep, tmp_path, capsys):
    out, _ = sweep
    (out / "table4.md").unlink()
    summary = reproduce(
        "table4", budget="tiny", seeds=2, out=out, methods=METHODS, use_ray=False, report_only=True
    )
    assert summary["ran"] == 0 and summary["skipped"] == 3 and summary["unfinished"] == 3
    assert summary["runner"] == "none"
    assert "Seeds per method: PID(PF) 1" in (out / "table4.md").read_text()
    assert not (out / "trials" / "cbc-s1").exists()
    # A part of the sweep (--methods) reports every finished trial in the folder.
    argv = ["reproduce", "table4", "--budget", "tiny", "--seeds", "1", "--out", str(out)]
    assert main([*argv, "--methods", "pid-pf", "--no-ray", "--report-only"]) == 0
    assert "done: 0 trial(s) run (none), 1 already finished, 0 not run" in capsys.readouterr().out
    assert "| CBC-TP Net |" in (out / "table4.md").read_text()
    # Outside reference runs (the records pes.benchmarl.reference writes) as Table IV columns;
    # the evaluation of PID(PF)'s trial stands in for a reference run's here.
    pid_eval = json.loads((out / "evals.json").read_text())["pid-pf-s0"]["evals"]["table4"]
    outside = tmp_path / "benchmarl"
    for seed in (0, 1):
        record = {
            "method": "MAPPO (BenchMARL)",
            "seed": seed,
            "frames": 2_004_000,
            "command": f"python -m pes.benchmarl.reference --algorithm mappo --seed {seed}",
            "eval": {**pid_eval, "success_rate": 0.25 + 0.5 * seed},
        }
        (outside / f"mappo-s{seed}").mkdir(parents=True)
        (outside / f"mappo-s{seed}" / "result.json").write_text(json.dumps(record))
    reproduce(
        "table4", budget="tiny", seeds=1, out=out, methods=METHODS, use_ray=False,
        report_only=True, outside=outside,
    )  # fmt: skip
    table4 = (out / "table4.md").read_text()
    header = next(line for line in table4.splitlines() if line.startswith("| |"))
    assert header.endswith("| CBC-TP Net | MAPPO (BenchMARL) |")
    assert "50.0 ± 35.4 %" in table4 and "MAPPO (BenchMARL) 2" in table4
    assert "2,004,000 frames" in table4 and "--algorithm mappo --seed 1" in table4
    meta = json.loads((out / "reproduce.json").read_text())
    assert [r["seed"] for r in meta["outside"]["runs"]] == [0, 1]
    with pytest.raises(pes.errors.ConfigError, match="no folder"):
        reproduce("table4", budget="tiny", out=out, outside=tmp_path / "nope", report_only=True)
    # the note on CBC Net (the ablation, not a column of the paper's table) only beside its column
    assert "CBC Net (the ablation of §V-C)" in table4
    alone = tmp_path / "alone"
    shutil.copytree(out / "trials" / "pid-pf-s0", alone / "trials" / "pid-pf-s0")
    reproduce(
        "table4", budget="tiny", seeds=1, out=alone, methods=["pid-pf"], use_ray=False,
        report_only=True,
    )  # fmt: skip
    assert "| PID(PF) |" in (alone / "table4.md").read_text()
    assert "CBC Net" not in (alone / "table4.md").read_text()


@pytest.mark.slow
def test_interrupted_trial_resumes_without_retraining(sweep):
    out, _ = sweep
    trial = out / "trials" / "cbc-s0"
    policy_time = (trial / "run" / "policy.pt").stat().st_mtime_ns
    (trial / "done.json").unlink()  # as if killed after training, during its evaluations
    (trial / "eval_table4.json").unlink()
    summary = reproduce("table4", budget="tiny", seeds=1, out=out, methods=METHODS, use_ray=False)
    assert summary["ran"] == 1 and summary["skipped"] == 2
    assert (trial / "done.json").is_file() and (trial / "eval_table4.json").is_file()
    assert (trial / "run" / "policy.pt").stat().st_mtime_ns == policy_time
    # Killed during training (Ctrl-C writes a summary that says so): the training goes on.
    run_summary = trial / "run" / "summary.json"
    record = json.loads(run_summary.read_text())
    run_summary.write_text(json.dumps({**record, "stopped_by": "interrupted"}))
    (trial / "done.json").unlink()
    reproduce("table4", budget="tiny", seeds=1, out=out, methods=METHODS, use_ray=False)
    assert json.loads(run_summary.read_text())["stopped_by"] == "episodes"


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason="Ray is not installed")
def test_table6_with_ray(tmp_path):
    summary = reproduce("table6", budget="tiny", seeds=1, out=tmp_path, use_ray=True)
    assert summary["runner"] == "ray" and summary["ran"] == 1
    assert "CBC-TP Net with damaged pursuers" in (tmp_path / "table6.md").read_text()
    assert json.loads((tmp_path / "trials" / "cbc-tp-s0" / "done.json").read_text())["evals"]


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason="Ray is not installed")
def test_failed_ray_trial_is_one_line(tmp_path):
    """A trial that fails under Ray ends the sweep with a one-line PESError naming the trial,
    the error's last line and the file that holds its traceback; the other trial finishes."""
    from pes.experiments.sweep import SweepProgress, run_ray

    def runner(spec, out, threads):
        if spec["id"] == "bad-s0":
            raise ValueError("the trial broke")
        (out / f"{spec['id']}.done").write_text("1")

    specs = [{"id": "bad-s0"}, {"id": "good-s0"}]
    view = SweepProgress(len(specs), 0, enabled=False)
    with pytest.raises(pes.errors.TrialsFailedError) as caught:
        run_ray(specs, tmp_path, None, view, runner, parallel=1, name="failing")
    message = str(caught.value)
    assert "\n" not in message and message.startswith("1 trial(s) failed (bad-s0)")
    assert "ValueError: the trial broke" in message
    traceback = message.split("traceback: '")[1].split("'")[0]
    assert "the trial broke" in Path(traceback).read_text()
    assert (tmp_path / "good-s0.done").is_file()


def test_tuning_trials_train_half_the_quick_budget_by_default():
    """``pes tune``'s default budget is half the preset's env steps (the quick presets'
    2,000,000 give searches of 1,000,000, as results/tuning was made); a preset budgeted in
    episodes needs --env-steps."""
    from pes.algos import build_train_config
    from pes.experiments.tune import preset_env_steps

    for algo in ("cbc-tp", "maddpg", "ppo"):
        quick = build_train_config(algo, "quick").env_steps
        assert preset_env_steps(algo, "quick", "pes") == quick // 2 == 1_000_000
    with pytest.raises(pes.errors.ConfigError, match="no env_steps budget: give --env-steps"):
        preset_env_steps("maddpg", "paper", "paper")


def test_budget_training_configs():
    """quick trains each method on its whole quick preset (its env steps, no time limit);
    paper keeps the paper preset's episodes; every trial gets its seed."""
    from pes.algos import build_train_config

    for algo in ("cbc-tp", "ppo", "maac"):
        preset = build_train_config(algo, "quick")
        cfg = train_config({"algo": algo, "seed": 2}, BUDGETS["quick"])
        assert cfg.env_steps == preset.env_steps == 2_000_000
        assert cfg.episodes == preset.episodes and cfg.time_limit == 0.0
        assert cfg.seed == 2 and cfg.preset == "quick" and cfg.eval_episodes == 0
    cfg = train_config({"algo": "cbc-tp", "seed": 0}, BUDGETS["paper"])
    assert cfg.episodes == build_train_config("cbc-tp", "paper").episodes == 4000


def test_protocol_of_the_learners():
    """Every learner of a reproduction trains under one protocol: pes unless asked (and paper
    under the paper budget); the scripted PID(PF) has none."""
    for protocol in ("pes", "paper"):
        specs = make_trials(["pid-pf", "maddpg", "cbc-tp"], 1, "quick", False, protocol)
        assert "protocol" not in specs[0]
        for spec in specs[1:]:
            assert train_config(spec, BUDGETS["quick"]).protocol.name == protocol
    with pytest.raises(pes.errors.ConfigError, match="protocol must be one of"):
        reproduce("table4", budget="tiny", protocol="mine", use_ray=False)


def test_user_mistakes(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["reproduce", "table9"])
    assert exc.value.code == 2
    argv = ["reproduce", "table4", "--budget", "tiny", "--out", str(tmp_path), "--no-ray"]
    assert main([*argv, "--methods", "nope"]) == 2
    assert "unknown method 'nope'" in capsys.readouterr().err


def test_tune_breaks_ties_by_reward_not_by_the_soonest_failure(tmp_path):
    """Without captures, the swarm lost to crashes in few steps does not outrank the one that
    kept up with the evader to the step limit; captures always come first; the report ranks
    trials of equal success by their reward."""
    from pes.experiments.tune import make_tune_trials, score, write_json, write_tuning_report

    lost_fast = {"success_rate": 0.0, "mean_steps": 163.0, "mean_reward": -0.9}
    kept_up = {"success_rate": 0.0, "mean_steps": 484.0, "mean_reward": -0.3}
    one_capture = {"success_rate": 0.005, "mean_steps": 480.0, "mean_reward": -5.0}
    assert score(kept_up) > score(lost_fast)
    assert score(one_capture) > score(kept_up)
    specs = make_tune_trials("ppo", 2, 800, 0, 2, "pes", 0, "tiny")
    for spec, result in zip(specs, (lost_fast, kept_up), strict=True):
        folder = tmp_path / "trials" / spec["id"]
        folder.mkdir(parents=True)
        train = {"episodes": 8, "env_steps": 800, "updates": 1, "cpu_s": 1.0}
        failures = {"mean_crashes": 1.0, "lost_rate": 0.5, "timeout_rate": 0.5}
        record = {"spec": spec, "env_steps": 800, "train": train, "eval": {**result, **failures}}
        write_json(folder / "result-800.json", record)
    summary = write_tuning_report(tmp_path, specs, "", 0.0)
    assert [r["id"] for r in summary["results"]] == ["t01", "t00"]
    assert "(trials trained on unrecorded CPU (2))" in (tmp_path / "README.md").read_text()
    assert summary["complete"] and summary["best"] == specs[1]["values"]


def test_tune_recommends_a_trial_within_one_standard_error_at_half_the_cost(tmp_path):
    """The best settings are the top trial's unless it captures and another trial at the furthest
    budget scores within one standard error of its success rate in at most half its CPU time;
    then the cheapest such trial's. Outside the error, at more than half the cost, or where no
    trial captures, the top stays."""
    from pes.experiments.tune import chosen, make_tune_trials, write_json, write_tuning_report

    def result(id_, success, cpu_s, env_steps=800):
        return {"id": id_, "success_rate": success, "cpu_s": cpu_s, "env_steps": env_steps}

    # 200 episodes at 47 %: one standard error is 3.53 points
    top = result("t05", 0.47, 10_000.0)
    assert chosen([top, result("t03", 0.46, 1_300.0)], 200)["id"] == "t03"
    assert chosen([top, result("t03", 0.43, 1_300.0)], 200)["id"] == "t05"  # outside the error
    assert chosen([top, result("t03", 0.46, 5_001.0)], 200)["id"] == "t05"  # over half the cost
    assert chosen([top, result("t03", 0.47, 900.0, env_steps=400)], 200)["id"] == "t05"
    cheaper = [top, result("t01", 0.45, 4_000.0), result("t03", 0.44, 2_000.0)]
    assert chosen(cheaper, 200)["id"] == "t03"  # the cheapest of those within the error
    nothing = [result("t05", 0.0, 10_000.0), result("t03", 0.0, 1_000.0)]
    assert chosen(nothing, 200)["id"] == "t05"  # no captures: the mean reward ranked them

    specs = make_tune_trials("ppo", 2, 800, 0, 200, "pes", 0, "tiny")
    for spec, (success, cpu_s) in zip(specs, ((0.46, 100.0), (0.47, 800.0)), strict=True):
        folder = tmp_path / "trials" / spec["id"]
        folder.mkdir(parents=True)
        train = {"episodes": 8, "env_steps": 800, "updates": 1, "cpu_s": cpu_s}
        ev = {"success_rate": success, "mean_steps": 400.0, "mean_reward": -0.2}
        ev |= {"mean_crashes": 1.0, "lost_rate": 0.1, "timeout_rate": 0.4}
        record = {"spec": spec, "env_steps": 800, "train": train, "eval": ev}
        write_json(folder / "result-800.json", record)
    summary = write_tuning_report(tmp_path, specs, "", 0.0)
    assert [r["id"] for r in summary["results"]] == ["t01", "t00"]
    assert summary["best_id"] == "t00" and summary["best"] == specs[0]["values"]
    line = "Best: t00 (46.0 %), within one standard error (3.5 points over 200 episodes) of t01's "
    assert line + "47.0 % in 0.12 of its CPU time." in (tmp_path / "README.md").read_text()


def test_tune_runs_the_trials_that_resume_first_then_the_cheapest(tmp_path):
    """A round starts the trials that resume from a checkpoint before those that train from
    the start (whose checkpoint is gone, or never was), each group by the CPU time of its last
    scored round, cheapest first (unscored trials in their order)."""
    from pes.experiments.tune import make_tune_trials, run_order, write_json

    specs = make_tune_trials("ppo", 5, 800, 0, 2, "pes", 0, "tiny")
    for trial in ("t01", "t03"):
        run = tmp_path / "trials" / trial / "run"
        run.mkdir(parents=True)
        (run / "checkpoint.pt").write_bytes(b"")
    (tmp_path / "trials" / "t02" / "run").mkdir(parents=True)  # a run without a checkpoint
    for trial, cpu_s in (("t03", 10.0), ("t01", 50.0), ("t04", 20.0), ("t00", 30.0)):
        for env_steps, scale in ((400, 1.0), (800, 3.0)):  # the last round counts
            record = {"env_steps": env_steps, "train": {"cpu_s": scale * cpu_s}}
            (tmp_path / "trials" / trial).mkdir(parents=True, exist_ok=True)
            write_json(tmp_path / "trials" / trial / f"result-{env_steps}.json", record)
    order = [s["id"] for s in run_order(tmp_path, specs)]
    assert order == ["t03", "t01", "t02", "t04", "t00"]


def test_tune_report_draws_every_trial_learning_curve(tmp_path):
    """curves.png: one training curve per trial with a log, its held-out scores as dots, those
    outside the search's rounds as hollow ones."""
    import matplotlib

    matplotlib.use("Agg")
    from pes.experiments.tune import write_curves

    header = "episodes,env_steps,success_rate,avg_reward\n"
    for trial, rows in (("t00", "50,2000,0.1,-1.0\n100,4000,0.5,-0.5\n"), ("t01", "")):
        (tmp_path / "trials" / trial).mkdir(parents=True)
        (tmp_path / "trials" / trial / "progress.csv").write_text(header + rows)
    results = [
        {"id": "t00", "by_budget": {"2000": {"success_rate": 0.2}, "4000": {"success_rate": 0.6}}},
        {"id": "t01", "by_budget": {"2000": {"success_rate": 0.0}}},
    ]
    drawn = []
    real_plot = matplotlib.axes.Axes.plot
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(
            matplotlib.axes.Axes,
            "plot",
            lambda ax, *a, **k: drawn.append(a) or real_plot(ax, *a, **k),
        )
        beyond = [{"id": "t00", "env_steps": 8000, "success_rate": 0.7}]
        assert write_curves(tmp_path, results, [2000, 4000], beyond)
    assert (tmp_path / "curves.png").read_bytes().startswith(b"\x89PNG")
    # t00's curve in % over env steps, its held-out dots, its score beyond the rounds; t01
    # logged no row: nothing drawn
    assert [list(map(float, a[0])) for a in drawn] == [[2000, 4000], [2000, 4000], [8000]]
    assert [list(map(float, a[1])) for a in drawn] == [[10.0, 50.0], [20.0, 60.0], [70.0]]
    assert not write_curves(tmp_path, results[1:], [2000])
    assert not (tmp_path / "curves.png").exists()  # no stale figure beside a report without one


def test_a_trial_that_starts_over_keeps_its_scored_log_until_the_new_one_is_longer(tmp_path):
    from pes.experiments.tune import copy_run_log

    folder = tmp_path / "t01"
    (folder / "run").mkdir(parents=True)
    scored = "episodes,env_steps\n50,2000\n100,4000\n"
    (folder / "progress.csv").write_text(scored)
    (folder / "run" / "progress.csv").write_text("episodes,env_steps\n50,2000\n")
    (folder / "run" / "config.yaml").write_text("seed: 0\n")
    copy_run_log(folder)
    assert (folder / "progress.csv").read_text() == scored
    assert not (folder / "config.yaml").exists()
    further = scored + "150,6000\n"
    (folder / "run" / "progress.csv").write_text(further)
    copy_run_log(folder)
    assert (folder / "progress.csv").read_text() == further
    assert (folder / "config.yaml").read_text() == "seed: 0\n"


def test_tune_halves_the_trials_resumes_and_refuses_other_settings(tmp_path, monkeypatch):
    """pes tune's successive halving on the tiny preset: every trial is scored at half the
    budget, the better two of three go on (resuming their own runs) to the whole budget; trial
    t00 holds the preset's own values of the search space, the others sampled settings; a
    second call finds everything done; a search of other rounds keeps the trials' scores,
    one of other evaluations is refused; --report-only reports what is scored and runs
    nothing."""
    import pes.experiments.tune as tune_module
    from pes.algos.ppo import PPO_PRESETS
    from pes.errors import ConfigError
    from pes.experiments.tune import make_tune_trials, score, tune

    kwargs = dict(
        trials=3, env_steps=800, halvings=1, eval_episodes=2, preset="tiny", use_ray=False
    )
    resumed = []
    real_train = tune_module.train
    monkeypatch.setattr(
        tune_module, "train", lambda *a, **k: resumed.append(k["resume"]) or real_train(*a, **k)
    )
    summary = tune("ppo", out=tmp_path, progress=False, **kwargs)
    assert resumed == [False, False, False, True, True]  # the second round goes on
    assert summary["budgets"] == [400, 800] and summary["complete"]
    assert summary["scored"] == 3
    reached = {r["id"]: r["env_steps"] for r in summary["results"]}
    assert sorted(reached.values()) == [400, 800, 800]
    losers = [i for i, s in reached.items() if s == 400]
    halves = {r["id"]: r["by_budget"]["400"] for r in summary["results"]}
    assert score(halves[losers[0]]) == min(score(h) for h in halves.values())
    for trial, steps in reached.items():
        folder = tmp_path / "trials" / trial
        assert (folder / "result-400.json").is_file()
        assert (folder / "result-800.json").is_file() == (steps == 800)
        curve = (folder / "progress.csv").read_text()
        assert curve == (folder / "run" / "progress.csv").read_text()
        trained = json.loads((folder / "run" / "summary.json").read_text())["env_steps"]
        assert steps <= trained < steps + 8  # stopped within one step of 8 environments
    values = {r["id"]: r["values"] for r in summary["results"]}
    space = set(pes.algos.learner_class("ppo").TUNE_SPACE)
    assert set(values["t00"]) == set(values["t01"]) == space
    preset = pes.algos.build_train_config("ppo", "tiny", {}, protocol="pes").learner
    assert values["t00"] == {key: getattr(preset, key) for key in space}
    assert summary["best"] == summary["results"][0]["values"]
    assert "t01" in (tmp_path / "README.md").read_text()
    assert f"trials trained on {machine_info()['cpu']} (" in (tmp_path / "README.md").read_text()
    # the tiny runs are too short to log a row: no learning curves, and none claimed
    assert "curves.png" not in (tmp_path / "README.md").read_text()
    assert not (tmp_path / "curves.png").exists()
    again = tune("ppo", out=tmp_path, progress=False, **kwargs)
    assert again["results"] == summary["results"]
    # A preset that took a search's best since: the search is still the one it began as.
    monkeypatch.setitem(PPO_PRESETS["tiny"], "lr_actor", 1.23e-4)
    first = make_tune_trials("ppo", 3, 800, 1, 2, "pes", 0, "tiny")[0]
    assert first["values"]["lr_actor"] == 1.23e-4
    assert tune("ppo", out=tmp_path, progress=False, **kwargs)["results"] == summary["results"]
    monkeypatch.undo()
    # A search of twice the budget: its first round, 800 env steps, is scored where the
    # trials reached it; their scores at 400 are listed beside, not ranked.
    longer = tune(
        "ppo",
        out=tmp_path,
        progress=False,
        report_only=True,
        **dict(kwargs, env_steps=1600),
    )
    assert longer["budgets"] == [800, 1600] and not longer["complete"]
    assert {r["id"]: r["env_steps"] for r in longer["results"]} == {
        i: 800 for i, s in reached.items() if s == 800
    }
    assert sorted(b["id"] for b in longer["other_budgets"]) == ["t00", "t01", "t02"]
    # One round of half the budget: the second round's scores are listed, not ranked.
    shorter = tune(
        "ppo",
        out=tmp_path,
        progress=False,
        report_only=True,
        **dict(kwargs, env_steps=400, halvings=0),
    )
    assert shorter["complete"] and {r["env_steps"] for r in shorter["results"]} == {400}
    further = sorted((b["id"], b["env_steps"]) for b in shorter["other_budgets"])
    assert further == sorted((i, 800) for i, s in reached.items() if s == 800)
    assert "outside this search's rounds" in (tmp_path / "README.md").read_text()
    with pytest.raises(ConfigError, match="other settings"):
        tune("ppo", out=tmp_path, progress=False, **dict(kwargs, eval_episodes=3))
    (tmp_path / "trials" / "t00" / "result.json").write_text("{}")  # a CPU-minute trial's
    with pytest.raises(ConfigError, match="budgeted in CPU minutes"):
        tune("ppo", out=tmp_path, progress=False, **kwargs)
    (tmp_path / "trials" / "t00" / "result.json").unlink()
    # --report-only: a longer search reports the scored trials and runs none.
    partial = tune("ppo", out=tmp_path, progress=False, report_only=True, **dict(kwargs, trials=4))
    assert partial["scored"] == 3 and partial["trials"] == 4 and not partial["complete"]
    assert partial["best"] is None
    assert not (tmp_path / "trials" / "t03").exists()
    report = (tmp_path / "README.md").read_text()
    assert "3 of 4 trials scored; the search is not finished" in report


def test_a_finished_trial_is_committed_but_not_its_checkpoint():
    """A sweep committed in parts: git keeps a reproduction trial's results, logs and policy
    (what the report needs) and leaves out the checkpoints with their replay buffers."""
    import shutil
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    if shutil.which("git") is None or not (root / ".git").exists():
        pytest.skip("not a git checkout")
    trial = "results/quick/trials/cbc-tp-s0"
    paths = [
        f"{trial}/done.json",
        f"{trial}/eval_table4.json",
        f"{trial}/run/policy.pt",
        f"{trial}/run/progress.csv",
        f"{trial}/run/checkpoint.pt",
        "results/tuning/ddpg/trials/t00/result-500000.json",
        "results/tuning/ddpg/trials/t00/run/checkpoint.pt",
    ]
    ignored = subprocess.run(
        ["git", "-C", str(root), "check-ignore", "--no-index", *paths],
        capture_output=True,
        text=True,
    ).stdout.split()
    assert ignored == [
        f"{trial}/run/checkpoint.pt",
        "results/tuning/ddpg/trials/t00/run/checkpoint.pt",
    ]


def test_set_changes_every_learner_s_training_and_a_folder_keeps_one_choice(sweep, tmp_path):
    """``--set`` changes the training of every learner (not PID(PF)), the trials record it, the
    report names it, and a folder made with other settings is refused, not mixed."""
    changes = {"protocol.n_step": 1, "protocol.demonstrations": None, "env.crash_mode": "continue"}
    specs = make_trials(["pid-pf", "maddpg"], 1, "quick", False, "pes", changes)
    assert "set" not in specs[0] and specs[1]["set"] == changes
    cfg = train_config(specs[1], BUDGETS["quick"])
    assert cfg.protocol.n_step == 1 and cfg.protocol.demonstrations is None
    assert cfg.env_config().crash_mode == "continue" and cfg.protocol.greedy_envs > 0

    argv = ["reproduce", "table4", "--budget", "tiny", "--seeds", "1", "--no-ray", "--json"]
    argv += ["--methods", "maddpg", "--out", str(tmp_path), "--set", "protocol.n_step=1"]
    assert main(argv) == 0
    trial = tmp_path / "trials" / "maddpg-s0"
    assert json.loads((trial / "done.json").read_text())["spec"]["set"] == {"protocol.n_step": 1}
    assert "n_step: 1" in (trial / "run" / "config.yaml").read_text()
    assert "`--set protocol.n_step=1`" in (tmp_path / "table4.md").read_text()
    assert json.loads((tmp_path / "reproduce.json").read_text())["overrides"] == {
        "protocol.n_step": 1
    }
    out, _ = sweep
    with pytest.raises(pes.errors.ConfigError, match="cbc-s0 .* was made with other settings"):
        reproduce("table4", budget="tiny", seeds=1, out=out, methods=["cbc"], overrides=changes)
    begun = tmp_path / "begun" / "trials" / "maddpg-s0"  # a trial begun with other settings
    begun.mkdir(parents=True)
    (begun / "spec.json").write_text(json.dumps({**specs[1], "budget": "tiny"}))
    with pytest.raises(pes.errors.ConfigError, match="maddpg-s0 .* was made with other settings"):
        reproduce("table4", budget="tiny", seeds=1, out=tmp_path / "begun", methods=["maddpg"])
    # A --set that restates what the preset resolves to is the same training: the folder is
    # reported under the plain command (as after a preset adopted a --set as its default).
    tiny = make_trials(["maddpg"], 1, "tiny", False)[0]
    default = train_config(tiny, BUDGETS["tiny"]).protocol.n_step
    restated = tmp_path / "restated"
    argv[argv.index("--out") + 1 :] = [str(restated), "--set", f"protocol.n_step={default}"]
    assert main(argv) == 0
    plain = reproduce("table4", budget="tiny", seeds=1, out=restated, methods=["maddpg"])
    assert plain["skipped"] == 1 and plain["ran"] == 0
    assert "--set" not in (restated / "table4.md").read_text()


def test_cpu_scale_says_how_fast_the_machine_is_not_what_a_folder_trained(tmp_path):
    """A trial trained with ``--set cpu_scale=X`` (a CPU X times slower than the reference of
    its ``cpu_limit``) is the same trial for a command without it; the report counts its CPU
    time on the reference CPU (divided by X) and does not name the key."""
    argv = ["reproduce", "table4", "--budget", "tiny", "--seeds", "1", "--no-ray", "--json"]
    argv += ["--methods", "maddpg", "--out", str(tmp_path), "--set", "cpu_scale=2"]
    assert main(argv) == 0
    plain = reproduce("table4", budget="tiny", seeds=1, out=tmp_path, methods=["maddpg"])
    assert plain["skipped"] == 1 and plain["ran"] == 0
    trial = tmp_path / "trials" / "maddpg-s0"
    done = json.loads((trial / "done.json").read_text())
    train = done["train"]
    assert done["spec"]["set"] == {"cpu_scale": 2} and train["cpu_scale"] == 2
    assert reference_cpu_s(train) == pytest.approx(train["cpu_s"] / 2)
    logged = read_progress(trial / "run" / "progress.csv")["cpu_s"]
    curve = _curves(tmp_path, make_trials(["maddpg"], 1, "tiny", False), {"maddpg-s0": done})
    assert np.allclose(curve["maddpg"][0]["cpu_s"], logged / 2)
    assert "--set cpu_scale" not in (tmp_path / "table4.md").read_text()
    assert (
        f"trials trained on {machine_info()['cpu']} (1, cpu_scale 2)"
        in (tmp_path / "table4.md").read_text()
    )


def test_recorded_commands_name_folders_as_the_repository_has_them(tmp_path):
    from pes.paths import recorded_command

    repo = tmp_path / "clone"
    (repo / ".git").mkdir(parents=True)
    out = repo / "results" / "quick"
    words = ["pes", "reproduce", "--out", str(out), f"--outside={repo / 'results' / 'b m'}"]
    assert recorded_command(words) == "pes reproduce --out results/quick '--outside=results/b m'"
    # Outside any git work tree, and relative paths, stay as they were given.
    elsewhere = tmp_path / "elsewhere" / "runs"
    assert recorded_command(["pes", "tune", "--out", str(elsewhere)]).endswith(str(elsewhere))
    assert recorded_command(["pes", "tune", "--out", "runs/x"]) == "pes tune --out runs/x"


def test_table5_gives_each_seed_s_window_counts():
    from pes.experiments.report import table5

    def record(train, test):
        errors = [0.001 * (k + 1) for k in range(5)]
        return {
            "table5": {
                "pursuers": "cbc-tp",
                "train_windows": train,
                "test_windows": test,
                "fde": errors,
                "ade": errors,
                "constant_position": {"fde": errors, "ade": errors},
            }
        }

    specs = [{"id": f"tpnet-s{s}", "kind": "tpnet"} for s in range(2)]
    meta = dict(
        budget="tiny",
        protocol="pes",
        overrides={},
        seeds=2,
        eval_episodes=8,
        evader="`flee` evader",
        command="pes reproduce table5",
        hardware="cpu",
    )
    text = table5(specs, {"tpnet-s0": record(34733, 16902), "tpnet-s1": record(35470, 15673)}, meta)
    assert "trained on between 34,733 and 35,470 windows" in text
    assert "measured on between 15,673 and 16,902 held-out windows" in text
    same = table5(specs, {"tpnet-s0": record(900, 300), "tpnet-s1": record(900, 300)}, meta)
    assert "trained on 900 windows" in same and "measured on 300 held-out windows" in same


def test_the_recorded_commit_is_dirty_only_when_the_source_differs(tmp_path):
    import subprocess

    from pes.experiments.budgets import source_commit

    package = tmp_path / "src" / "pes"
    package.mkdir(parents=True)
    (package / "step.py").write_text("x = 1\n")
    (tmp_path / "README.md").write_text("results\n")
    git = ["git", "-C", str(tmp_path), "-c", "user.name=t", "-c", "user.email=t@t"]
    for args in (["init", "-q"], ["add", "."], ["commit", "-qm", "one"]):
        subprocess.run([*git, *args], check=True)
    head = subprocess.run([*git, "rev-parse", "HEAD"], capture_output=True, text=True).stdout
    assert source_commit(package) == head.strip()
    (tmp_path / "README.md").write_text("a regenerated report\n")  # not the source
    assert source_commit(package) == head.strip()
    (package / "step.py").write_text("x = 2\n")
    assert source_commit(package) == head.strip() + "-dirty"


def test_a_scenario_changes_every_method_s_task_in_training_and_evaluation(tmp_path):
    """``--scenario`` (the positive control's slower evader) reaches PID(PF)'s evaluation, the
    learner's training and its evaluation, is named by the report, and a folder keeps one."""
    slow = {"evader_max_speed": 8.0}
    reproduce("table4", budget="tiny", seeds=1, methods=["pid-pf", "maddpg"], out=tmp_path,
              use_ray=False, progress=False, scenario=slow)  # fmt: skip
    trained = yaml.safe_load(
        (tmp_path / "trials" / "maddpg-s0" / "run" / "config.yaml").read_text()
    )
    assert trained["env"]["evader_max_speed"] == 8.0
    for trial in ("pid-pf-s0", "maddpg-s0"):
        done = json.loads((tmp_path / "trials" / trial / "done.json").read_text())
        assert done["spec"]["scenario"] == slow
    assert eval_config(BUDGETS["tiny"], 0, slow).evader_max_speed == 8.0
    assert "`--scenario evader_max_speed=8.0`" in (tmp_path / "table4.md").read_text()
    # and the figures' recorded episodes (Figs. 11-12) play on the same task
    figure_task = episode_config(json.loads((tmp_path / "reproduce.json").read_text()), 1)
    assert figure_task.evader_max_speed == 8.0 and figure_task.damaged == 1
    with pytest.raises(ConfigError, match="other settings"):
        reproduce("table4", budget="tiny", seeds=1, methods=["pid-pf"], out=tmp_path,
                  use_ray=False, progress=False)  # fmt: skip
    with pytest.raises(ConfigError, match="evader_max_sped"):
        reproduce("table4", budget="tiny", seeds=1, methods=["pid-pf"], out=tmp_path / "x",
                  use_ray=False, progress=False, scenario={"evader_max_sped": 8})  # fmt: skip
