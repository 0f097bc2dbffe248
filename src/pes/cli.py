"""The ``pes`` command: a thin layer over the library.

Every sub-command has ``--help``; with ``--json`` it prints exactly one JSON object on stdout
(progress goes to stderr). A user mistake ends with a one-line ``error: ...`` on stderr and exit
status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any, NoReturn

from pes import __version__
from pes.errors import CheckpointError, ConfigError, PESError, TrainingInterruptedError
from pes.paths import prepare_output, prepare_output_dir, recorded_command
from pes.sim.config import EnvConfig
from pes.sim.env import resolve_device
from pes.strict import load_yaml, parse_override

EXIT_USER_ERROR = 2


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose mistakes end in one line on stderr and exit status 2 (docs/cli.md),
    not argparse's usage block; ``--help`` still prints the full usage."""

    def error(self, message: str) -> NoReturn:
        text = " ".join(message.split())
        self.exit(EXIT_USER_ERROR, f"{self.prog}: error: {text} (see '{self.prog} --help')\n")


# --- shared options ------------------------------------------------------------------------


def _add_set_option(parser, help: str) -> None:
    """``--set KEY=VALUE`` (repeatable) into ``args.overrides``; ``parser`` a parser or group."""
    parser.add_argument(
        "--set", metavar="KEY=VALUE", action="append", default=[], dest="overrides", help=help
    )


def _add_scenario_options(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("scenario")
    group.add_argument("--config", metavar="F.yaml", help="EnvConfig values from a YAML file")
    _add_set_option(
        group,
        "override one EnvConfig key (repeatable), e.g. "
        "--set num_pursuers=8 --set dynamics=point_mass",
    )


def _add_ray_timeout(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--ray-timeout",
        type=_positive_float,
        default=30.0,
        metavar="S",
        help="seconds to wait for the cluster at --ray-address to answer (default: 30)",
    )


def _overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The ``--set KEY=VALUE`` options as a mapping (the values read as YAML), in order."""
    return dict(parse_override(text) for text in args.overrides)


def _scenario(args: argparse.Namespace, **defaults: Any) -> EnvConfig:
    """The EnvConfig of ``--config`` and ``--set`` on top of ``defaults``."""
    values: dict[str, Any] = dict(defaults)
    if args.config:
        values.update(load_yaml(args.config))
    values.update(_overrides(args))
    return EnvConfig.from_dict(values)


def _print_json(obj: dict[str, Any]) -> None:
    print(json.dumps(obj, indent=2, default=str))


def _say(args: argparse.Namespace, text: str) -> None:
    """Human-readable output, silenced by --json."""
    if not getattr(args, "json", False):
        print(text)


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got '{text}'") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text}")
    return value


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got '{text}'") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def _non_negative(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got '{text}'") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {value}")
    return value


def _opponent() -> dict[str, Any]:
    """The default evader of evaluations: the shipped DDPG evader calibrated to the paper's, as
    in the paper (``flee`` if this installation has none)."""
    from pes.models import default_evader_policy

    return {"evader_policy": default_evader_policy()}


# --- policies --------------------------------------------------------------------------------


def make_policy(name: str, config: EnvConfig, seed: int = 0, device: str = "cpu"):
    """The pursuer policy called ``name`` for the scenario ``config``: a scripted policy, a
    shipped model (``cbc-tp``), or a policy file, checkpoint or run folder."""
    from pes.algos.loading import is_policy_spec, load_pursuer_policy
    from pes.policies import SCRIPTED

    if name in SCRIPTED:
        return SCRIPTED[name](config, seed=seed)
    if _is_benchmarl_checkpoint(name):
        from pes.benchmarl.reload import load_benchmarl_policy

        return load_benchmarl_policy(name, config, device)
    if is_policy_spec(name):
        return load_pursuer_policy(name, config, device)[0]
    known = ", ".join([*SCRIPTED, "cbc-tp"])
    raise ConfigError(
        f"unknown policy '{name}' (available: {known}, or a policy file / checkpoint path)"
    )


def _is_benchmarl_checkpoint(name: str) -> bool:
    """A BenchMARL experiment's ``checkpoints/*.pt`` (see :mod:`pes.benchmarl.reload`), told
    apart without importing BenchMARL."""
    path = Path(name)
    return (
        path.suffix == ".pt"
        and path.parent.name == "checkpoints"
        and (path.parent.parent / "config.pkl").is_file()
    )


def _run_episode(config: EnvConfig, policy_name: str, seed: int, device: str = "cpu"):
    """One recorded episode of ``policy_name``: returns the episode record."""
    from pes.record import record_episode

    policy = make_policy(policy_name, config, seed=seed, device=device)
    return record_episode(policy, config, seed=seed, device=device)


def _progress_line(text: str) -> None:
    """One line of progress on stderr (stdout carries --json's object alone)."""
    print(text, file=sys.stderr, flush=True)


def _add_threads_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--threads",
        type=_positive,
        default=1,
        help="torch CPU threads (default: 1, which holds its speed when other work shares "
        "the cores; more help only on otherwise idle cores, see docs/performance.md)",
    )


def _set_threads(threads: int) -> None:
    import torch

    torch.set_num_threads(threads)


def _add_test_options(p: argparse.ArgumentParser, disturbance: bool = False) -> None:
    """--damaged and --disturbance, the paper's test conditions (pes eval, pes render; the
    disturbance is on by default where ``disturbance``)."""
    p.add_argument(
        "--damaged",
        type=_non_negative,
        default=None,
        help="disable K random pursuers in every episode (anti-damage test)",
    )
    p.add_argument(
        "--disturbance",
        action=argparse.BooleanOptionalAction,
        default=disturbance,
        help="random 5 %% weight pushes (the paper's evaluation setting; default: "
        + ("on, as pes demo" if disturbance else "off")
        + ")",
    )


def _test_scenario(args: argparse.Namespace) -> EnvConfig:
    """The scenario of pes eval / pes render: crashes disable a pursuer, the default opponent,
    and the --damaged / --disturbance test conditions, under the scenario options."""
    defaults: dict[str, Any] = {"crash_mode": "disable", **_opponent()}
    if args.disturbance:
        defaults["disturbance"] = True
    if args.damaged is not None:
        defaults["damaged"] = args.damaged
    return _scenario(args, **defaults)


# --- commands --------------------------------------------------------------------------------


def cmd_demo(args: argparse.Namespace) -> int:
    from pes.models import is_shipped
    from pes.record import save_gif, save_record

    start = time.time()
    config = _scenario(args, disturbance=True, crash_mode="disable", **_opponent())
    if args.policy is None:
        args.policy = "cbc-tp" if is_shipped("cbc-tp") else "pid-pf"
    out = prepare_output_dir(args.out)
    record = _run_episode(config, args.policy, args.seed)
    record_path = save_record(record, out / "episode.json")
    gif_path = save_gif(record, out / "episode.gif", every=2)
    outcome = record["outcome"]
    summary = {
        "policy": args.policy,
        "evader": config.evader_policy,
        "seed": args.seed,
        "success": outcome["success"],
        "steps": outcome["steps"],
        "crashes": outcome["crashes"],
        "gif": str(gif_path),
        "record": str(record_path),
        "seconds": round(time.time() - start, 2),
    }
    if args.json:
        _print_json(summary)
    else:
        verdict = "captured the evader" if outcome["success"] else "did not capture the evader"
        print(
            f"{config.num_pursuers} {args.policy} pursuers {verdict} in {outcome['steps']} "
            f"steps ({outcome['steps'] * config.dt:.1f} s) with {outcome['crashes']} crashes "
            f"(evader: {config.evader_policy}, seed {args.seed})."
        )
        print(f"GIF:    {gif_path}\nrecord: {record_path}   (view it: pes view {record_path})")
    return 0


def cmd_eval(args: argparse.Namespace) -> int:
    from pes.evaluate import evaluate

    config = _test_scenario(args)
    _set_threads(args.threads)
    policy = make_policy(args.policy, config, seed=args.seed, device=args.device)
    start = time.time()
    result = evaluate(
        policy,
        config,
        episodes=args.episodes,
        num_envs=args.num_envs,
        seed=args.seed,
        device=args.device,
        progress=True,  # a bar on stderr; --json's object alone goes to stdout
    )
    summary = {
        "policy": args.policy,
        **result.summary(),
        "damaged": config.damaged,
        "disturbance": config.disturbance,
        "crash_mode": config.crash_mode,
        "evader": config.evader_policy,
        "seconds": round(time.time() - start, 2),
    }
    if args.json:
        _print_json(summary)
    else:
        print(
            f"{args.policy}: success {100 * result.success_rate:.1f} % "
            f"(± {100 * result.success_rate_ci95:.1f}), mean steps {result.mean_steps:.1f}, "
            f"average reward {result.mean_reward:.3f}, crashes/episode "
            f"{result.mean_crashes:.2f} over {result.episodes} episodes; failed "
            f"{100 * result.lost_rate:.1f} % by losing the swarm, "
            f"{100 * result.timeout_rate:.1f} % at the step limit"
        )
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    from pes.record import load_record, save_gif, save_mp4, save_plot, save_record

    out = Path(args.out)
    suffix = out.suffix.lower()
    writers = {
        ".gif": lambda record, path: save_gif(record, path, every=args.every),
        ".mp4": lambda record, path: save_mp4(record, path, every=args.every),
        ".png": save_plot,
        ".json": save_record,
    }
    if suffix not in writers:
        raise ConfigError(f"--out must end in .gif, .mp4, .png or .json, got '{out.name}'")
    prepare_output(out)  # before any episode is run
    if args.record is not None:
        records = [load_record(args.record)]
    else:
        config = _test_scenario(args)
        records = (_run_episode(config, args.policy, args.seed + k) for k in range(args.episodes))
    many = args.record is None and args.episodes > 1
    written = []
    for k, record in enumerate(records):
        path = out.with_name(f"{out.stem}_{k}{out.suffix}") if many else out
        writers[suffix](record, path)
        written.append(
            {
                "path": str(path),
                **{k2: record["outcome"][k2] for k2 in ("success", "steps", "crashes")},
            }
        )
        _say(
            args,
            f"wrote {path} (success={record['outcome']['success']}, "
            f"steps={record['outcome']['steps']})",
        )
    if args.json:
        _print_json({"files": written})
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    import webbrowser

    from pes.record.viewer import write_page

    page, record = write_page(args.record, args.out)
    opened = webbrowser.open(page.resolve().as_uri()) if args.open else False
    outcome = record["outcome"]
    if args.json:
        _print_json(
            {
                "record": args.record,
                "page": str(page),
                "bytes": page.stat().st_size,
                "steps": len(record["frames"]) - 1,
                "success": outcome["success"],
                "opened": opened,
            }
        )
    else:
        print(f"wrote {page} ({len(record['frames']) - 1} steps); open it in a browser")
        if args.open and not opened:
            print("(no browser could be started here)", file=sys.stderr)
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    from pes.algos import build_train_config, train

    values: dict[str, Any] = {}
    if args.config:
        values.update(load_yaml(args.config))
    if "algo" in values and values.pop("algo") != args.algo:
        raise ConfigError("the config file names another algo than --algo")
    values.pop("preset", None)
    protocol = args.protocol
    recorded = values.get("protocol")
    if isinstance(recorded, dict) and "name" in recorded:  # a run's config.yaml
        recorded = dict(recorded)
        name = str(recorded.pop("name")).removesuffix("+custom")
        values["protocol"] = recorded
        protocol = protocol or name
    values.update(_overrides(args))
    cfg = build_train_config(args.algo, args.preset, values, protocol=protocol)
    out = Path(args.out or f"runs/{args.algo}")
    _say(
        args,
        f"training {args.algo} ({args.preset} preset, {cfg.protocol.name} protocol) into {out}",
    )
    summary = train(cfg, out, resume=args.resume, progress=not args.json)
    if args.json:
        _print_json(summary)
    else:
        print(
            f"done: {summary['episodes']} episodes, {summary['env_steps']} env steps, "
            f"{summary['updates']} updates in {summary['wall_s']:.0f} s "
            f"(stopped by {summary['stopped_by']})"
        )
        if "eval" in summary:
            ev = summary["eval"]
            print(
                f"evaluation vs {ev['opponent']}: success {100 * ev['success_rate']:.1f} %, "
                f"mean steps {ev['mean_steps']:.1f} over {ev['episodes']} episodes"
            )
        print(f"policy: {out / 'policy.pt'}   logs: {out / 'progress.csv'}, {out / 'tb'}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from pes.sim.bench import run_benchmark

    config = _scenario(args)
    _set_threads(args.threads)
    results = run_benchmark(
        config,
        args.num_envs,
        device=args.device,
        steps=args.steps,
        compile=args.compile,
        log=_progress_line if args.json else print,  # with --json, progress goes to stderr
    )
    if args.json:
        _print_json(results)
    return 0


def cmd_export_onnx(args: argparse.Namespace) -> int:
    from pes.algos.cbc_tp_onnx import export_onnx

    out = Path(args.out)
    if out.suffix.lower() != ".onnx":
        raise ConfigError(f"OUT must end in .onnx, got '{out.name}'")
    prepare_output(out)
    summary = export_onnx(args.checkpoint, out, opset=args.opset, check=args.check)
    error = summary.get("max_abs_error")
    if error is not None and not math.isfinite(error):
        raise CheckpointError(
            f"onnxruntime's actions from {out} are not finite (max abs error {error}): "
            "the exported graph does not compute the policy"
        )
    if args.json:
        _print_json(summary)
    else:
        sizes = summary["num_pursuers"]
        print(
            f"wrote {out} ({summary['algo']}, {summary['bytes'] / 1e6:.2f} MB, opset "
            f"{summary['opset']}, {sizes} pursuers, dynamic batch)"
        )
        for kind in ("inputs", "outputs"):
            shapes = ", ".join(f"{k} {v}" for k, v in summary[kind].items())
            print(f"  {kind}: {shapes}")
        if "max_abs_error" in summary:
            print(
                f"  onnxruntime vs PyTorch: max abs error {summary['max_abs_error']:.1e} on "
                f"random inputs with {summary['checked_num_pursuers']} pursuers"
            )
    return 0


def cmd_reproduce(args: argparse.Namespace) -> int:
    from pes.experiments.reproduce import reproduce

    out = args.out or f"runs/reproduce-{args.budget}"
    _say(args, f"reproducing {args.target} ({args.budget} budget, {args.seeds} seed(s)) into {out}")
    summary = reproduce(
        args.target,
        budget=args.budget,
        seeds=args.seeds,
        out=out,
        methods=args.methods,
        ray_address=args.ray_address,
        ray_timeout=args.ray_timeout,
        use_ray=False if args.no_ray else None,
        progress=not args.json,
        command=recorded_command(["pes", *sys.argv[1:]]) if sys.argv[1:2] == ["reproduce"] else "",
        parallel=args.parallel,
        report_only=args.report_only,
        protocol=args.protocol,
        outside=args.outside,
        overrides=_overrides(args),
        scenario=dict(parse_override(text) for text in args.scenario),
    )
    if args.json:
        _print_json(summary)
    else:
        print(
            f"done: {summary['ran']} trial(s) run ({summary['runner']}), "
            f"{summary['skipped']} already finished, "
            f"{summary['unfinished']} not run, {summary['seconds']:.0f} s; "
            f"wrote in {out}: " + ", ".join(f for f in summary["files"] if "/" not in f)
        )
    return 0


def cmd_tune(args: argparse.Namespace) -> int:
    from pes.experiments.tune import tune

    out = args.out or f"results/tuning/{args.algo}"
    _say(
        args,
        f"tuning {args.algo} ({args.protocol} protocol): {args.trials} trials, "
        f"{args.halvings} halving{'' if args.halvings == 1 else 's'}, up to "
        + (f"{args.env_steps:,} env steps" if args.env_steps else "the preset's env steps")
        + f" into {out}",
    )
    summary = tune(
        args.algo,
        trials=args.trials,
        env_steps=args.env_steps,
        halvings=args.halvings,
        eval_episodes=args.eval_episodes,
        protocol=args.protocol,
        seed=args.seed,
        out=out,
        use_ray=False if args.no_ray else None,
        ray_address=args.ray_address,
        ray_timeout=args.ray_timeout,
        parallel=args.parallel,
        progress=not args.json,
        # The command that runs the trials (a --report-only run names it, not itself).
        command=recorded_command(["pes", *(a for a in sys.argv[1:] if a != "--report-only")])
        if sys.argv[1:2] == ["tune"]
        else "",
        report_only=args.report_only,
        preset=args.preset,
    )
    if args.json:
        _print_json(summary)
    else:
        ranked = {r["id"]: r for r in summary["results"]}
        lead = ranked.get(summary["best_id"]) or next(iter(ranked.values()), None)
        print(
            f"{summary['scored']} of {summary['trials']} trials scored; "
            + ("best: " if summary["complete"] else "leading so far: ")
            + (
                f"{lead['id']} {lead['values'] or '(quick preset)'}: "
                f"{100 * lead['success_rate']:.1f} % in {lead['mean_steps']:.0f} steps "
                f"after {lead['env_steps']:,} env steps"
                if lead
                else "none yet"
            )
            + f"; report: {out}/README.md"
        )
    return 0


# --- the parser ------------------------------------------------------------------------------


def _add_demo(sub) -> None:
    """The parser of ``pes demo``."""
    p = sub.add_parser(
        "demo",
        help="one episode of the best shipped policy: GIF + record",
        description="Run one episode of the best shipped policy on the default "
        "map (with disturbance, crash_mode=disable), write a GIF and an episode "
        "record, and print a summary. No training, no network.",
    )
    p.add_argument("--out", default="pes-demo", help="output folder (default: pes-demo)")
    p.add_argument("--seed", type=int, default=0, help="episode seed (default: 0)")
    p.add_argument(
        "--policy",
        default=None,
        help="pursuer policy (default: the shipped cbc-tp swarm, or pid-pf without one)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    _add_scenario_options(p)
    p.set_defaults(func=cmd_demo)


def _add_eval(sub) -> None:
    """The parser of ``pes eval``."""
    p = sub.add_parser(
        "eval",
        help="evaluate a policy over many episodes",
        description="Evaluate pursuer policy over N episodes (crash_mode=disable "
        "unless set otherwise). Prints success rate, mean episode steps and "
        "average reward.",
    )
    p.add_argument(
        "--policy",
        required=True,
        help="pid-pf, random, cbc-tp (the shipped swarm), a policy.pt / checkpoint / run folder, "
        "or a BenchMARL checkpoint",
    )
    p.add_argument("--episodes", type=_positive, default=100, help="episodes (default: 100)")
    _add_test_options(p)
    p.add_argument("--seed", type=int, default=0, help="seed of the first environment")
    p.add_argument(
        "--num-envs",
        type=_positive,
        default=100,
        help="environments stepped together (default: 100)",
    )
    p.add_argument("--device", default="cpu", help="cpu or cuda")
    _add_threads_option(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    _add_scenario_options(p)
    p.set_defaults(func=cmd_eval)


def _add_render(sub) -> None:
    """The parser of ``pes render``."""
    p = sub.add_parser(
        "render",
        help="record episodes as GIF, MP4, PNG plot or JSON",
        description="Record episodes of a policy (or redraw a saved episode record) to "
        "FILE.gif or FILE.mp4 (top-down animation; MP4 is H.264), FILE.png (every vehicle's "
        "path, damaged pursuers, the capture point and TP Net's predictions on the map) or "
        "FILE.json (episode record, for pes view).",
    )
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument(
        "--policy",
        help="pid-pf, random, cbc-tp (the shipped swarm), or a policy.pt / checkpoint / run folder",
    )
    source.add_argument(
        "--record", metavar="FILE.json", help="draw this episode record instead of running one"
    )
    p.add_argument(
        "--out", required=True, metavar="FILE", help="FILE.gif, FILE.mp4, FILE.png or FILE.json"
    )
    p.add_argument(
        "--episodes",
        type=_positive,
        default=1,
        help="episodes to record; more than one writes FILE_0, FILE_1, ...",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the first episode")
    p.add_argument(
        "--every",
        type=_positive,
        default=2,
        help="GIF/MP4: draw every K-th step (default: 2)",
    )
    _add_test_options(p, disturbance=True)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    _add_scenario_options(p)
    p.set_defaults(func=cmd_render)


def _add_view(sub) -> None:
    """The parser of ``pes view``."""
    p = sub.add_parser(
        "view",
        help="the interactive 3-D replay of an episode record (an HTML page)",
        description="Write a self-contained HTML page (works offline, from disk) that replays "
        "an episode record in 3-D: buildings, vehicles, trails, predictions, capture radius, "
        "with a timeline and an orbiting camera.",
    )
    p.add_argument("record", metavar="EPISODE.json", help="an episode record (pes render / demo)")
    p.add_argument("--out", metavar="PAGE.html", help="the page (default: EPISODE.html)")
    p.add_argument("--open", action="store_true", help="open the page in the web browser")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_view)


def _add_train(sub) -> None:
    """The parser of ``pes train``."""
    from pes.algos import ALGOS  # noqa: PLC0415 - loads every learner

    p = sub.add_parser(
        "train",
        help="train a learner (progress bar, CSV/TensorBoard logs, checkpoints)",
        description="Train an algorithm into --out: config.yaml, progress.csv, tb/, "
        "checkpoint.pt (every checkpoint_every minutes, atomically), policy.pt and summary.json "
        "(with the final evaluation) at the end. --resume continues from checkpoint.pt; Ctrl-C "
        "stops at the next step with a checkpoint written.",
    )
    p.add_argument("--algo", required=True, choices=list(ALGOS), help="the algorithm")
    p.add_argument(
        "--preset",
        default="quick",
        choices=["quick", "gpu", "paper", "tiny"],
        help="budget preset: quick (laptop CPU, default), gpu (the quick settings at a GPU's "
        "sizes: thousands of environments, large batches, 10x the budget; --set device=cpu runs "
        "it on a CPU), paper (the paper's settings), tiny (tests)",
    )
    p.add_argument(
        "--protocol",
        choices=["paper", "pes"],
        help="training protocol: paper (the paper's reward and rules, no aids; the default of "
        "--preset paper) or pes (the aids that make learning feasible on a CPU budget; the "
        "default otherwise). docs/training.md lists the aids",
    )
    p.add_argument(
        "--config",
        metavar="F.yaml",
        help="settings from a YAML file, e.g. a run's config.yaml to train it again",
    )
    _add_set_option(
        p,
        "override a setting (repeatable): a run or learner key, env.KEY for the scenario, "
        "protocol.AID[.KEY] for the protocol, e.g. --set batch_size=256 "
        "--set env.num_pursuers=4 --set protocol.n_step=5 --set protocol.demonstrations=null",
    )
    p.add_argument("--out", help="run folder (default: runs/ALGO)")
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    p.add_argument("--json", action="store_true", help="print one JSON object at the end")
    p.set_defaults(func=cmd_train)


def _add_bench(sub) -> None:
    """The parser of ``pes bench``."""
    p = sub.add_parser(
        "bench",
        help="simulator throughput in env-steps/s",
        description="Measure simulator throughput (env-steps/s) with random "
        "pursuer actions, after a warm-up, at each --num-envs.",
    )
    p.add_argument(
        "--num-envs",
        type=_positive,
        nargs="+",
        default=[1, 64, 1024],
        help="batch sizes (default: 1 64 1024)",
    )
    p.add_argument("--device", default="cpu", help="cpu or cuda")
    p.add_argument("--steps", type=_positive, default=200, help="timed steps per size")
    p.add_argument(
        "--compile",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="fuse the step with torch.compile (compiles some 40 s per size first; "
        "default: off, the step as pes.make_env gives it)",
    )
    _add_threads_option(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    _add_scenario_options(p)
    p.set_defaults(func=cmd_bench)


def _add_export_onnx(sub) -> None:
    """The parser of ``pes export-onnx``."""
    p = sub.add_parser(
        "export-onnx",
        help="a CBC-TP / CBC policy (actor + TP Net) as one ONNX graph",
        description="Export the actor of a cbc-tp or cbc policy, with its TP Net, as one ONNX "
        "graph with a dynamic number of pursuers and a dynamic batch (inputs obs, alive, "
        "history; outputs actions and prediction; see docs/export.md). Then run the file with "
        "onnxruntime on random inputs and report its largest difference from PyTorch.",
    )
    p.add_argument(
        "checkpoint",
        metavar="CHECKPOINT",
        help="cbc-tp (the shipped swarm), or a policy.pt / checkpoint.pt / run folder",
    )
    p.add_argument("out", metavar="OUT.onnx", help="the ONNX file to write")
    p.add_argument(
        "--opset",
        type=_positive,
        default=None,
        help="ONNX opset, 18 or above (default: torch's, 20 with torch 2.13)",
    )
    p.add_argument(
        "--check",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="compare onnxruntime with PyTorch on random inputs (default: on)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_export_onnx)


def _add_reproduce(sub) -> None:
    """The parser of ``pes reproduce``."""
    p = sub.add_parser(
        "reproduce",
        help="run the paper's experiments: tables IV-VI and figures 6-13",
        description="Train and evaluate every method over several seeds and write the paper's "
        "tables (Markdown, beside the paper's numbers), figures (PNG) and each trial's CSV log "
        "into --out. Trials run as Ray Tune trials (one CPU each) when Ray is installed, else "
        "one after the other; re-running skips finished trials and resumes interrupted ones "
        "(see docs/reproduce.md).",
    )
    p.add_argument("target", choices=["table4", "table5", "table6", "figures", "all"])
    p.add_argument(
        "--budget",
        choices=["quick", "paper", "tiny"],
        default="quick",
        help="training presets and evaluation size: quick (laptop CPU), paper (the paper's "
        "settings), tiny (a one-minute check of the pipeline) (default: quick)",
    )
    p.add_argument("--seeds", type=_positive, default=3, help="seeds per method (default: 3)")
    p.add_argument(
        "--protocol",
        choices=["pes", "paper"],
        default=None,
        help="training protocol of every learner (default: paper under --budget paper, pes "
        "otherwise; see docs/training.md)",
    )
    p.add_argument(
        "--methods",
        nargs="+",
        default=None,
        metavar="M",
        help="only these methods (default: every one available: pid-pf and the learners)",
    )
    p.add_argument(
        "--ray-address",
        default=None,
        metavar="A",
        help="run the trials on this Ray cluster (its nodes must see --out); default: a local "
        "Ray instance",
    )
    _add_ray_timeout(p)
    p.add_argument("--no-ray", action="store_true", help="run the trials here, one at a time")
    p.add_argument(
        "--parallel",
        type=_non_negative,
        default=0,
        metavar="N",
        help="with Ray, at most N trials at once (default 0: one per CPU)",
    )
    p.add_argument(
        "--report-only",
        action="store_true",
        help="run no trial: write the tables and figures of the trials finished so far",
    )
    p.add_argument(
        "--outside",
        default=None,
        metavar="DIR",
        help="outside reference runs (python -m pes.benchmarl.reference, one subfolder each) "
        "to show beside the methods in Table IV",
    )
    _add_set_option(
        p,
        "change a setting of every learner's training, as pes train --set (repeatable), "
        "e.g. --set protocol.n_step=1 to take an aid away; the report names the changes; "
        "use a new --out for each choice",
    )
    p.add_argument(
        "--scenario",
        metavar="KEY=VALUE",
        action="append",
        default=[],
        help="change one EnvConfig key of every method's task, in training and evaluation "
        "alike (repeatable), e.g. --scenario evader_max_speed=8 for the positive control of "
        "an evader slower than the pursuers; the report names it; use a new --out for each",
    )
    p.add_argument("--out", default=None, help="output folder (default: runs/reproduce-BUDGET)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_reproduce)


def _add_tune(sub) -> None:
    """The parser of ``pes tune``."""
    from pes.algos import ALGOS  # noqa: PLC0415 - loads every learner

    p = sub.add_parser(
        "tune",
        help="the same hyper-parameter search for any learner",
        description="Random search over the learner's key settings (its TUNE_SPACE: learning "
        "rates, exploration or entropy, batch size, network width): each trial trains the "
        "quick preset with its settings under --protocol on one thread, with a budget of env "
        "steps (the same work on any machine), spent by successive halving: every trial to "
        "--env-steps / 2^--halvings, the better half on to twice that, and so on to "
        "--env-steps; each score is on the same --eval-episodes held-out episodes; trial t00 "
        "is the preset itself. "
        "Trials run under Ray when it is installed, else one after the other; re-running "
        "resumes. Writes OUT/tuning.json and OUT/README.md (see docs/reproduce.md).",
    )
    p.add_argument("--algo", required=True, choices=[a for a in ALGOS if a != "evader-ddpg"])
    p.add_argument("--protocol", choices=["pes", "paper"], default="pes", help="training protocol")
    p.add_argument(
        "--preset",
        choices=["quick", "gpu", "paper", "tiny"],
        default="quick",
        help="what each trial trains (default: quick; gpu: on a GPU; tiny: a seconds-long check)",
    )
    p.add_argument("--trials", type=_positive, default=8, help="trials (default: 8)")
    p.add_argument(
        "--env-steps",
        type=_positive,
        default=0,
        metavar="N",
        help="env steps of the trials that train longest (default: half the preset's budget, "
        "1,000,000 for quick; the other presets need it)",
    )
    p.add_argument(
        "--halvings",
        type=_non_negative,
        default=1,
        metavar="K",
        help="rounds of successive halving before the full budget (default: 1, so 8 trials: 8 "
        "to half of --env-steps, the better 4 to all of it; 0: every trial to all)",
    )
    p.add_argument(
        "--eval-episodes",
        type=_positive,
        default=200,
        help="held-out evaluation episodes per trial (default: 200)",
    )
    p.add_argument("--seed", type=_non_negative, default=0, help="training and search seed")
    p.add_argument("--ray-address", default=None, metavar="A", help="a Ray cluster to use")
    _add_ray_timeout(p)
    p.add_argument("--no-ray", action="store_true", help="run the trials here, one at a time")
    p.add_argument(
        "--parallel",
        type=_non_negative,
        default=0,
        metavar="N",
        help="with Ray, at most N trials at once (default 0: one per CPU)",
    )
    p.add_argument(
        "--report-only",
        action="store_true",
        help="run no trial: write OUT/tuning.json and OUT/README.md of the trials scored so far",
    )
    p.add_argument("--out", default=None, help="output folder (default: results/tuning/ALGO)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_tune)


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="pes",
        description="PES: multi-quadcopter pursuit-evasion (Game of Drones, TNNLS 2022).",
    )
    parser.add_argument("--version", action="version", version=f"pes {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    sub.required = True
    _add_demo(sub)
    _add_eval(sub)
    _add_render(sub)
    _add_view(sub)
    _add_train(sub)
    _add_bench(sub)
    _add_export_onnx(sub)
    _add_reproduce(sub)
    _add_tune(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if getattr(args, "device", None) is not None:
            resolve_device(args.device)  # before any network is moved there
        return args.func(args)
    except TrainingInterruptedError as exc:
        print(f"stopped: {exc}", file=sys.stderr)
        return 130
    except PESError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader of stdout went away (``pes eval --json | head``): stop quietly, and point
        # stdout at /dev/null so that the interpreter's final flush does not raise again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 128 + 13  # as a process killed by SIGPIPE


if __name__ == "__main__":
    sys.exit(main())
