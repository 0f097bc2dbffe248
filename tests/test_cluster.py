"""A real two-node Ray cluster on this machine, started as a user starts one (``ray start
--head``, then ``ray start --address`` for a second node) with Ray's token authentication:
``pes tune`` and ``pes reproduce`` run their trials on both nodes, a trial whose node is killed
is retried on the other and finishes, a driver without the token gets one line naming the fix,
and the cluster is stopped by killing the processes it started (never by name)."""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from tests.conftest import optional

optional("ray")

pytestmark = pytest.mark.slow


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Node:
    """One ``ray start --block`` in a session of its own: stopping it kills its whole process
    group (the GCS, the raylet, the workers it started)."""

    def __init__(self, args: list[str], env: dict[str, str], log: Path) -> None:
        self.log = open(log, "w")  # noqa: SIM115 - closed in stop()
        ray = [str(Path(sys.executable).parent / "ray"), "start", "--block"]
        self.proc = subprocess.Popen(
            ray + args, env=env, stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True
        )

    def stop(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
        self.proc.wait(timeout=60)
        self.log.close()


def pes(args: list[str], env: dict[str, str], **kwargs) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "pes.cli", *args],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kwargs,
    )


def attempts(folder: Path) -> list[dict]:
    path = folder / "attempts.jsonl"
    if not path.is_file():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def wait_until(check, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = check()
        if value:
            return value
        time.sleep(0.5)
    raise AssertionError(f"timed out waiting for {what}")


def alive_nodes(address: str, env: dict[str, str]) -> int:
    code = (
        "import ray, sys\n"
        f"ray.init(address={address!r}, log_to_driver=False, include_dashboard=False)\n"
        "print(sum(1 for n in ray.nodes() if n['Alive']))\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120
    )
    return int(run.stdout.strip().splitlines()[-1]) if run.returncode == 0 else 0


@pytest.fixture
def cluster(tmp_path):
    port = free_port()
    address = f"127.0.0.1:{port}"
    env = dict(
        os.environ,
        RAY_AUTH_MODE="token",
        RAY_AUTH_TOKEN=secrets.token_hex(16),
        RAY_USAGE_STATS_ENABLED="0",
        # a lost node is found within seconds, not Ray's default half minute
        RAY_health_check_period_ms="1000",
        RAY_health_check_failure_threshold="3",
        OMP_NUM_THREADS="1",
    )
    common = ["--num-cpus=1", "--disable-usage-stats"]
    # Ray's files in a folder of the test's own (a short path: Ray's sockets live there), so
    # that the default one (/tmp/ray) names no cluster of this test once it is stopped
    temp = tempfile.mkdtemp(prefix="pes-ray-")
    head = Node(
        ["--head", f"--port={port}", "--include-dashboard=false", f"--temp-dir={temp}", *common],
        env,
        tmp_path / "head",
    )
    nodes = [head]
    try:
        wait_until(lambda: alive_nodes(address, env) == 1, 180, "the head node")
        nodes.append(Node([f"--address={address}", *common], env, tmp_path / "worker"))
        wait_until(lambda: alive_nodes(address, env) == 2, 180, "the second node")
        yield address, env, nodes
    finally:
        for node in nodes:
            node.stop()
        shutil.rmtree(temp, ignore_errors=True)


def test_a_two_node_cluster_runs_sweeps_on_both_nodes_and_retries_a_lost_node(cluster, tmp_path):
    address, env, (head, worker) = cluster

    # no token on this side: one line that names the fix, within the timeout
    bare = {k: v for k, v in env.items() if not k.startswith("RAY_AUTH")}
    refused = pes(["reproduce", "table4", "--budget", "tiny", "--seeds", "1", "--methods",
                   "pid-pf", "--ray-address", address, "--ray-timeout", "10", "--json",
                   "--out", str(tmp_path / "refused")], bare)  # fmt: skip
    _, err = refused.communicate(timeout=120)
    assert refused.returncode != 0
    last = err.strip().splitlines()[-1]
    assert last.startswith("error: ") and "RAY_AUTH_MODE=token" in last, err

    # pes tune: its two trials at once, one on each node
    tune_out = tmp_path / "tune"
    tune = pes(["tune", "--algo", "maddpg", "--preset", "tiny", "--trials", "2", "--halvings",
                "0", "--env-steps", "400", "--eval-episodes", "2", "--parallel", "2",
                "--ray-address", address, "--json", "--out", str(tune_out)], env)  # fmt: skip
    out, err = tune.communicate(timeout=600)
    assert tune.returncode == 0, err
    assert "2 node(s), 2 CPUs" in err
    nodes = {a["node"] for t in ("t00", "t01") for a in attempts(tune_out / "trials" / t)}
    assert len(nodes) == 2, nodes
    assert json.loads(out)["trials"] == 2

    # pes reproduce: two trials training for 24 s each, one per node; the worker node is killed
    # while its trial trains, and the trial is retried on the head and finishes
    out_dir = tmp_path / "reproduce"
    trials = out_dir / "trials"
    run = pes(["reproduce", "table4", "--budget", "tiny", "--seeds", "1", "--methods", "ddpg",
               "maddpg", "--parallel", "2", "--set", "episodes=1000000", "--set",
               "time_limit=0.4", "--ray-address", address, "--json", "--out", str(out_dir)],
              env)  # fmt: skip
    try:
        started = wait_until(
            lambda: (
                (a := {t: attempts(trials / t) for t in ("ddpg-s0", "maddpg-s0")})
                and all(a.values())
                and a
            ),
            300,
            "both trials to start",
        )
        first = {t: a[0]["node"] for t, a in started.items()}
        assert len(set(first.values())) == 2, first
        worker.stop()
        out, err = run.communicate(timeout=600)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0, err
    summary = json.loads(out)
    assert summary["ran"] == 2 and summary["unfinished"] == 0
    retried = [t for t in first if len(attempts(trials / t)) > 1]
    assert len(retried) == 1, {t: attempts(trials / t) for t in first}
    (lost,) = retried
    survivor = next(node for t, node in first.items() if t != lost)
    assert attempts(trials / lost)[-1]["node"] == survivor
    for t in first:
        assert (trials / t / "done.json").is_file()
