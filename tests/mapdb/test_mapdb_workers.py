"""``deferred_signals``: Ctrl-C during a parallel build is raised where the build checks for it,
never inside the process pool's own code. ``stop_workers``: a process whose pool was stopped
exits, even when a killed worker left half a result in the pool's pipe. ``results_in_order``: a
worker that dies while results are awaited is named, instead of a wait for ever."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from mapdb.workers import deferred_signals, describe_exit

REPO = Path(__file__).resolve().parents[2]

HALF_SENT_RESULT = """
import os, struct, time
from mapdb.workers import spawn_process_pool, stop_workers

pool = spawn_process_pool(1)
pool.submit(time.sleep, 60)
# the length of a 26,135-byte result and no payload: what a worker killed between the two
# writes of a large result leaves in the pipe (the pool's manager thread cannot tell who wrote)
os.write(pool._result_queue._writer.fileno(), struct.pack("!i", 26135))
stop_workers(pool)
"""


KILLED_WHILE_SENDING = """
import os, signal, struct, time
from mapdb.workers import WorkerDiedError, results_in_order, spawn_process_pool

pool = spawn_process_pool(1)
(pid,) = results_in_order(pool, [pool.submit(os.getpid)])  # the worker is up
sleeping = pool.submit(time.sleep, 60)
# half a result in the pipe (see HALF_SENT_RESULT), and then the worker is killed
os.write(pool._result_queue._writer.fileno(), struct.pack("!i", 26135))
os.kill(pid, signal.SIGKILL)
try:
    list(results_in_order(pool, [sleeping]))
except WorkerDiedError as error:
    print(f"{error} | pid {error.pid == pid} | exitcode {error.exitcode}")
"""


def run_python(code: str) -> subprocess.CompletedProcess[str]:
    """``code`` in a fresh interpreter with the repository on its path; fails the test if it
    has not exited within 30 s."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    try:
        return subprocess.run(
            [sys.executable, "-c", code], env=env, cwd=REPO, capture_output=True, text=True,
            timeout=30,
        )  # fmt: skip
    except subprocess.TimeoutExpired:
        pytest.fail("the process did not exit: it is still waiting for its pool")


@pytest.fixture(autouse=True)
def default_handlers() -> Iterator[None]:
    """Ctrl-C raises and SIGTERM is default, as in a fresh process (a node command run in the
    same test process may have left its own handlers)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    previous_term = signal.signal(signal.SIGTERM, signal.SIG_DFL)
    yield
    signal.signal(signal.SIGINT, previous)
    signal.signal(signal.SIGTERM, previous_term)


def test_ctrl_c_in_the_block_waits_for_check() -> None:
    reached = False
    with pytest.raises(KeyboardInterrupt), deferred_signals() as check:
        signal.raise_signal(signal.SIGINT)
        reached = True  # the signal did not raise here
        check()
    assert reached


def test_check_without_a_signal_does_nothing() -> None:
    with deferred_signals() as check:
        check()
        check()


def test_a_signal_after_the_last_check_raises_when_the_block_ends() -> None:
    after_block = False
    with pytest.raises(KeyboardInterrupt):
        with deferred_signals():
            signal.raise_signal(signal.SIGINT)
        after_block = True
    assert not after_block


def test_the_handlers_are_restored_after_the_block() -> None:
    before = signal.getsignal(signal.SIGINT)
    with deferred_signals():
        assert signal.getsignal(signal.SIGINT) is not before
    assert signal.getsignal(signal.SIGINT) is before


def test_a_sigterm_handler_runs_deferred_too() -> None:
    calls: list[int] = []
    previous = signal.signal(signal.SIGTERM, lambda signum, _frame: calls.append(signum))
    try:
        with deferred_signals() as check:
            signal.raise_signal(signal.SIGTERM)
            assert calls == []
            check()
            assert calls == [signal.SIGTERM]
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_default_sigterm_is_left_alone() -> None:
    previous = signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        with deferred_signals():
            assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_outside_the_main_thread_the_block_changes_nothing() -> None:
    seen: list[object] = []

    def in_thread() -> None:
        with deferred_signals() as check:
            seen.append(signal.getsignal(signal.SIGINT))
            check()

    before = signal.getsignal(signal.SIGINT)
    thread = threading.Thread(target=in_thread)
    thread.start()
    thread.join()
    assert seen == [before]


def test_a_second_ctrl_c_acts_at_once() -> None:
    with pytest.raises(KeyboardInterrupt), deferred_signals():
        signal.raise_signal(signal.SIGINT)  # noted
        signal.raise_signal(signal.SIGINT)  # raises here, not at the end of the block
        pytest.fail("the second Ctrl-C was deferred too")


def test_a_signal_noted_before_an_error_is_raised_over_it() -> None:
    with pytest.raises(KeyboardInterrupt) as raised, deferred_signals():
        signal.raise_signal(signal.SIGINT)
        raise RuntimeError("a worker died")
    assert isinstance(raised.value.__context__, RuntimeError)


def test_a_stopped_pool_whose_pipe_holds_half_a_result_lets_the_process_exit() -> None:
    """Before the fix the manager thread waited for the payload for ever, and the interpreter
    waited for that thread at exit (a killed build hung after printing "interrupted")."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    try:
        done = subprocess.run(
            [sys.executable, "-c", HALF_SENT_RESULT],
            env=env,
            cwd=REPO,
            capture_output=True,
            timeout=20,
        )
    except subprocess.TimeoutExpired:
        pytest.fail("the process did not exit: the pool's manager thread is still reading")
    assert done.returncode == 0, done.stderr.decode()


def test_a_worker_killed_while_sending_a_result_is_named_instead_of_awaited_for_ever() -> None:
    """Before ``check_workers`` the pool's manager thread read for ever, and every future of the
    pool, the sleeping one too, stayed pending: a map build that never ended."""
    done = run_python(KILLED_WHILE_SENDING)
    assert done.returncode == 0, done.stderr
    assert "was killed by SIGKILL (the out-of-memory killer, or a kill -9)" in done.stdout
    assert "| pid True | exitcode -9" in done.stdout


@pytest.mark.parametrize(
    ("exitcode", "words"),
    [
        (3, "exited with status 3"),
        (-signal.SIGKILL, "was killed by SIGKILL (the out-of-memory killer, or a kill -9)"),
        (-signal.SIGSEGV, "was ended by SIGSEGV"),
        (-200, "was ended by signal 200"),
    ],
)
def test_how_a_worker_ended_is_said_in_words(exitcode: int, words: str) -> None:
    assert describe_exit(exitcode) == words


def test_a_pool_that_noticed_a_dead_worker_first_still_names_it():
    from concurrent.futures.process import BrokenProcessPool

    from mapdb.workers import WorkerDiedError, spawn_process_pool, stop_workers

    pool = spawn_process_pool(1)
    try:
        worker_pid = pool.submit(os.getpid).result(timeout=60)
        (process,) = dict(pool._processes).values()
        process.kill()
        process.join(timeout=10)
        named = pool.named(BrokenProcessPool("A child process terminated abruptly"))
    finally:
        stop_workers(pool)
    assert isinstance(named, WorkerDiedError)
    assert named.pid == worker_pid and "SIGKILL" in str(named)
