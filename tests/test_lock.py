"""One writer per output folder (pes.lock): a second ``pes train``, ``pes reproduce`` or
``pes tune`` into a folder in use fails at once with one line naming the holder and changes
nothing there; a folder whose holder died is taken over with a line saying so. And a Ray
address where nothing answers is one line too (the real cluster: tests/test_cluster.py)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from pes.cli import main
from pes.errors import FolderInUseError
from pes.lock import FolderLock, check_free, folder_lock
from tests.learning import FAST

HOLD = (
    "import sys, time\n"
    "from pes.lock import FolderLock\n"
    "lock = FolderLock(sys.argv[1]).acquire()\n"
    "print('held', flush=True)\n"
    "time.sleep(600)\n"
)


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (the lock file aside) and its bytes."""
    return {
        str(p.relative_to(folder)): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != ".lock"
    }


def test_a_second_lock_fails_at_once_naming_the_holder(tmp_path):
    with folder_lock(tmp_path / "run", "pes train"):
        with pytest.raises(FolderInUseError, match=rf"in use by pid {os.getpid()} on "):
            FolderLock(tmp_path / "run").acquire()
        with pytest.raises(FolderInUseError, match="in use"):
            check_free([tmp_path / "run"], "pes reproduce")
    # released cleanly: the next holder takes it without a takeover line
    lock = FolderLock(tmp_path / "run").acquire()
    lock.release()
    check_free([tmp_path / "run", tmp_path / "missing"], "pes reproduce")


def test_a_lock_whose_holder_was_killed_is_taken_over_with_a_line(tmp_path, capsys):
    folder = tmp_path / "run"
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(folder)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(FolderInUseError, match=f"pid {holder.pid}"):
            FolderLock(folder).acquire()
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    lock = FolderLock(folder, "pes train").acquire()
    lock.release()
    err = capsys.readouterr().err
    assert f"pes train: taking over '{folder}' from pid {holder.pid}" in err
    assert "ended without releasing it" in err


def tiny_train(out: Path, *extra: str) -> list[str]:
    return ["train", "--algo", "maddpg", "--preset", "tiny", "--out", str(out), "--json",
            "--set", "episodes=8", "--set", "eval_episodes=0", "--set", "compile_env=false",
            "--set", f"tensorboard={str(FAST['tensorboard']).lower()}", *extra]  # fmt: skip


def test_a_second_train_into_a_folder_in_use_exits_with_one_line_and_changes_nothing(
    tmp_path, capsys
):
    out = tmp_path / "x"
    with folder_lock(out, "pes train"):  # a first run, still running (before any file)
        assert main(tiny_train(out)) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("error: ") and "in use by pid" in err
    assert snapshot(out) == {}

    assert main(tiny_train(out)) == 0  # the folder free again: a run, then --resume on it
    capsys.readouterr()
    before = snapshot(out)
    with folder_lock(out, "pes train"):
        assert main(tiny_train(out, "--resume", "--set", "episodes=16")) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "in use by pid" in err
    assert snapshot(out) == before


def test_a_sweep_whose_trial_is_in_use_fails_before_running_anything(tmp_path, capsys):
    out = tmp_path / "sweep"
    argv = ["reproduce", "table4", "--budget", "tiny", "--seeds", "1", "--methods", "pid-pf",
            "--no-ray", "--json", "--out", str(out)]  # fmt: skip
    with folder_lock(out / "trials" / "pid-pf-s0", "pes reproduce"):
        assert main(argv) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "pid-pf-s0' is in use by pid" in err
    assert not (out / "trials" / "pid-pf-s0" / "done.json").exists()
    assert not (out / "table4.md").exists()

    tune = ["tune", "--algo", "maddpg", "--preset", "tiny", "--trials", "2", "--halvings", "0",
            "--env-steps", "400", "--eval-episodes", "2", "--no-ray", "--json",
            "--out", str(tmp_path / "tune")]  # fmt: skip
    with folder_lock(tmp_path / "tune" / "trials" / "t00", "pes tune"):
        assert main(tune) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "t00' is in use by pid" in err


def test_an_unreachable_cluster_is_one_line_within_the_timeout(tmp_path, capsys):
    """Nothing listens on port 1: one line naming the address, at once (Ray alone would retry
    for minutes)."""
    argv = ["reproduce", "table6", "--budget", "tiny", "--seeds", "1", "--ray-address",
            "127.0.0.1:1", "--ray-timeout", "5", "--json", "--out", str(tmp_path)]  # fmt: skip
    assert main(argv) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: cannot reach a Ray cluster at 127.0.0.1:1")
