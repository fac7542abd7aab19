"""File-system helpers for a dataset's directory: one writer at a time, and cleaning up after a killed one."""

from __future__ import annotations

import contextlib
import os

from jarena.data.chunks import PARTIAL_SUFFIX
from jarena.data.schema import DatasetError


def remove_partial_files(path: str) -> None:
    """Deletes temporary files that a killed writer left behind (chunks go to ``*.partial``, then are renamed)."""
    for directory, _, files in os.walk(path):
        for name in files:
            if name.endswith(PARTIAL_SUFFIX):
                with contextlib.suppress(OSError):
                    os.remove(os.path.join(directory, name))


class _DirectoryLock:
    """An exclusive advisory lock on a directory, released when closed or when the process dies."""

    def __init__(self, path: str):
        import fcntl

        self._fd = os.open(path, os.O_RDONLY)
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(self._fd)
            raise DatasetError(f"dataset {path!r} is open for writing by another process") from None

    def close(self) -> None:
        os.close(self._fd)


class _NoLock:
    def close(self) -> None:
        pass


def lock(path: str):
    """Takes the exclusive writer's lock on the dataset directory ``path`` (``DatasetError`` if held)."""
    try:
        return _DirectoryLock(path)
    except ImportError:  # no fcntl (Windows): no cross-process protection
        return _NoLock()
