"""The TorchRL interface (pes.torchrl) and the BenchMARL task family (pes.benchmarl).

Skipped unless the extras are installed (failing instead under ``PES_REQUIRE_EXTRAS=1``, as in
CI): ``pip install -e ".[test,torchrl]"`` for the TorchRL tests, ``pip install -e
".[test,benchmarl]"`` for all of them.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
import torch

from tests.conftest import optional

optional("torchrl")

from tensordict import TensorDict  # noqa: E402
from torchrl.envs.utils import check_env_specs  # noqa: E402

import pes  # noqa: E402
from pes.sim import scenario  # noqa: E402
from pes.torchrl import GROUP, PESTorchRLEnv, flatten_observation  # noqa: E402

SHORT = {"max_steps": 12}  # episodes end inside a 50-step rollout


def fixed_policy(seed: int = 0):
    """A random but reproducible policy: uniform actions in [-1, 1]^2 from its own generator."""
    gen = torch.Generator().manual_seed(seed)

    def policy(td):
        shape = td.get((GROUP, "observation")).shape[:-1] + (2,)
        return td.set((GROUP, "action"), torch.rand(shape, generator=gen) * 2 - 1)

    return policy


def run_module(*args: str, timeout: float) -> subprocess.CompletedProcess:
    """``python -m ARGS`` in a child process on one torch thread, its output captured."""
    return subprocess.run(
        [sys.executable, "-m", *args], capture_output=True, text=True, timeout=timeout,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )  # fmt: skip


def test_check_env_specs():
    check_env_specs(PESTorchRLEnv(num_envs=4, seed=0), seed=0)


def test_rollout_shapes():
    e, n, steps = 6, 5, 50
    env = PESTorchRLEnv(SHORT, num_envs=e, seed=0)
    td = env.rollout(steps, fixed_policy(), break_when_any_done=False)
    assert td.batch_size == (e, steps)
    nxt = td["next"]
    assert nxt[GROUP, "observation"].shape == (e, steps, n, 9 * n)
    assert nxt[GROUP, "obs_mask"].shape == (e, steps, n, n)
    assert nxt[GROUP, "mask"].shape == (e, steps, n)
    assert nxt[GROUP, "reward"].shape == (e, steps, n, 1)
    assert nxt[GROUP, "info", "distance"].shape == (e, steps, n, 1)
    assert td[GROUP, "action"].shape == (e, steps, n, 2)
    assert nxt["state"].shape == (e, steps, (n + 1) * 8)
    for key in ("done", "terminated", "truncated", "success"):
        assert nxt[key].shape == (e, steps, 1) and nxt[key].dtype == torch.bool
    assert torch.isfinite(nxt[GROUP, "reward"]).all()
    # Episodes of 12 steps: every game finished (by truncation at the latest) and went on.
    assert nxt["done"].any(1).all()
    assert (nxt["done"] == (nxt["terminated"] | nxt["truncated"])).all()


def test_rollout_matches_the_simulator():
    """The episodes seen through TorchRL are the simulator's own, auto-reset included: "next"
    holds the finished episode's last observation, the following root entry the first of the
    next episode, and no episode is skipped or started twice."""
    e, steps = 4, 40
    env = PESTorchRLEnv(SHORT, num_envs=e, seed=3)
    td = env.rollout(steps, fixed_policy(1), break_when_any_done=False)
    sim = pes.make_env(SHORT, num_envs=e, seed=3)
    obs, info = sim.reset()
    assert torch.equal(td[GROUP, "observation"][:, 0], flatten_observation(obs, info["obs_mask"]))
    for t in range(steps):
        obs, reward, terminated, truncated, info = sim.step(td[GROUP, "action"][:, t])
        nxt = td["next"][:, t]
        final = flatten_observation(info["final_obs"], info["final_obs_mask"])
        assert torch.equal(nxt[GROUP, "observation"], final)
        assert torch.equal(nxt[GROUP, "reward"][..., 0], reward)
        assert torch.equal(nxt["terminated"][:, 0], terminated)
        assert torch.equal(nxt["truncated"][:, 0], truncated)
        assert torch.equal(nxt["state"], info["final_state"].flatten(1))
        if t + 1 < steps:
            first = flatten_observation(obs, info["obs_mask"])
            assert torch.equal(td[GROUP, "observation"][:, t + 1], first)


def test_partial_reset_leaves_the_others_untouched():
    e = 5
    env = PESTorchRLEnv(num_envs=e, seed=0)
    td = env.reset()
    policy = fixed_policy(2)
    for _ in range(3):
        td = env.step(policy(td))["next"]
    before_state = env.sim.get_state()
    before_obs = td[GROUP, "observation"].clone()
    reset = torch.tensor([True, False, True, False, False])
    out = env.reset(td.clone().set("_reset", reset.unsqueeze(-1)))
    after = env.sim.get_state()
    keep = ~reset
    for name, tensor in after.items():
        dim = 0 if name == "history" else 1
        old, new = before_state[name], tensor
        assert torch.equal(
            old.index_select(dim, keep.nonzero()[:, 0]), new.index_select(dim, keep.nonzero()[:, 0])
        ), name
    assert torch.equal(out[GROUP, "observation"][keep], before_obs[keep])
    # The reset games start their next episode: step counter 0, a new start.
    counters = scenario.Counters(*after["counters"].unbind(0))
    old_counters = scenario.Counters(*before_state["counters"].unbind(0))
    assert (counters.step[reset] == 0).all() and (counters.step[keep] == 3).all()
    assert torch.equal(counters.episode[reset], old_counters.episode[reset] + 1)
    assert not torch.equal(out[GROUP, "observation"][reset], before_obs[reset])
    assert not out["done"].any()


def test_damaged_pursuers_are_masked():
    n = 5
    env = PESTorchRLEnv({"damaged": 1}, num_envs=3, seed=0)
    td = env.rollout(5, fixed_policy(3), break_when_any_done=False)
    mask = td["next"][GROUP, "mask"]
    assert (mask.sum(-1) == n - 1).all()
    dead = ~mask
    assert (td["next"][GROUP, "observation"][dead] == 0).all()
    assert (td["next"][GROUP, "reward"][dead] == 0).all()
    # Live pursuers' row-mask bits hide the dead one.
    bits = td["next"][GROUP, "observation"][..., 8 * n :]
    assert torch.equal(bits.bool(), td["next"][GROUP, "obs_mask"])
    assert (bits.sum(-1)[mask] == n - 1).all()


def test_seed_and_reset():
    env = PESTorchRLEnv(num_envs=2)
    env.set_seed(7)
    first = env.reset()
    again = PESTorchRLEnv(num_envs=2, seed=7).reset()
    assert torch.equal(first[GROUP, "observation"], again[GROUP, "observation"])
    # A second reset starts new episodes, and what was handed out before stays as it was.
    snapshot = first.clone()
    assert not torch.equal(env.reset()[GROUP, "observation"], first[GROUP, "observation"])
    env.reset(first.clone().set("_reset", torch.tensor([[True], [False]])))
    assert (first == snapshot).all()


def test_options_pass_through():
    env = PESTorchRLEnv(num_envs=2, sim_compile=True, check_actions=False)
    assert env.sim.compiled and not env.sim.check_actions
    with pytest.raises(pes.errors.ConfigError):
        PESTorchRLEnv({"num_pursuer": 3})
    with pytest.raises(pes.errors.ConfigError, match="external"):
        PESTorchRLEnv({"evader_policy": "external"})


@pytest.mark.slow
def test_the_compiled_step_through_torchrl():
    """``sim_compile=True``: TorchRL's rollout steps the fused simulator (no fall-back to eager)
    and sees the eager one's episodes, resets included."""
    fused = PESTorchRLEnv(SHORT, num_envs=4, seed=3, sim_compile=True)
    eager = PESTorchRLEnv(SHORT, num_envs=4, seed=3)
    a = fused.rollout(30, fixed_policy(1), break_when_any_done=False)
    b = eager.rollout(30, fixed_policy(1), break_when_any_done=False)
    assert fused.sim.compiled
    for key in (("next", GROUP, "observation"), ("next", GROUP, "reward"), ("next", "state")):
        torch.testing.assert_close(a[key], b[key], atol=1e-4, rtol=0)
    for key in ("terminated", "truncated", "done"):
        assert torch.equal(a["next", key], b["next", key])
    assert a["next", "done"].any()  # episodes of 12 steps: the reset pass ran too


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA GPU")
def test_cuda():
    env = PESTorchRLEnv(num_envs=8, device="cuda", seed=0)
    check_env_specs(env)
    td = env.rollout(20, break_when_any_done=False)
    assert td.device.type == "cuda" and td["next", GROUP, "reward"].is_cuda


def test_reset_without_td_keys():
    """A plain TensorDict with only "_reset" works as TorchRL's partial reset."""
    env = PESTorchRLEnv(num_envs=3, seed=0)
    env.reset()
    out = env.reset(TensorDict({"_reset": torch.tensor([[True], [False], [False]])}, [3]))
    assert out[GROUP, "observation"].shape == (3, 5, 45)


# --- BenchMARL ----------------------------------------------------------------------------------

BENCHMARL_TASK = {"max_steps": 20, "num_pursuers": 3, "capture_count": 2}


def tiny_experiment(tmp_path, task_name: str, algorithm: str, task_config=None):
    """A BenchMARL experiment shrunk to seconds: two iterations of 60 frames, 2 envs."""
    optional("benchmarl")
    from benchmarl import algorithms
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models import MlpConfig

    from pes.benchmarl import PESTask

    config = ExperimentConfig.get_from_yaml()
    config.save_folder = str(tmp_path)
    config.loggers = []
    config.create_json = False
    config.checkpoint_at_end = False
    config.max_n_iters = 2
    config.max_n_frames = None
    config.on_policy_collected_frames_per_batch = 60
    config.on_policy_n_envs_per_worker = 2
    config.on_policy_n_minibatch_iters = 1
    config.on_policy_minibatch_size = 20
    config.off_policy_collected_frames_per_batch = 60
    config.off_policy_n_envs_per_worker = 2
    config.off_policy_n_optimizer_steps = 2
    config.off_policy_train_batch_size = 16
    config.off_policy_memory_size = 200
    config.off_policy_init_random_frames = 0
    config.evaluation = True
    config.evaluation_interval = 60
    config.evaluation_episodes = 2
    config.render = False
    algo_config = getattr(algorithms, f"{algorithm}Config").get_from_yaml()
    task = getattr(PESTask, task_name.upper()).get_task()
    task.config.update(task_config or BENCHMARL_TASK)
    model = MlpConfig.get_from_yaml()
    model.num_cells = [16]
    return Experiment(
        task=task,
        algorithm_config=algo_config,
        model_config=model,
        critic_model_config=model,
        seed=0,
        config=config,
    )


@pytest.mark.parametrize("algorithm", ["Mappo", "Ippo", "Maddpg", "Masac"])
def test_benchmarl_algorithms_run(tmp_path, algorithm):
    experiment = tiny_experiment(tmp_path, "default", algorithm)
    experiment.run()
    assert experiment.n_iters_performed == 2
    assert experiment.total_frames == 120


@pytest.mark.parametrize("task_name", ["damaged", "point_mass", "easy", "train"])
def test_benchmarl_tasks_run(tmp_path, task_name):
    experiment = tiny_experiment(tmp_path, task_name, "Mappo")
    config = experiment.task.config
    if task_name == "damaged":
        assert config["damaged"] == 1
    if task_name == "point_mass":
        assert config["dynamics"] == "point_mass"
    if task_name == "easy":
        assert config["evader_max_speed"] < config["pursuer_max_speed"]
    if task_name == "train":
        assert config["evader_policy"] == "ddpg" and config["capture_reward"] == 25.0
    experiment.run()
    assert experiment.n_iters_performed == 2


def test_the_benchmarl_command_line_runs_an_experiment_on_pes(tmp_path):
    """``python -m pes.benchmarl``, BenchMARL's own command line, trains on a PES task."""
    optional("benchmarl")
    tiny = [
        "experiment.max_n_iters=1", "experiment.max_n_frames=null",
        "experiment.on_policy_collected_frames_per_batch=60",
        "experiment.on_policy_n_envs_per_worker=2", "experiment.on_policy_n_minibatch_iters=1",
        "experiment.on_policy_minibatch_size=20", "experiment.evaluation=false",
        "experiment.loggers=[csv]", "experiment.checkpoint_at_end=false",
        f"experiment.save_folder={tmp_path}", f"hydra.run.dir={tmp_path / 'hydra'}",
    ]  # fmt: skip
    task = ["task.num_pursuers=3", "task.capture_count=2", "task.max_steps=20"]
    run = run_module(
        "pes.benchmarl", "algorithm=mappo", "task=pes/damaged", *task, *tiny, timeout=300
    )
    assert run.returncode == 0, run.stderr[-2000:]
    assert "Algorithm: mappo, Task: pes/damaged" in run.stdout
    (frames,) = tmp_path.glob("*/*/scalars/counters_total_frames.csv")  # BenchMARL's layout
    assert frames.read_text().strip().splitlines()[-1].endswith(",60.0")


def test_benchmarl_task_specs_and_errors():
    optional("benchmarl")
    from benchmarl.environments import task_config_registry

    from pes.benchmarl import PESTask

    assert task_config_registry["pes/point_mass"] is PESTask.POINT_MASS
    task = PESTask.DEFAULT.get_task({"num_pursuers": 3})
    env = task.get_env_fun(4, True, 0, "cpu")()
    assert task.group_map(env) == {GROUP: ["pursuer_0", "pursuer_1", "pursuer_2"]}
    assert task.observation_spec(env)[GROUP, "observation"].shape == (3, 27)
    assert task.state_spec(env)["state"].shape == (32,)
    assert set(task.info_spec(env)[GROUP, "info"].keys()) == {"crashed", "distance"}
    assert task.action_spec(env)[GROUP, "action"].shape == (3, 2)
    assert task.max_steps(env) == 500
    with pytest.raises(pes.errors.ConfigError):
        PESTask.DEFAULT.get_task({"num_pursuer": 3}).get_env_fun(4, True, 0, "cpu")
    with pytest.raises(ValueError):
        task.get_env_fun(4, False, 0, "cpu")


def test_benchmarl_hydra_config_and_log_info():
    """``task=pes/<task>`` resolves in BenchMARL's own config tree (what ``python -m
    pes.benchmarl`` runs), EnvConfig keys are task overrides, and the success rate is logged."""
    optional("benchmarl")
    from benchmarl.hydra_config import load_task_config_from_hydra
    from hydra import compose, initialize_config_module

    from pes.benchmarl import PESClass, register

    register()
    with initialize_config_module(config_module="benchmarl.conf", version_base=None):
        cfg = compose(
            config_name="config",
            overrides=["algorithm=mappo", "task=pes/easy", "task.num_pursuers=3"],
        )
    task = load_task_config_from_hydra(cfg.task, "pes/easy")
    assert task.config["num_pursuers"] == 3 and task.config["evader_max_speed"] == 8.0
    env = task.get_env_fun(2, True, 0, "cpu")()
    td = env.rollout(30, break_when_any_done=False)  # 500-step episodes: none ends
    assert PESClass.log_info(td) == {}
    td["next", "done"][:, -1] = True
    td["next", "success"][0, -1] = True
    assert PESClass.log_info(td) == {"collection/success_rate": 0.5}


@pytest.mark.parametrize("algorithm", ["Mappo", "Maddpg"])
def test_pes_eval_measures_a_benchmarl_checkpoint(tmp_path, algorithm, capsys):
    """A BenchMARL experiment's checkpoint is a ``pes eval --policy``: its deterministic
    policy, measured with PES's own evaluation."""
    import json

    from pes.cli import main, make_policy

    experiment = tiny_experiment(tmp_path, "default", algorithm)
    experiment.config.checkpoint_at_end = True
    experiment.run()
    (checkpoint,) = tmp_path.glob("*/checkpoints/checkpoint_*.pt")

    def files():
        return {f: f.read_bytes() for f in tmp_path.rglob("*") if f.is_file()}

    run = files()
    scenario = ["--set", "num_pursuers=3", "--set", "capture_count=2", "--set", "max_steps=20"]
    assert main(["eval", "--policy", str(checkpoint), "--episodes", "3", "--json", *scenario]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["episodes"] == 3 and result["policy"] == str(checkpoint)
    assert files() == run  # pes eval leaves the run's folder as it was

    config = pes.EnvConfig(num_pursuers=3, capture_count=2, max_steps=20)
    policy = make_policy(str(checkpoint), config)
    env = pes.make_env(config, num_envs=4, seed=0)
    obs, info = env.reset(seed=0)
    actions = policy(obs, info)
    assert actions.shape == (4, 3, 2) and actions.abs().max() <= 1.0
    assert torch.equal(actions, policy(obs, info))  # no exploration noise
    if torch.cuda.is_available():  # pes eval --device cuda: the networks and the env on the GPU
        on_gpu = make_policy(str(checkpoint), config, device="cuda")
        gpu_env = pes.make_env(config, num_envs=4, seed=0, device="cuda")
        gpu_obs, gpu_info = gpu_env.reset(seed=0)
        gpu_actions = on_gpu(gpu_obs, gpu_info)
        assert gpu_actions.is_cuda
        torch.testing.assert_close(gpu_actions.cpu(), actions, atol=1e-4, rtol=0)
    with pytest.raises(pes.errors.ConfigError, match="trained with 3 pursuers"):
        make_policy(str(checkpoint), pes.EnvConfig())


def test_torchrl_policy_refuses_a_recurrent_module():
    from tensordict.nn import TensorDictModule

    from pes.torchrl import TorchRLPolicy

    module = TensorDictModule(
        lambda obs, h: obs[..., :2], [(GROUP, "observation"), (GROUP, "_hidden")],
        [(GROUP, "action")],
    )  # fmt: skip
    with pytest.raises(pes.errors.ConfigError, match="stateless"):
        TorchRLPolicy(module)


def test_benchmarl_reference_run_stops_at_its_frame_budget_and_is_evaluated(tmp_path):
    """A reference run on pes/train: BenchMARL's configs, stopped by its budget of frames (env
    steps) with a checkpoint, that checkpoint evaluated with PES's protocol; a second call
    reads the result; a larger budget resumes from the checkpoint."""
    optional("benchmarl")
    from pes.algos import build_train_config
    from pes.benchmarl.reference import quick_frames, run_reference

    # by default the budget of PES's learners in the quick presets
    assert quick_frames() == build_train_config("maddpg", "quick").env_steps == 2_000_000
    small = {
        "on_policy_collected_frames_per_batch": 60,
        "on_policy_n_envs_per_worker": 2,
        "on_policy_n_minibatch_iters": 1,
        "on_policy_minibatch_size": 20,
    }
    kwargs = dict(frames=120, eval_episodes=2, checkpoint_every=1)
    result = run_reference("mappo", 0, tmp_path, experiment_overrides=small, **kwargs)
    assert result["frames"] == result["frame_budget"] == 120 and result["cpu_s"] > 0
    assert result["eval"]["episodes"] == 2 and result["task"] == "pes/train"
    assert (tmp_path / result["checkpoint"]).is_file()
    assert run_reference("mappo", 0, tmp_path, **kwargs) == result
    (tmp_path / "result.json").unlink()
    longer = dict(kwargs, frames=240)
    resumed = run_reference("mappo", 0, tmp_path, experiment_overrides=small, **longer)
    assert resumed["frames"] == 240 and resumed["cpu_s"] > result["cpu_s"]


def test_a_diverged_reference_run_is_evaluated_at_its_last_checkpoint(tmp_path, monkeypatch):
    """When the policy's actions go NaN (the simulator raises ActionError) the run stops, its
    last checkpoint is evaluated and result.json records the divergence."""
    optional("benchmarl")
    from pes.benchmarl import reference

    trains = reference.Experiment.run

    def run(self):  # trains as asked, then the next batch's actions are NaN
        trains(self)
        raise pes.errors.ActionError("actions hold NaN or infinite values")

    monkeypatch.setattr(reference.Experiment, "run", run)
    small = {
        "on_policy_collected_frames_per_batch": 60,
        "on_policy_n_envs_per_worker": 2,
        "on_policy_n_minibatch_iters": 1,
        "on_policy_minibatch_size": 20,
    }
    result = reference.run_reference(
        "ippo", 0, tmp_path, frames=120, eval_episodes=2, checkpoint_every=1,
        experiment_overrides=small,
    )  # fmt: skip
    assert result["diverged"] == "actions hold NaN or infinite values after 120 frames"
    assert result["frames"] == 120 and result["eval"]["episodes"] == 2


def test_a_reference_run_diverging_before_its_first_checkpoint_fails_in_one_line(
    tmp_path, monkeypatch, capsys
):
    """Nothing to evaluate: the command says so in one line, exits non-zero and writes no
    result.json (which would otherwise stand in Table IV's report)."""
    optional("benchmarl")
    from pes.benchmarl import reference

    def run(self):  # the first batch's actions are already NaN
        raise pes.errors.ActionError("actions hold NaN or infinite values")

    monkeypatch.setattr(reference.Experiment, "run", run)
    out = tmp_path / "run"
    assert reference.main(["--algorithm", "ippo", "--seed", "0", "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ippo seed 0: training diverged (actions hold NaN")
    assert "before its first checkpoint" in err and "\n" not in err
    assert not (out / "result.json").exists()


@pytest.mark.slow
def test_pes_eval_loads_a_checkpoint_of_the_reference_command(tmp_path, capsys):
    """``python -m pes.benchmarl.reference`` pickles its callback into the run's config.pkl;
    another process (``pes eval``) must be able to load the run's checkpoint from it."""
    optional("benchmarl")
    import json

    from pes.cli import main

    budget = ["--frames", "6000", "--eval-episodes", "2", "--out", str(tmp_path)]
    run = run_module("pes.benchmarl.reference", "--algorithm", "mappo", *budget, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    (checkpoint,) = tmp_path.glob("*/checkpoints/checkpoint_6000.pt")
    assert main(["eval", "--policy", str(checkpoint), "--episodes", "2", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["episodes"] == 2
