"""Bad input of every kind gets a one-line PESError (a one-line ``error:`` and exit 2 on the
command line), never a traceback and never a silent fix (docs/interfaces.md, docs/cli.md)."""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import re
import typing
from pathlib import Path

import numpy as np
import pytest
import torch

import pes
from pes.cli import main
from pes.errors import ActionError, CheckpointError, ConfigError
from pes.paths import prepare_output, prepare_output_dir
from pes.record import check_record, load_record
from pes.sim.layout import Layout
from pes.strict import load_yaml, read_text_file
from tests.conftest import optional


def one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


# --- 7. argparse mistakes: one line, exit 2 ------------------------------------------------


@pytest.mark.parametrize(
    "argv, message",
    [
        (["eval", "--episodes", "x"], "argument --episodes"),
        (["eval", "--policy", "pid-pf", "--bogus"], "unrecognized arguments: --bogus"),
        (["frobnicate"], "invalid choice: 'frobnicate'"),
        ([], "required: COMMAND"),
        (["view"], "required: EPISODE.json"),
        (["bench", "--num-envs", "x"], "argument --num-envs"),
    ],
)
def test_argparse_mistakes_are_one_line(argv, message, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    err = one_line_error(capsys)
    assert err.startswith("pes") and "error: " in err and message in err
    assert "usage:" not in err


def test_help_still_prints_usage(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["eval", "--help"])
    assert exit_.value.code == 0 and "usage: pes eval" in capsys.readouterr().out


# --- 1. layout and config files ---------------------------------------------------------------

BINARY = bytes(range(256)) * 4


def layout_error(tmp_path, text: str | bytes, name: str = "city.yaml") -> str:
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    with pytest.raises(ConfigError) as error:
        pes.make_env({"layout": str(path)})
    message = str(error.value)
    assert "\n" not in message
    return message


@pytest.mark.parametrize("name", ["city.yaml", "city.txt"])
def test_binary_layout_file(tmp_path, name):
    assert "not a text file" in layout_error(tmp_path, BINARY, name)


@pytest.mark.parametrize(
    "text, field",
    [
        ("arena: foo\nbuildings: []\n", "arena"),
        ("arena: [100]\nbuildings: []\n", "arena"),
        ("buildings: [[1, 1, 5, 5]]\nheights: [abc]\n", "heights"),
        ("buildings: [[1, 1, 5, 5]]\nheights: 5\n", "heights"),
        ("buildings: [[1, 1, 5, 5]]\nheights: [-3]\n", "heights"),
        ("buildings: [[1, 1, .nan, 5]]\n", "buildings[0]"),
        ("buildings: [[1, 1, .inf, 5]]\n", "buildings[0]"),
        ("buildings: [[1, 1, 5, 5, 10, 10, 20, 20]]\n", "buildings[0]"),
        ("buildings: [[1, 1], [5, 5]]\n", "buildings[0]"),
        ("buildings: [[1, 1, 5, 5], [2, 2, 3]]\n", "buildings[1]"),
        ("buildings: [[1, 1, x, 5]]\n", "buildings[0]"),
        ("buildings: 7\n", "buildings"),
        ("{1: 2, buildings: []}\n", "unknown layout keys"),
    ],
)
def test_bad_layout_fields_are_named(tmp_path, text, field):
    assert field in layout_error(tmp_path, text)


def test_layout_class_rejects_non_finite_and_wrong_rows():
    with pytest.raises(ConfigError, match="finite"):
        Layout(100.0, 100.0, np.array([[1.0, 1.0, np.nan, 5.0]]), np.array([30.0]))
    with pytest.raises(ConfigError, match="xmin, ymin, xmax, ymax"):
        Layout(100.0, 100.0, np.arange(8.0).reshape(1, 8), np.array([30.0]))


def test_binary_config_file_through_the_cli(tmp_path, capsys):
    path = tmp_path / "config.yaml"
    path.write_bytes(BINARY)
    assert main(["eval", "--policy", "pid-pf", "--config", str(path)]) == 2
    assert "not a text file" in one_line_error(capsys)
    with pytest.raises(ConfigError, match="not a text file"):
        load_yaml(path)
    with pytest.raises(ConfigError, match="is a folder"):
        read_text_file(tmp_path, "config file")


@pytest.mark.parametrize("pair", [[3, 0], [0, 3], [-1, 1], [1, -1]])
def test_removed_blocks_outside_the_grid(pair):
    with pytest.raises(ConfigError, match="removed_blocks entry .* outside the 3 x 3 grid"):
        pes.EnvConfig(removed_blocks=[pair]).validate()
    # on a layout that is not the grid the key plays no part
    pes.EnvConfig(removed_blocks=[pair], layout="empty").validate()


# --- 2. NaN/inf and typos in EnvConfig ------------------------------------------------------------


def float_fields() -> list[str]:
    hints = typing.get_type_hints(pes.EnvConfig)
    return [f.name for f in dataclasses.fields(pes.EnvConfig) if hints[f.name] is float]


@pytest.mark.parametrize("name", float_fields())
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_every_float_field_rejects_nan_and_inf(name, bad):
    with pytest.raises(ConfigError, match=name) as error:
        pes.EnvConfig.from_dict({name: bad})
    assert "\n" not in str(error.value)
    with pytest.raises(ConfigError, match=name):
        pes.EnvConfig(**{name: bad}).validate()


@pytest.mark.parametrize("name", ["pursuer_inertia", "evader_inertia", "building_height_range"])
@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_tuple_fields_reject_nan_and_inf(name, bad):
    value = list(getattr(pes.EnvConfig(), name))
    value[-1] = bad
    with pytest.raises(ConfigError, match=name):
        pes.EnvConfig.from_dict({name: value})


def test_typo_keyword_is_a_config_error():
    with pytest.raises(ConfigError, match="did you mean 'num_pursuers'"):
        pes.EnvConfig(num_pursers=5)
    with pytest.raises(ConfigError, match="positional"):
        pes.EnvConfig(*range(100))
    with pytest.raises(ConfigError, match="two values for 'num_pursuers'"):
        pes.EnvConfig(5, num_pursuers=4)
    # valid keywords and positional values still build the same dataclass
    assert pes.EnvConfig(4) == pes.EnvConfig(num_pursuers=4)
    assert pes.EnvConfig(num_pursuers=4, capture_count=2).replace(max_steps=9).max_steps == 9
    assert "num_pursuers" in inspect.signature(pes.EnvConfig).parameters


def test_validate_checks_types_of_a_constructed_config():
    with pytest.raises(ConfigError, match="grid_rows: expected an integer"):
        pes.EnvConfig(grid_rows="3").validate()


# --- 6. PettingZoo actions ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def zoo():
    from pes.pettingzoo import parallel_env

    env = parallel_env(num_pursuers=3, capture_count=2, max_steps=50)
    env.reset(seed=0)
    return env


@pytest.mark.parametrize(
    "bad, message",
    [
        (np.zeros(3), "shape (2,), got (3,)"),
        (np.zeros((1, 2)), "shape (2,), got (1, 2)"),
        (0.5, "shape (2,), got ()"),
        (np.float32(0.5), "shape (2,), got ()"),
        ("ab", "got str"),
        ("0.5", "got str"),
        ([0.1, "x"], "must be numbers"),
        ([True, False], "must be numbers"),
        ([0.1, math.nan], "NaN or infinite"),
        ([0.1, math.inf], "NaN or infinite"),
        ([1e39, 0.0], "may not exceed"),
        ({"x": 1}, "got dict"),
        (None, "must be numbers"),
        (torch.tensor([True, False]), "real numbers"),
        (torch.zeros(2, dtype=torch.complex64), "real numbers"),
        (torch.full((2,), math.nan, dtype=torch.bfloat16), "NaN or infinite"),
    ],
)
def test_pettingzoo_bad_action_names_the_agent(zoo, bad, message):
    actions = {agent: np.zeros(2, dtype=np.float32) for agent in zoo.agents}
    actions["pursuer_1"] = bad
    with pytest.raises(ActionError) as error:
        zoo.step(actions)
    text = str(error.value)
    assert "pursuer_1" in text and message in text and "\n" not in text


def test_pettingzoo_actions_must_be_a_dict(zoo):
    with pytest.raises(ActionError, match="must be a dict of agent name to action, got list"):
        zoo.step([np.zeros(2)] * 3)
    with pytest.raises(ActionError, match="unknown agent 7"):
        zoo.step({7: np.zeros(2), **{a: np.zeros(2) for a in zoo.agents}})
    # a good step still runs, also with a list or a tensor per agent
    _, rewards, *_ = zoo.step({a: [0.1, -0.2] for a in zoo.agents})
    assert set(rewards) <= set(zoo.possible_agents)
    zoo.step({a: torch.tensor([0.1, 0.2], dtype=torch.bfloat16) for a in zoo.agents})


def test_step_rejects_huge_actions():
    env = pes.make_env(num_envs=2, seed=0)
    env.reset()
    with pytest.raises(ActionError, match="beyond 1e"):
        env.step(torch.full((2, 5, 2), 1e30))
    with pytest.raises(ActionError, match="NaN or infinite"):
        env.step(torch.full((2, 5, 2), math.nan))
    env.step(torch.full((2, 5, 2), 3.0))  # beyond norm 1 is clipped, as documented


# --- 3. episode records: one validator for `pes view` and `pes render --record` ---------------


def minimal_record() -> dict:
    """A hand-made record of two pursuers and an evader."""
    frame = {
        "t": 0.0,
        "pos": [[10.0, 10.0], [20.0, 10.0], [15.0, 15.0]],
        "vel": [[0.0, 0.0]] * 3,
        "alive": [True, True],
        "crashed": [False, False],
    }
    return {
        "version": 1,
        "config": {"capture_count": 2},
        "arena": [50.0, 40.0],
        "buildings": [[30.0, 20.0, 40.0, 30.0]],
        "dt": 0.1,
        "agents": [
            {"id": "pursuer_0", "role": "pursuer"},
            {"id": "pursuer_1", "role": "pursuer"},
            {"id": "evader", "role": "evader"},
        ],
        "frames": [frame, dict(frame, t=0.1)],
        "outcome": {"success": False, "steps": 1, "crashes": 0},
    }


def spoil(path: str, value):
    """A copy of the minimal record with the part at ``path`` (keys and indices split by
    '/') set to ``value``, or cut to its first element when ``value`` is ``CUT``."""
    record = json.loads(json.dumps(minimal_record()))
    *parents, last = [int(p) if p.isdigit() else p for p in path.split("/")]
    target = record
    for key in parents:
        target = target[key]
    target[last] = target[last][:1] if value is CUT else value
    return record


CUT = object()
BAD_RECORDS = [
    ("frames/1/pos/2/0", math.nan, "frame 1: pos[2]"),
    ("frames/1/pos/0/1", math.inf, "frame 1: pos[0]"),
    ("frames/0/pos", CUT, "frame 0: pos must be a list of 3"),
    ("frames/0/pos", "here", "frame 0: pos"),
    ("frames/0/pos/1", [1.0, 2.0, 3.0], "frame 0: pos[1] must be [x, y]"),
    ("frames/0/pos/1/0", "1.0", "frame 0: pos[1]"),
    ("frames/0/vel", CUT, "frame 0: vel"),
    ("frames/1/alive", [True], "frame 1: alive"),
    ("frames/1/alive", ["yes", "no"], "frame 1: alive"),
    ("frames/1/t", "soon", "frame 1: t"),
    ("frames/1/pred", [[1.0]], "frame 1: pred[0]"),
    ("frames/1", [1, 2], "frame 1"),
    ("frames", [], "no frames"),
    ("frames", {"0": 1}, "frames"),
    ("arena", [50.0, math.nan], "arena"),
    ("arena", "big", "arena"),
    ("buildings/0", [1.0, 2.0, 3.0], "buildings[0]"),
    ("buildings/0/2", math.nan, "buildings[0]"),
    ("buildings", 5, "buildings"),
    ("dt", -0.1, "dt"),
    ("dt", "0.1", "dt"),
    ("agents", 5, "agents"),
    ("agents/2/role", "pursuer", "agents"),
    ("config", [1], "config"),
    ("outcome", {"success": True}, "outcome"),
    ("outcome/steps", 1.5, "outcome.steps"),
    ("outcome/success", "no", "outcome.success"),
    ("version", [1], "version"),
]


@pytest.mark.parametrize("path, value, message", BAD_RECORDS)
def test_bad_record_is_one_line_in_view_and_render(tmp_path, capsys, path, value, message):
    record_path = tmp_path / "ep.json"
    record_path.write_text(json.dumps(spoil(path, value)))  # NaN is written as NaN, as Python does
    with pytest.raises(CheckpointError, match=re.escape(message)):
        check_record(spoil(path, value))
    for argv in (
        ["view", str(record_path), "--out", str(tmp_path / "ep.html")],
        ["render", "--record", str(record_path), "--out", str(tmp_path / "ep.png")],
    ):
        assert main(argv) == 2, argv
        err = one_line_error(capsys)
        assert err.startswith(f"error: {record_path}: ") and message in err


def test_good_minimal_record_renders(tmp_path, capsys):
    record_path = tmp_path / "ep.json"
    record_path.write_text(json.dumps(minimal_record()))
    assert check_record(load_record(record_path))["dt"] == 0.1
    assert main(["render", "--record", str(record_path), "--out", str(tmp_path / "a.gif")]) == 0
    assert main(["view", str(record_path)]) == 0


def test_binary_record_file(tmp_path, capsys):
    record_path = tmp_path / "ep.json"
    record_path.write_bytes(BINARY)
    assert main(["view", str(record_path)]) == 2
    assert "not a JSON episode record" in one_line_error(capsys)


# --- 4. output paths ---------------------------------------------------------------------------


@pytest.fixture()
def a_file(tmp_path) -> Path:
    path = tmp_path / "ep.json"
    path.write_text(json.dumps(minimal_record()))
    return path


@pytest.mark.parametrize(
    "argv, message",
    [
        (["render", "--policy", "pid-pf", "--out", "{file}/sub.json"], "is a file, not a folder"),
        (["render", "--policy", "pid-pf", "--out", "/proc/x/y.gif"], "cannot write /proc/x/y.gif"),
        (["render", "--policy", "pid-pf", "--out", "/proc/y.png"], "cannot write /proc/y.png"),
        (["render", "--record", "{file}", "--out", "{file}/a/b.gif"], "is a file, not a folder"),
        (["render", "--record", "{file}", "--out", "{tmp}/dir.png"], "it is a folder"),
        (["view", "{file}", "--out", "{file}/page.html"], "is a file, not a folder"),
        (["view", "{file}", "--out", "/proc/x/page.html"], "cannot write /proc/x/page.html"),
        (["demo", "--out", "{file}"], "it is a file, not a folder"),
        (["demo", "--out", "{file}/run"], "is a file, not a folder"),
        (["demo", "--out", "/proc/x"], "cannot write"),
        (["export-onnx", "cbc-tp", "{file}/policy.onnx"], "is a file, not a folder"),
        (["export-onnx", "cbc-tp", "/proc/x/policy.onnx"], "cannot write /proc/x/policy.onnx"),
    ],
)
def test_unwritable_output_is_one_line(argv, message, a_file, tmp_path, capsys):
    (tmp_path / "dir.png").mkdir()  # a folder where a file is asked for
    argv = [a.format(file=a_file, tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    err = one_line_error(capsys)
    assert err.startswith("error: ") and message in err


def test_prepare_output_creates_the_folder(tmp_path):
    path = prepare_output(tmp_path / "a" / "b" / "c.json")
    assert path.parent.is_dir() and not path.exists()
    assert prepare_output_dir(tmp_path / "d" / "e").is_dir()
    with pytest.raises(ConfigError, match="is a folder"):
        prepare_output(tmp_path / "a")


# --- 5. ONNX export of a policy with NaN weights -----------------------------------------------


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_export_onnx_rejects_non_finite_weights(tmp_path, capsys, bad):
    optional("onnx")
    optional("onnxscript")
    from pes.models import is_shipped

    if not is_shipped("cbc-tp"):
        pytest.skip("no shipped cbc-tp policy")
    shipped = Path(pes.__file__).parent / "models" / "cbc_tp.pt"
    blob = torch.load(shipped, map_location="cpu", weights_only=False)
    actor = blob["policy"]["actor"]
    name = next(k for k, v in actor.items() if torch.is_tensor(v) and v.is_floating_point())
    actor[name] = torch.full_like(actor[name], bad)
    path = tmp_path / "broken.pt"
    torch.save(blob, path)
    out = tmp_path / "broken.onnx"
    assert main(["export-onnx", str(path), str(out), "--json"]) == 2
    err = one_line_error(capsys)
    assert "NaN or infinite weights" in err and not out.exists()
    assert capsys.readouterr().out == ""  # no JSON with NaN in it


@pytest.mark.parametrize(
    "name, value",
    [
        ("arena_width", 1e9),
        ("arena_height", 1e5),
        ("grid_rows", 10**6),
        ("physics_substeps", 10**9),
        ("history_length", 10**9),
        ("num_pursuers", 1000),
    ],
)
def test_sizes_that_would_exhaust_memory_or_hang(name, value):
    with pytest.raises(ConfigError, match=f"{name} must be at most"):
        pes.EnvConfig.from_dict({name: value})
