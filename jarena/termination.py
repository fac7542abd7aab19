"""SIGTERM, what schedulers send first, ends a run promptly and keeps what it saved.

Python's signal handlers run in the main thread between bytecodes, so a process whose main thread waits in
native code (a compiled chunk, a collective, a compilation) would not see the signal until that call returns:
minutes, or never if it waits on a process that is gone. Within :func:`handling` (the command line runs every
command in it) SIGTERM is therefore handled twice:

- in the main thread, as soon as it runs Python again, the signal raises :class:`Terminated`, so ``finally``
  blocks close logs and checkpoint managers (checkpoints and CSV files are written atomically: a write cut
  short leaves the previous ones, never half a file);
- in a watcher thread, woken at once through the signal module's wakeup file descriptor, the callbacks given
  to :func:`on_signal` run (a multi-process run tells the other processes, ``jarena.watchdog``) and, if the
  main thread has not left the block ``grace`` seconds later, the process exits with status 143 (128 + SIGTERM).

A second SIGTERM exits at once.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import sys
import threading
import time
from collections.abc import Callable

#: Exit status of a process ended by SIGTERM (the shell's 128 + signal number).
EXIT_STATUS = 128 + signal.SIGTERM

#: Seconds the main thread has to unwind after SIGTERM before the process exits regardless.
GRACE_SECONDS = 10.0


class Terminated(BaseException):  # noqa: N818 - a signal, like KeyboardInterrupt, not an error
    """Raised in the main thread when the process receives SIGTERM (a ``BaseException``, like
    ``KeyboardInterrupt``: an ``except Exception`` does not swallow it)."""


_callbacks: list[Callable[[], None]] = []
_state: dict = {"active": False, "received": False, "raised": False, "grace": GRACE_SECONDS}
_watcher: dict = {}


def on_signal(callback: Callable[[], None]) -> None:
    """Runs ``callback()`` in the watcher thread as soon as SIGTERM arrives (even while the main thread waits in
    native code). Callbacks must be quick and must not raise; one given again is kept once."""
    if callback not in _callbacks:
        _callbacks.append(callback)


def received() -> bool:
    """Whether this process has received SIGTERM while :func:`handling` it."""
    return bool(_state["received"])


@contextlib.contextmanager
def handling(grace: float = GRACE_SECONDS):
    """Within the block, SIGTERM raises :class:`Terminated` in the main thread and ends the process within
    ``grace`` seconds (see the module docstring); the previous handler is restored after it.

    Outside the main thread, where Python cannot set signal handlers, it changes nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    write_end = _start_watcher()
    previous = signal.signal(signal.SIGTERM, _raise_in_main_thread)
    previous_fd = signal.set_wakeup_fd(write_end, warn_on_full_buffer=False)
    _state.update(active=True, received=False, raised=False, grace=float(grace))
    try:
        yield
    finally:
        _state["active"] = False
        signal.signal(signal.SIGTERM, previous)
        signal.set_wakeup_fd(previous_fd)


def _start_watcher() -> int:
    """The wakeup pipe's write end; the pipe and its watcher thread are made once per process."""
    if not _watcher:
        read_end, write_end = os.pipe()
        os.set_blocking(read_end, False)
        os.set_blocking(write_end, False)
        _watcher.update(read_end=read_end, write_end=write_end)
        threading.Thread(target=_watch, args=(read_end,), name="jarena-sigterm", daemon=True).start()
    return _watcher["write_end"]


def _raise_in_main_thread(signum, frame):
    if _state["raised"]:  # a second SIGTERM while unwinding: no more waiting
        _exit_now("a second SIGTERM")
    _state.update(raised=True, received=True)
    raise Terminated("received SIGTERM")


def _watch(read_end: int) -> None:
    """The watcher thread: on SIGTERM's byte on the wakeup pipe (while handling), runs the callbacks and exits the
    process if the main thread has not left the handling block within the grace period."""
    while True:
        select.select([read_end], [], [])
        try:
            data = os.read(read_end, 512)
        except BlockingIOError:
            continue
        if signal.SIGTERM in data and _state["active"]:
            break
    _state["received"] = True
    for callback in list(_callbacks):
        with contextlib.suppress(Exception):  # a failing callback must not keep the process alive
            callback()
    grace = _state["grace"]
    deadline = time.monotonic() + grace
    while time.monotonic() < deadline:
        if not _state["active"]:  # the main thread left the block: it ends the process (or goes on) itself
            return
        time.sleep(0.05)
    _exit_now(f"the main thread did not stop within {grace:g} s of SIGTERM (it was waiting in native code)")


def _exit_now(why: str) -> None:
    print(f"jarena: terminated: {why}; what was saved is kept (checkpoints, logs, datasets)", file=sys.stderr,
          flush=True)
    sys.stdout.flush()
    os._exit(EXIT_STATUS)
