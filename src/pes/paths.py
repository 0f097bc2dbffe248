"""Output paths: one check, shared by every command and writer that creates files.

A user who points ``--out`` at an impossible place (under a regular file, in ``/proc``, in a
folder without write permission) gets a one-line :class:`pes.errors.ConfigError` naming the
path, before any work is done, instead of a ``FileNotFoundError`` or ``FileExistsError``
traceback from deep inside a writer.
"""

from __future__ import annotations

import shlex
import tempfile
from pathlib import Path

from pes.errors import ConfigError


def _blocking_file(path: Path) -> Path | None:
    """The first existing ancestor of ``path`` that is not a folder, or None."""
    for parent in reversed(path.parents):
        if parent.exists() and not parent.is_dir():
            return parent
    return None


def _make_folder(folder: Path, target: Path) -> None:
    blocker = _blocking_file(folder / "x")
    if blocker is not None:
        raise ConfigError(f"cannot write {target}: {blocker} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"cannot write {target}: {exc.strerror or exc}") from None
    # Try it: permission bits do not tell (root, read-only mounts, /proc).
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise ConfigError(f"cannot write {target}: {exc.strerror or exc} in {folder}") from None


def prepare_output(path: str | Path) -> Path:
    """Make sure the file ``path`` can be written: its folder exists (created with its
    parents) and is writable, and ``path`` is not a folder. Returns ``path`` as a Path; raises
    a one-line :class:`ConfigError` otherwise. An existing file is overwritten later."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"cannot write {path}: it is a folder, give a file name")
    _make_folder(path.parent, path)
    return path


def prepare_output_dir(path: str | Path) -> Path:
    """Make sure the folder ``path`` exists (created with its parents) and is writable.
    Returns it as a Path; raises a one-line :class:`ConfigError` otherwise."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ConfigError(f"cannot write into {path}: it is a file, not a folder")
    _make_folder(path, path)
    return path


def _in_repository(path: Path) -> str | None:
    """``path`` relative to the root of the git work tree it lies in, or None."""
    for folder in (path, *path.parents):
        if (folder / ".git").exists():
            return path.relative_to(folder).as_posix() or "."
    return None


def recorded_command(words: list[str]) -> str:
    """The command line ``words`` as reports record it (shell-quoted): an absolute path that
    lies in a git work tree, alone or after ``--option=``, is written relative to that tree's
    root, so a committed record names the folder as a reader of the repository finds it
    (``--out results/quick``, not this machine's ``/home/…/results/quick``)."""

    def portable(word: str) -> str:
        head, sep, tail = word.partition("=")
        if not (sep and word.startswith("--")):  # a word of its own, not --option=value
            head, sep, tail = "", "", word
        if not tail.startswith("/"):
            return word
        relative = _in_repository(Path(tail))
        return word if relative is None else head + sep + relative

    return shlex.join(portable(word) for word in words)
