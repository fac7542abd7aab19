"""A multi-process run that cannot go on fails within a bounded time, saying which process went missing.

Every process of a run (``jarena.distributed.initialize``) runs a watchdog thread that talks to the others
through the coordination service's key-value store (process 0 hosts it). Each process publishes, every
``interval`` seconds, a record: a heartbeat counter, the number and name of the last *collective point* it
entered (``jarena.distributed.fetch``: the points where a process waits on all others), a fingerprint of what it
fetches there, and its state (running, finished, failed, terminated). From the others' records each watchdog
knows, with its own clock only:

- a process whose heartbeat stopped for ``heartbeat`` seconds (killed, stopped, its machine gone), or a
  coordination service that stopped answering (process 0 gone), is missing;
- a process that failed or was terminated says so, and the others stop at once instead of waiting on it;
- a process that waits at collective point ``k`` while another has stayed at an earlier point for ``wait``
  seconds is waiting on a process that will not come (the timeout on a result fetch);
- two processes at the same point fetching differently shaped results entered different collectives, which
  would wait forever: a bug, reported at once.

A watchdog that finds such a failure prints what happened and that the run resumes from its checkpoints when
every process is started again with the same command, tells the others, and ends the process with status
:data:`EXIT_STATUS` (its main thread may be waiting in native code, which nothing else can interrupt). At the
end of a run each process waits for the others to finish too (:func:`finish`, at exit), so the process that
writes the results and videos is never cut short by the others leaving.
"""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import json
import os
import sys
import threading
import time
from typing import Any

from jarena import termination

#: Exit status of a process that stopped because another went missing: EX_TEMPFAIL, "try again" (resume).
EXIT_STATUS = 75

#: Defaults, overridable with the environment variables of :data:`ENVIRONMENT`.
HEARTBEAT_SECONDS = 60.0
WAIT_SECONDS = 900.0
ENVIRONMENT = {"heartbeat": "JARENA_HEARTBEAT_TIMEOUT", "wait": "JARENA_WAIT_TIMEOUT"}

_PREFIX = "jarena/watchdog/"


@dataclasses.dataclass(frozen=True)
class Limits:
    """How long a process waits before it calls another missing.

    Attributes:
      heartbeat: seconds without a heartbeat (or an answer from the coordination service) after which a
        process is missing.
      wait: seconds a process waits at a collective point for another that has not reached it (and is not
        moving) before it gives up. Must cover the slowest legitimate difference between processes, such
        as one compiling a program the other found in its cache.
    """

    heartbeat: float = HEARTBEAT_SECONDS
    wait: float = WAIT_SECONDS

    def __post_init__(self):
        for name in ("heartbeat", "wait"):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not value > 0:
                raise ValueError(f"watchdog {name} must be a positive number of seconds, got {value!r}")

    @property
    def interval(self) -> float:
        """Seconds between heartbeats: several per ``heartbeat``, at most 1 (two small key-value calls per
        process and second: nothing next to a run's own traffic)."""
        return min(1.0, self.heartbeat / 8)

    @classmethod
    def from_environment(cls) -> Limits:
        """Limits from ``JARENA_HEARTBEAT_TIMEOUT`` and ``JARENA_WAIT_TIMEOUT`` (seconds), defaults elsewhere."""
        values = {}
        for name, var in ENVIRONMENT.items():
            text = os.environ.get(var)
            if text:
                try:
                    values[name] = float(text)
                except ValueError:
                    raise ValueError(f"{var} must be a number of seconds, got {text!r}") from None
        return cls(**values)


@dataclasses.dataclass
class _Record:
    beat: int = 0
    point: int = 0
    name: str = "start"
    fingerprint: str = ""
    state: str = "running"  # running | finished | failed | terminated
    message: str = ""


class Watchdog:
    """The watchdog of one process (see the module docstring); :func:`start` makes the process's one."""

    def __init__(self, client, process: int, processes: int, limits: Limits, coordinator: str):
        self.client, self.process, self.processes, self.limits = client, process, processes, limits
        self.coordinator = coordinator
        self.record = _Record()
        self.resume_hint = ("start every process again with the same command: a run with a run directory resumes "
                            "from its last checkpoint")
        self._lock = threading.Lock()
        self._seen: dict[int, tuple[int, float]] = {}  # process -> (beat, my time it last changed)
        self._points: dict[int, tuple[int, float]] = {}  # process -> (point, my time it last changed)
        self._others: dict[int, _Record] = {}
        self._last_round = self._entered = time.monotonic()
        self._stopped = False
        self._failing = False

    # -- what the process tells its watchdog ------------------------------------------------------------------
    def enter(self, name: str, fingerprint: str = "") -> None:
        """This process is at its next collective point, ``name``, fetching results shaped ``fingerprint``."""
        with self._lock:
            self.record.point += 1
            self.record.name, self.record.fingerprint = name, fingerprint
            self._entered = time.monotonic()
        self._publish()

    def set_state(self, state: str, message: str = "") -> None:
        with self._lock:
            self.record.state, self.record.message = state, message
        self._publish()

    # -- the thread --------------------------------------------------------------------------------------------
    def run(self) -> None:
        threading.Thread(target=self._loop, name="jarena-watchdog", daemon=True).start()
        threading.Thread(target=self._deadman, name="jarena-watchdog-deadman", daemon=True).start()

    def stop(self) -> None:
        self._stopped = True

    def _key(self, process: int) -> str:
        return f"{_PREFIX}{process}"

    def _publish(self) -> None:
        with self._lock:
            self.record.beat += 1
            text = json.dumps(dataclasses.asdict(self.record))
        with contextlib.suppress(Exception):  # the service gone: the loop and the deadman report it
            self.client.key_value_set(self._key(self.process), text, allow_overwrite=True)

    def _read(self, process: int) -> _Record | None:
        try:
            text = self.client.key_value_try_get(self._key(process))
        except Exception as e:  # noqa: BLE001 - not published yet (NOT_FOUND), or the service is unreachable
            if "NOT_FOUND" in str(e) or "not found" in str(e).lower():
                return None
            raise
        return _Record(**json.loads(text))

    def _loop(self) -> None:
        while not self._stopped:
            self._publish()
            try:
                for p in range(self.processes):
                    if p != self.process:
                        record = self._read(p)
                        if record is not None:
                            self._others[p] = record
                self._last_round = time.monotonic()
            except Exception as e:  # noqa: BLE001
                self._check_service(e)
            else:
                problem = self._problem(time.monotonic())
                if problem:
                    self.fail(problem)
            time.sleep(self.limits.interval)

    def _deadman(self) -> None:
        """Reports a coordination service that stopped answering altogether (a call that hangs)."""
        while not self._stopped:
            time.sleep(self.limits.interval)
            if time.monotonic() - self._last_round > self.limits.heartbeat:
                self.fail(self._service_lost(f"no answer for {self.limits.heartbeat:g} s"))

    def _check_service(self, error: Exception) -> None:
        if time.monotonic() - self._last_round > self.limits.heartbeat:
            self.fail(self._service_lost(f"{type(error).__name__}: {str(error).splitlines()[0][:200]}"))

    def _service_lost(self, why: str) -> str:
        return (f"lost the coordination service at {self.coordinator}, which process 0 hosts ({why}): process 0 "
                "went missing")

    def _problem(self, now: float) -> str | None:
        """What is wrong with the run from this process's view, or ``None``."""
        for p, other in self._others.items():  # when each process's heartbeat and point last changed, by my clock
            if self._seen.get(p, (None,))[0] != other.beat:
                self._seen[p] = (other.beat, now)
            if self._points.get(p, (None,))[0] != other.point:
                self._points[p] = (other.point, now)
        mine = self.record
        for p, other in sorted(self._others.items()):
            since, point_since = self._seen[p][1], self._points[p][1]
            if other.state in ("failed", "terminated"):
                return f"process {p} {'was terminated' if other.state == 'terminated' else 'stopped'}: {other.message}"
            if other.state == "finished":
                if mine.state == "running" and mine.point > other.point:
                    return (f"process {p} finished at collective point {other.point} ({other.name!r}) while this "
                            f"process waits at point {mine.point} ({mine.name!r}): the processes ran different "
                            "programs")
                continue
            if now - since > self.limits.heartbeat:
                return (f"process {p} stopped responding: no heartbeat for {now - since:.0f} s (its last "
                        f"collective point: {other.point}, {other.name!r})")
            if other.point == mine.point and other.fingerprint and mine.fingerprint \
                    and other.fingerprint != mine.fingerprint:
                return (f"processes {self.process} and {p} entered collective point {mine.point} ({mine.name!r}) "
                        f"with different results to fetch ({mine.fingerprint} vs {other.fingerprint}): they would "
                        "wait on each other forever")
            waited = now - max(point_since, self._entered)  # since both were where they are now
            if mine.state == "running" and other.point < mine.point and waited > self.limits.wait:
                return (f"process {p} has not reached collective point {mine.point} ({mine.name!r}) in "
                        f"{waited:.0f} s; it is still at point {other.point} ({other.name!r})")
        return None

    def fail(self, problem: str, status: int = EXIT_STATUS, state: str = "failed") -> None:
        """Reports ``problem``, tells the other processes and ends this process with ``status`` (without JAX's
        shutdown, whose barrier would wait for the processes that are gone)."""
        with self._lock:
            if self._failing:
                return
            self._failing = True
        if termination.received():  # this process was told to stop: that is why it ends, whatever else it saw
            status, state, problem = termination.EXIT_STATUS, "terminated", "it received SIGTERM"
        self.record.state, self.record.message = state, problem
        self._publish()
        print(f"jarena: process {self.process} of {self.processes} stops: {problem}. The run cannot go on; "
              f"to resume it, {self.resume_hint}.", file=sys.stderr, flush=True)
        sys.stdout.flush()
        if self.process == 0:
            self._let_the_others_leave()
        os._exit(status)

    def _let_the_others_leave(self) -> None:
        """Process 0 hosts the coordination service: leaving at once would make JAX abort the processes still
        connected to it (with its own message, not this one), so it waits, 10 s at most, until every other
        process has gone silent (each stops too on seeing this one's record)."""
        deadline = time.monotonic() + min(10.0, self.limits.heartbeat)
        silent = 2.5 * self.limits.interval + 0.5
        while time.monotonic() < deadline:
            now = time.monotonic()
            if all(now - self._seen.get(p, (None, now))[1] > silent for p in self._others):
                return
            time.sleep(self.limits.interval / 4)

    def crashed(self, error: BaseException, status: int = 1) -> None:
        """Ends this process after ``error`` in its main thread, naming the process that went missing if that is
        what caused it: a collective whose peer died fails at once (gloo: "connection reset"), before any
        heartbeat is overdue, so the watchdog watches a few more heartbeats to see whose have stopped."""
        summary = f"{type(error).__name__}: {str(error).strip().splitlines()[0][:300] if str(error).strip() else ''}"
        silent = 2.5 * self.limits.interval + 0.5  # a live process beats every interval

        def missing(now: float) -> tuple[list[int], list[str]]:
            """The processes silent for longer than ``silent`` (a process's last beat is timed when this process
            read it, up to an interval or a busy scheduler's delay later), and those that said they stopped."""
            gone = [p for p, r in sorted(self._others.items())
                    if r.state == "running" and now - self._seen.get(p, (None, now))[1] > silent]
            told = [f"process {p} {'was terminated' if r.state == 'terminated' else 'failed'}"
                    for p, r in sorted(self._others.items()) if r.state in ("failed", "terminated")]
            return gone, told

        # a dead process shows as silent `silent` seconds after this process last read its beat; a few more
        # intervals leave room for a slow read, and the wait ends as soon as one shows
        settle = time.monotonic() + silent + 4 * self.limits.interval
        while time.monotonic() < settle and time.monotonic() - self._last_round < self.limits.heartbeat:
            if any(missing(time.monotonic())):
                break
            time.sleep(self.limits.interval / 2)
        now = time.monotonic()
        if now - self._last_round > silent:
            self.fail(f"{self._service_lost('it stopped answering')}, and then {summary}", status)
        gone, told = missing(now)
        if gone:
            self.fail(f"process{'es' if len(gone) > 1 else ''} {', '.join(map(str, gone))} went missing (no "
                      f"heartbeat in {now - max(self._seen[p][1] for p in gone):.0f} s), and the collective with "
                      f"{'them' if len(gone) > 1 else 'it'} failed: {summary}", status)
        if told:
            self.fail(f"{', '.join(told)}, and then {summary}", status)
        self.fail(summary, status)

    def wait_for_all(self) -> None:
        """Waits until every other process has finished (or the loop finds one missing and ends this one)."""
        while not self._stopped:
            if all(self._others.get(p) is not None and self._others[p].state == "finished"
                   for p in range(self.processes) if p != self.process):
                return
            time.sleep(self.limits.interval / 2)


_watchdog: Watchdog | None = None


def start(launch: Any, limits: Limits | None = None) -> Watchdog | None:
    """Starts this process's watchdog after ``jax.distributed.initialize`` (``launch``: a
    ``jarena.distributed.Launch``); at exit the process marks itself finished and waits for the others."""
    global _watchdog
    if _watchdog is not None or launch is None or launch.num_processes < 2:
        return _watchdog
    from jax._src import distributed as jax_distributed

    client = jax_distributed.global_state.client
    if client is None:
        raise RuntimeError("start the watchdog after jax.distributed.initialize")
    _watchdog = Watchdog(client, launch.process_id, launch.num_processes, limits or Limits.from_environment(),
                         launch.coordinator)
    _watchdog._publish()
    _watchdog.run()
    atexit.register(finish)  # runs before JAX's own shutdown, registered when jax was imported
    previous_hook = sys.excepthook

    def hook(kind, error, traceback):  # an uncaught error: the others learn of it at once (and why)
        previous_hook(kind, error, traceback)
        if _watchdog is not None and isinstance(error, Exception):
            _watchdog.crashed(error, 1)

    sys.excepthook = hook
    return _watchdog


def current() -> Watchdog | None:
    """This process's watchdog, or ``None`` in a single-process run."""
    return _watchdog


def enter(name: str, fingerprint: str = "") -> None:
    """Marks a collective point (every process enters the same points in the same order); no-op without a
    watchdog."""
    if _watchdog is not None:
        _watchdog.enter(name, fingerprint)


def set_resume_hint(text: str) -> None:
    """What a failure message tells the user to do to resume (e.g. the run directory's checkpoints)."""
    if _watchdog is not None:
        _watchdog.resume_hint = text


def fail(problem: str, status: int = EXIT_STATUS) -> None:
    """Ends this process with ``status`` as a failure the other processes learn of at once (no-op without a
    watchdog)."""
    if _watchdog is not None:
        _watchdog.fail(problem, status)


def crashed(error: BaseException, status: int = 1) -> None:
    """Ends this process after ``error``, naming a process that went missing if one did (no-op without a
    watchdog); see :meth:`Watchdog.crashed`."""
    if _watchdog is not None:
        _watchdog.crashed(error, status)


def terminated() -> None:
    """Tells the other processes that this one received SIGTERM (called from the signal's watcher thread)."""
    if _watchdog is not None:
        _watchdog.set_state("terminated", "it received SIGTERM")


def finish() -> None:
    """Marks this process finished and waits for the others (so that none leaves while process 0 still writes);
    run at exit."""
    if _watchdog is None or _watchdog.record.state != "running":
        return
    _watchdog.set_state("finished")
    _watchdog.wait_for_all()
    _watchdog.stop()
