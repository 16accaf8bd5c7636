"""``stop_on_signals``: what a node waits on, and what it leaves behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

from toploc.commands.options import stop_on_signals

REPO = Path(__file__).resolve().parents[2]


def test_sigterm_and_ctrl_c_set_the_event_within_the_block() -> None:
    for signum in (signal.SIGTERM, signal.SIGINT):
        with stop_on_signals() as stop:
            signal.raise_signal(signum)  # does not raise, does not end the process
            assert stop.is_set()


def test_ctrl_c_exits_130_and_sigterm_0_whichever_came_second() -> None:
    for first, second, code in [
        (signal.SIGINT, signal.SIGTERM, 130),
        (signal.SIGTERM, signal.SIGINT, 0),
    ]:
        with stop_on_signals() as stop:
            signal.raise_signal(first)
            signal.raise_signal(second)  # a Ctrl-C while it shuts down changes nothing
        assert stop.exit_code == code


def test_the_previous_handlers_are_back_after_the_block() -> None:
    before = (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM))
    with stop_on_signals():
        assert signal.getsignal(signal.SIGINT) is not before[0]
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before


WAIT_FOR_A_SIGNAL_ON_ANOTHER_THREAD = """
import signal, threading, time
from toploc.commands.options import stop_on_signals

with stop_on_signals() as stop:
    def send() -> None:  # the kernel may deliver a process's signal to any of its threads
        time.sleep(0.3)
        signal.pthread_kill(threading.get_ident(), signal.SIGTERM)
        time.sleep(30)  # this thread stays alive, as Zenoh's do

    threading.Thread(target=send, daemon=True).start()
    stop.{wait}
print("stopped", stop.exit_code)
"""


def test_the_wait_ends_when_the_signal_lands_on_another_thread() -> None:
    """A node's main thread wakes for a SIGTERM that the kernel gave another thread."""
    script = WAIT_FOR_A_SIGNAL_ON_ANOTHER_THREAD.replace("{wait}", "wait_for_signal()")
    done = subprocess.run(
        [sys.executable, "-c", script],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        timeout=20,
    )
    assert done.stdout.strip() == "stopped 0", done.stdout + done.stderr
