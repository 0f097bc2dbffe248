"""One writer per output folder: the lock that ``pes train``, ``pes tune`` and ``pes reproduce``
hold on the folders they write (docs/training.md, "One writer per folder").

A lock is the file ``FOLDER/.lock``, locked with ``flock`` for as long as its holder runs and
holding a line of JSON that names the holder (pid, host, start time). The operating system
releases the lock when its process ends, however it ends (a crash, SIGKILL, a lost node), so a
lock is never stale: a folder whose last holder died is taken over at once, with a line that
names the holder that is gone. A second writer fails at once with a :class:`FolderInUseError`
naming the holder.

On a local filesystem the guarantee is complete. On NFS, Linux implements ``flock`` with NFS
byte-range locks: writers on different nodes exclude each other when the NFS lock service runs
(NFSv4, or NFSv3 with ``lockd``); a mount with ``nolock`` or ``local_lock=flock`` keeps the
locks on each node, and then only writers on the same node exclude each other.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import socket
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from pes.errors import FolderInUseError

LOCK_NAME = ".lock"
"""The lock file in a locked folder."""


def _holder_text(record: dict) -> str:
    started = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(record.get("started", 0)))
    return f"pid {record.get('pid', '?')} on {record.get('host', '?')} since {started}"


def _read(handle) -> dict | None:
    handle.seek(0)
    text = handle.read().strip()
    if not text:
        return None
    try:
        record = json.loads(text)
    except json.JSONDecodeError:
        return None
    return record if isinstance(record, dict) else None


def _in_use(folder: Path, handle, prefix: str = "") -> FolderInUseError:
    """The one-line error for ``folder``, whose lock file ``handle`` another process holds."""
    holder = _read(handle)
    who = _holder_text(holder) if holder else "another process"
    return FolderInUseError(
        f"{prefix}'{folder}' is in use by {who}; wait for it to finish, stop it, or choose "
        "another --out"
    )


class FolderLock:
    """The lock on ``folder`` (created if missing): :meth:`acquire` takes it or raises
    :class:`FolderInUseError`; :meth:`release` lets it go. Locks are per open file, so two
    locks of one process on one folder exclude each other too.

    Args:
        folder: the folder to lock.
        what: the writer's name in messages (``pes train``, ...).
    """

    def __init__(self, folder: str | Path, what: str = "a run") -> None:
        self.folder = Path(folder)
        self.what = what
        self.path = self.folder / LOCK_NAME
        self.handle = None

    def acquire(self, wait: bool = False) -> FolderLock:
        """Take the lock (``wait``: block until it is free, else fail at once); says on
        stderr when it takes over from a holder that is gone."""
        self.folder.mkdir(parents=True, exist_ok=True)
        handle = open(self.path, "a+")  # noqa: SIM115 - held until release()
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            error = _in_use(self.folder, handle)
            handle.close()
            raise error from None
        previous = _read(handle)
        if previous is not None:
            print(
                f"{self.what}: taking over '{self.folder}' from {_holder_text(previous)}, "
                "which ended without releasing it",
                file=sys.stderr,
            )
        handle.seek(0)
        handle.truncate()
        record = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.time()}
        handle.write(json.dumps(record) + "\n")
        handle.flush()
        self.handle = handle
        return self

    def release(self) -> None:
        """Let the lock go, leaving the lock file empty (a clean end: no takeover line)."""
        if self.handle is None:
            return
        self.handle.seek(0)
        self.handle.truncate()
        self.handle.flush()
        fcntl.flock(self.handle, fcntl.LOCK_UN)
        self.handle.close()
        self.handle = None


@contextlib.contextmanager
def folder_lock(folder: str | Path, what: str = "a run", wait: bool = False) -> Iterator[None]:
    """Hold the lock on ``folder`` for the ``with`` block (:class:`FolderLock`)."""
    lock = FolderLock(folder, what).acquire(wait)
    try:
        yield
    finally:
        lock.release()


def check_free(folders: list[Path], what: str) -> None:
    """Raise :class:`FolderInUseError` at once if any of ``folders`` (those that exist) is
    locked by a running writer, before a sweep starts work that would meet it later."""
    for folder in folders:
        if (folder / LOCK_NAME).is_file():
            with open(folder / LOCK_NAME, "a+") as handle:
                try:
                    fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    raise _in_use(folder, handle, f"{what}: ") from None
                fcntl.flock(handle, fcntl.LOCK_UN)
