"""Stop requests: signals close together are one request (GNU `timeout`, systemd)."""

from __future__ import annotations

import os
import signal

import pytest

from groundstation.app.signals import STOP_SIGNALS, StopRequests, on_stop_signals


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_a_repeat_within_the_window_is_the_same_request() -> None:
    clock = FakeClock()
    stops = StopRequests(0.5, clock)
    assert stops.request() and stops.count == 1
    clock.t += 0.001  # `timeout`: the process, then its group, a millisecond apart
    assert not stops.request()
    clock.t += 0.3
    assert not stops.request()
    assert stops.count == 1 and stops.ignored == 2
    clock.t = 100.5  # half a second after the first: the operator asks again
    assert stops.request() and stops.count == 2


def test_zero_window_counts_every_signal_and_negative_is_refused() -> None:
    stops = StopRequests(0.0, FakeClock())
    assert stops.request() and stops.request() and stops.count == 2
    with pytest.raises(ValueError):
        StopRequests(-0.1)


def test_two_real_signals_a_millisecond_apart_count_once() -> None:
    stops = StopRequests(0.5)
    with on_stop_signals(lambda _sig: stops.request()):
        os.kill(os.getpid(), signal.SIGTERM)
        os.kill(os.getpid(), signal.SIGTERM)
    assert stops.count == 1 and stops.ignored == 1


@pytest.mark.parametrize("sig", [signal.SIGHUP, signal.SIGQUIT, signal.SIGINT, signal.SIGTERM])
def test_hangup_and_quit_are_stop_requests_and_the_old_handlers_come_back(
        sig: signal.Signals) -> None:
    """Python's default for SIGHUP (a closed terminal) and SIGQUIT (Ctrl-\\) ends the
    process at once: no landing. Inside, each is a stop request; after, whatever was
    installed before is back."""
    before = signal.getsignal(sig)
    got: list[signal.Signals] = []
    with on_stop_signals(got.append):
        os.kill(os.getpid(), sig)
    assert got == [sig]
    assert signal.getsignal(sig) == before


def test_a_hangup_asks_for_a_stop_and_never_for_more() -> None:
    """One hangup reaches a process more than once (its shell forwards it, then the
    kernel sends it to the foreground group as the shell exits), seconds apart on a
    loaded machine: it must not turn a landing into a handback in the air."""
    clock = FakeClock()
    stops = StopRequests(0.5, clock)
    assert stops.request(escalates=False) and stops.count == 1
    clock.t += 5.0
    assert not stops.request(escalates=False) and stops.count == 1
    clock.t += 5.0
    assert stops.request() and stops.count == 2  # the operator asks again: hand back
    after_term = StopRequests(0.5, clock)
    assert after_term.request()
    clock.t += 5.0
    assert not after_term.request(escalates=False) and after_term.count == 1


def test_sigpipe_stays_ignored_during_a_flight() -> None:
    """A reader of our output that went away is lost output (EPIPE on that write), not
    a stop request: a restarted journald or an ended `| tee` must not land the vehicle."""
    assert signal.SIGPIPE not in STOP_SIGNALS
    with on_stop_signals(lambda _sig: None):
        assert signal.getsignal(signal.SIGPIPE) == signal.SIG_IGN
        read, write = os.pipe()
        os.close(read)
        try:
            with pytest.raises(BrokenPipeError):
                os.write(write, b"progress line\n")
        finally:
            os.close(write)
