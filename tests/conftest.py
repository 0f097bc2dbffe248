"""Shared fixtures: small scenarios that run in seconds."""

from __future__ import annotations

import importlib
import os
from types import ModuleType
from typing import NoReturn

import pytest
import torch

import pes
from pes.sim import kernels


@pytest.fixture(autouse=True, scope="session")
def _kernels_loaded():
    """The compiled step from the first test on (compiled here if none is cached): a background
    compilation finishing mid-session would switch later steps from the torch code to the
    kernels, and tests that compare two runs would compare two paths."""
    kernels.wait()
    yield


@pytest.fixture(autouse=True)
def _one_thread():
    """One torch thread, as training runs use: the test networks and batches are small, and on a
    busy 2-core machine a two-thread matrix product of them waits ~8 ms on the other core
    (hundreds of times a one-thread one)."""
    torch.set_num_threads(1)
    yield


def unavailable(reason: str) -> NoReturn:
    """Skip the test for something it needs that is not installed, except under
    ``PES_REQUIRE_EXTRAS=1`` (as in CI, which installs every optional package and the Chromium
    the tests use), where that is a failure."""
    if os.environ.get("PES_REQUIRE_EXTRAS") == "1":
        pytest.fail(f"{reason}; PES_REQUIRE_EXTRAS=1 requires it")
    pytest.skip(reason, allow_module_level=True)


def optional(module: str) -> ModuleType:
    """``module`` imported, for a package of an optional extra; else :func:`unavailable`."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        unavailable(f"needs {module} ({exc})")


@pytest.fixture
def small_config() -> pes.EnvConfig:
    """A short-episode scenario for fast tests."""
    return pes.EnvConfig(max_steps=60).validate()


def set_vehicles(env: pes.PursuitEvasionEnv, **fields: torch.Tensor) -> None:
    """Overwrite vehicle fields (each (E, A)) of ``env``'s state, then refresh obstacle data."""
    from pes.sim import scenario
    from pes.sim.geometry import nearest_obstacle_xy

    v, c, f = scenario.unpack(env.state)
    v = v._replace(**{k: t.to(env.device).float() for k, t in fields.items()})
    dist, nx, ny = nearest_obstacle_xy(v.x, v.y, env.scenario.boxes, env.scenario.arena)
    v = v._replace(obstacle_dist=dist, obstacle_dx=-nx * dist, obstacle_dy=-ny * dist)
    env.state = scenario.pack(v, c, f, env.state["history"])
