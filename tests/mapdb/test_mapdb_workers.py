"""``deferred_signals``: Ctrl-C during a parallel build is raised where the build checks for it,
never inside the process pool's own code."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator

import pytest

from mapdb.workers import deferred_signals


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
