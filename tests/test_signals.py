"""Stop requests: signals close together are one request (GNU `timeout`, systemd)."""

from __future__ import annotations

import os
import signal

import pytest

from groundstation.loop.signals import StopRequests, on_stop_signals


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
