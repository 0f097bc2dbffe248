"""Property-based checks of the input contract (docs/interfaces.md), with Hypothesis.

For generated scenario configs, layout files, episode records and actions, the library either
runs correctly or raises a :class:`pes.errors.PESError` whose message is one line and names the
bad part -- never another exception type. The default tier runs about 200 generated inputs;
the ``slow`` tier runs over 1000. Both are derandomized, so CI sees the same inputs every run.
"""

from __future__ import annotations

import dataclasses
import json
import math
import tempfile
import typing
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import pes
from pes.errors import PESError
from pes.record import check_record
from pes.record.render import render_frames
from pes.record.viewer import scene_data

FIELDS = [f.name for f in dataclasses.fields(pes.EnvConfig)]
HINTS = typing.get_type_hints(pes.EnvConfig)


def fails_cleanly(call, *names: str) -> PESError | None:
    """Run ``call``; a PESError must be one non-empty line (naming one of ``names`` when
    given); any other exception fails the test. Returns the error, or None if it ran."""
    try:
        call()
    except PESError as error:
        message = str(error)
        assert message and "\n" not in message, repr(message)
        if names:
            assert any(name in message for name in names), (names, message)
        return error
    return None


def variants(strategy, fast: int, slow: int):
    """Two copies of a property: ``fast`` examples by default, ``slow`` under
    ``@pytest.mark.slow``; deterministic, no example database, no deadline."""

    def wrap(body):
        common = dict(
            deadline=None,
            derandomize=True,
            database=None,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
        )
        quick = settings(max_examples=fast, **common)(given(strategy)(body))
        long = pytest.mark.slow(settings(max_examples=slow, **common)(given(strategy)(body)))
        return quick, long

    return wrap


# --- values -----------------------------------------------------------------------------------

odd_floats = st.sampled_from([math.nan, math.inf, -math.inf, -1.0, 0.0, 1e308, -1e-300])
any_value = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    odd_floats,
    st.integers(min_value=-(10**12), max_value=10**12),
    st.booleans(),
    st.none(),
    st.text(max_size=8),
    st.lists(st.floats(allow_nan=True), max_size=4),
    st.lists(st.integers(-3, 5), max_size=3).map(lambda v: [v]),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)


def typo(name: str) -> st.SearchStrategy[str]:
    """The key with a letter dropped, doubled or swapped for another."""
    return st.integers(0, len(name) - 1).flatmap(
        lambda i: st.sampled_from(
            [
                name[:i] + name[i + 1 :],
                name[:i] + name[i] + name[i:],
                name[:i] + "x" + name[i + 1 :],
            ]
        )
    )


keys = st.one_of(st.sampled_from(FIELDS), st.sampled_from(FIELDS).flatmap(typo))


def plausible(name: str) -> st.SearchStrategy[typing.Any]:
    """Mostly valid values of the field ``name``, with invalid ones mixed in."""
    default = getattr(pes.EnvConfig(), name)
    if isinstance(default, bool):
        return st.one_of(st.booleans(), any_value)
    if isinstance(default, int):
        return st.one_of(st.integers(-2, 12), any_value)
    if isinstance(default, float):
        return st.one_of(
            st.floats(min_value=-5.0, max_value=3 * max(default, 1.0)), odd_floats, any_value
        )
    return any_value


config_dicts = st.lists(
    keys.flatmap(lambda k: st.tuples(st.just(k), plausible(k) if k in FIELDS else any_value)),
    max_size=4,
).map(dict)


# --- 1. scenario configs ----------------------------------------------------------------------


@variants(config_dicts, fast=60, slow=400)
def _config_dicts(values):
    """from_dict and the constructor agree: a valid config, or one ConfigError naming a key."""
    error = fails_cleanly(lambda: pes.EnvConfig.from_dict(values), *FIELDS)
    if error is None:
        assert pes.EnvConfig.from_dict(values).validate() is not None
    else:
        fails_cleanly(lambda: pes.EnvConfig(**values).validate(), *FIELDS)


test_config_dicts, test_config_dicts_slow = _config_dicts

single_field = st.sampled_from(FIELDS).flatmap(lambda k: st.tuples(st.just(k), any_value))


@variants(single_field, fast=40, slow=200)
def _one_bad_field(item):
    """A single field set to anything: valid, or an error that names that field (or, for a
    value that is valid alone but contradicts another, the key it contradicts)."""
    name, value = item
    fails_cleanly(lambda: pes.EnvConfig.from_dict({name: value}), *FIELDS)
    error = fails_cleanly(lambda: pes.EnvConfig.from_dict({name: value}))
    if error is not None and (
        isinstance(value, float) and not math.isfinite(value) or type(value) not in (int, float)
    ):
        assert name in str(error) or "grid" in str(error), (name, value, str(error))


test_one_bad_field, test_one_bad_field_slow = _one_bad_field


@variants(st.sampled_from(FIELDS).flatmap(typo), fast=10, slow=60)
def _typo_keyword(key):
    if key in FIELDS:
        return
    error = fails_cleanly(lambda: pes.EnvConfig(**{key: 1}), key)
    assert error is not None and "unknown EnvConfig key" in str(error)


test_typo_keyword, test_typo_keyword_slow = _typo_keyword


# --- 2. layout files --------------------------------------------------------------------------

coordinate = st.one_of(
    st.floats(min_value=-10.0, max_value=110.0), odd_floats, st.text(max_size=3), st.none()
)
layout_dicts = st.fixed_dictionaries(
    {"buildings": st.one_of(st.lists(st.lists(coordinate, max_size=6), max_size=4), any_value)},
    optional={
        "arena": st.one_of(st.just([100, 100]), st.lists(coordinate, max_size=3), any_value),
        "heights": st.one_of(st.lists(coordinate, max_size=4), any_value),
        "extra": any_value,
    },
)
layout_texts = st.one_of(
    layout_dicts.map(lambda d: ("city.yaml", yaml.safe_dump(d).encode())),
    st.binary(max_size=64).map(lambda b: ("city.yaml", b)),
    st.text(alphabet="#. x\n", max_size=40).map(lambda t: ("city.txt", t.encode())),
    st.binary(max_size=64).map(lambda b: ("city.txt", b)),
)


@variants(layout_texts, fast=30, slow=200)
def _layout_files(item):
    name, data = item
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / name
        path.write_bytes(data)

        def build():
            env = pes.make_env({"layout": str(path), "max_steps": 3}, num_envs=1, seed=0)
            env.reset(seed=0)
            env.step(torch.zeros(1, 5, 2))

        fails_cleanly(build)


test_layout_files, test_layout_files_slow = _layout_files


# --- 3. episode records -----------------------------------------------------------------------


def minimal_record() -> dict:
    frame = {
        "t": 0.0,
        "pos": [[10.0, 10.0], [20.0, 10.0], [15.0, 15.0]],
        "vel": [[0.0, 0.0]] * 3,
        "alive": [True, True],
        "crashed": [False, False],
        "pred": [[16.0, 16.0]],
    }
    return {
        "version": 1,
        "config": {"capture_count": 2},
        "arena": [50.0, 40.0],
        "buildings": [[30.0, 20.0, 40.0, 30.0]],
        "building_heights": [30.0],
        "altitudes": [10.0, 11.0, 12.0],
        "dt": 0.1,
        "body_radius": 0.3,
        "agents": [
            {"id": "pursuer_0", "role": "pursuer"},
            {"id": "pursuer_1", "role": "pursuer"},
            {"id": "evader", "role": "evader"},
        ],
        "frames": [frame, dict(frame, t=0.1)],
        "outcome": {"success": False, "steps": 1, "crashes": 0},
    }


def _paths(value, prefix=()):
    """Every (path, value) inside a JSON value."""
    yield prefix, value
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _paths(item, (*prefix, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield from _paths(item, (*prefix, index))


RECORD_PATHS = [path for path, _ in _paths(minimal_record()) if path]
record_edits = st.lists(
    st.tuples(st.sampled_from(RECORD_PATHS), st.one_of(any_value, st.just("DELETE"))),
    min_size=1,
    max_size=3,
)


def edited(edits) -> dict:
    record = minimal_record()
    for path, value in edits:
        target = record
        try:
            for key in path[:-1]:
                target = target[key]
            if value == "DELETE":
                del target[path[-1]]
            else:
                target[path[-1]] = value
        except (KeyError, IndexError, TypeError):
            pass  # an earlier edit removed or replaced the parent
    return record


@variants(record_edits, fast=40, slow=300)
def _records(edits):
    record = edited(edits)
    error = fails_cleanly(lambda: check_record(record))
    if error is None:  # a record that passes the check must render and view
        scene = scene_data(record)
        json.dumps(scene, allow_nan=False)
        next(render_frames(record, size=64))
    else:
        assert str(error).startswith(("episode record", "not an episode", "the episode", "not a"))


test_records, test_records_slow = _records


# --- 4. actions -------------------------------------------------------------------------------

action_values = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=32),
    st.floats(min_value=-1.0, max_value=1.0, width=32),
)
shapes = st.one_of(
    st.just((2, 5, 2)),
    st.lists(st.integers(0, 5), max_size=4).map(tuple),
)


@st.composite
def actions(draw):
    kind = draw(st.sampled_from(["array", "tensor", "list", "other"]))
    if kind == "other":
        return draw(any_value)
    shape = draw(shapes)
    size = int(np.prod(shape)) if shape else 1
    values = draw(st.lists(action_values, min_size=size, max_size=size))
    dtype = draw(st.sampled_from([np.float32, np.float64, np.int64, np.bool_, np.float16]))
    with np.errstate(all="ignore"):
        array = np.asarray(values, dtype=np.float64).reshape(shape).astype(dtype)
    if kind == "tensor":
        return torch.from_numpy(np.ascontiguousarray(array))
    return array.tolist() if kind == "list" else array


ENV = pes.make_env({"max_steps": 20}, num_envs=2, seed=0)


@variants(actions(), fast=20, slow=150)
def _step_actions(action):
    ENV.reset(seed=0)
    error = fails_cleanly(lambda: ENV.step(action), "actions")
    if error is None:
        positions = ENV.positions
        assert bool(torch.isfinite(positions).all())


test_step_actions, test_step_actions_slow = _step_actions

ZOO = None


def zoo():
    global ZOO
    if ZOO is None:
        from pes.pettingzoo import parallel_env

        ZOO = parallel_env(num_pursuers=3, capture_count=2, max_steps=20)
    return ZOO


agent_actions = st.one_of(
    st.lists(action_values, min_size=2, max_size=2).map(np.array),
    st.lists(action_values, max_size=4).map(np.array),
    action_values,
    any_value,
)
zoo_actions = st.one_of(
    st.dictionaries(
        st.sampled_from(["pursuer_0", "pursuer_1", "pursuer_2", "pursuer_9", "evader"]),
        agent_actions,
        max_size=4,
    ),
    any_value,
)


@variants(zoo_actions, fast=20, slow=150)
def _pettingzoo_actions(actions):
    env = zoo()
    env.reset(seed=0)
    agents = list(env.agents)
    error = fails_cleanly(lambda: env.step(actions), "agent", "actions", "action")
    if error is None:  # it ran: then every action was two finite numbers
        assert isinstance(actions, dict) and set(actions) == set(agents)
        for value in actions.values():
            array = np.asarray(value, dtype=np.float64)
            assert array.shape == (2,) and np.isfinite(array).all()


test_pettingzoo_actions, test_pettingzoo_actions_slow = _pettingzoo_actions
