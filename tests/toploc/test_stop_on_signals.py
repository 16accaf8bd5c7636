"""``stop_on_signals``: what a node waits on, and what it leaves behind."""

from __future__ import annotations

import signal

from toploc.commands.options import stop_on_signals


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
