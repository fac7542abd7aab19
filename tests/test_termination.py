"""SIGTERM ends a process promptly: at once where the main thread runs Python (``finally`` blocks run), and within
the grace period where it waits in native code, which Python's own handlers never interrupt."""

import signal
import subprocess
import sys
import time

from jarena import termination

WAITS_IN_NATIVE_CODE = """
import jax
from jarena import termination
forever = jax.jit(lambda x: jax.lax.while_loop(lambda c: c[0] < 1.0, lambda c: (c[0] * c[1], c[1]), (x, x))[0])
with termination.handling(grace=1.0):
    forever.lower(0.0).compile()  # compiled before the signal comes: the wait is in the computation
    print("waiting", flush=True)
    forever(0.0).block_until_ready()  # 0 * 0 stays below 1: never returns
"""

RUNS_PYTHON = """
import time
from jarena import termination
with termination.handling(grace=30.0):
    try:
        print("waiting", flush=True)
        while True:
            time.sleep(0.01)
    except termination.Terminated:
        print("closed what it had open", flush=True)
        raise SystemExit(termination.EXIT_STATUS)
"""


def _terminate_when_waiting(script: str) -> tuple[subprocess.CompletedProcess, float]:
    process = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    try:
        assert process.stdout.readline().strip() == "waiting"
        time.sleep(0.3)
        sent = time.monotonic()
        process.send_signal(signal.SIGTERM)
        out, err = process.communicate(timeout=60)
        return subprocess.CompletedProcess(process.args, process.returncode, out, err), time.monotonic() - sent
    finally:
        process.kill()


def test_sigterm_ends_a_process_whose_main_thread_waits_in_native_code():
    done, seconds = _terminate_when_waiting(WAITS_IN_NATIVE_CODE)
    assert done.returncode == termination.EXIT_STATUS == 143, done.stderr[-2000:]
    assert "did not stop within 1 s of SIGTERM" in done.stderr
    assert seconds < 10


def test_sigterm_raises_terminated_in_the_main_thread_at_once():
    done, seconds = _terminate_when_waiting(RUNS_PYTHON)
    assert done.returncode == 143, done.stderr[-2000:]
    assert "closed what it had open" in done.stdout
    assert "did not stop" not in done.stderr  # it ended by itself, long before the 30 s grace
    assert seconds < 10


def test_the_previous_handler_comes_back_after_the_block():
    before = signal.getsignal(signal.SIGTERM)
    with termination.handling():
        assert signal.getsignal(signal.SIGTERM) is not before
    assert signal.getsignal(signal.SIGTERM) is before
    assert not termination.received()
