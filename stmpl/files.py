"""Atomic file writes: a temporary file beside the target, then a rename, so a reader never sees
half a file and a killed writer leaves the old one in place; and a folder held by one process at
a time (:func:`folder_lock`).
"""

from __future__ import annotations

import contextlib
import os
import pathlib
import tempfile

import numpy as np


def _default_mode() -> int:
    """The mode a plain ``open(path, "w")`` would give (``mkstemp`` makes files 0600)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def atomic_savez(path, arrays: dict, compressed: bool = False) -> pathlib.Path:
    """Write ``arrays`` to the ``.npz`` file ``path`` atomically."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz")
    try:
        with os.fdopen(fd, "wb") as f:
            (np.savez_compressed if compressed else np.savez)(f, **arrays)
        os.chmod(tmp, _default_mode())
        os.replace(tmp, path)
    except BaseException:
        pathlib.Path(tmp).unlink(missing_ok=True)
        raise
    return path


class atomic_path:
    """``with atomic_path(target) as tmp:`` write ``tmp``; it becomes ``target`` only when the
    block ends without an error (a temporary file in the same folder, then ``os.replace``).
    """

    def __init__(self, path, suffix: str = ".tmp"):
        self.path = pathlib.Path(path)
        self.suffix = suffix

    def __enter__(self) -> pathlib.Path:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(
            dir=self.path.parent, prefix=self.path.name + ".", suffix=self.suffix
        )
        os.close(fd)
        self.tmp = pathlib.Path(tmp)
        return self.tmp

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            os.chmod(self.tmp, _default_mode())
            os.replace(self.tmp, self.path)
        else:
            self.tmp.unlink(missing_ok=True)


def atomic_write_text(path, text: str) -> pathlib.Path:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return pathlib.Path(path)


@contextlib.contextmanager
def folder_lock(folder, what: str):
    """Hold ``folder`` for this process while the block runs (``folder/.lock`` names its pid
    and ``what`` holds it): a second process that asks for it while the first lives gets a
    ``RuntimeError`` naming what holds it and that process; a lock left by a process that is
    gone is taken over.
    """
    path = pathlib.Path(folder) / ".lock"
    try:
        pid, _, holder = path.read_text().strip().partition(" ")
        pid = int(pid)
    except (OSError, ValueError):
        pid, holder = None, ""
    if pid is not None and pid != os.getpid() and _alive(pid):
        raise RuntimeError(
            f"{folder} is held by {holder or 'another run'} (process {pid}); wait for it to "
            "end or stop it"
        )
    atomic_write_text(path, f"{os.getpid()} {what}\n")
    try:
        yield
    finally:
        path.unlink(missing_ok=True)


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` runs on this machine."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's: alive
        return True
    return True
