"""DATA stream monitor: counter gaps and repeats (uint16 wrap) and the windowed rate."""

from __future__ import annotations

import pytest

from groundstation.asctec.stats import DataStreamMonitor
from groundstation.errors import ConfigError


def test_counter_gaps_repeats_and_wrap() -> None:
    m = DataStreamMonitor()
    # 65534, 65535, 0 (wrap = +1), 1, 1 (repeat), 4 (2 missed), 5
    for i, c in enumerate([65534, 65535, 0, 1, 1, 4, 5]):
        m.update(c, 0.01 * i)
    assert (m.counter_repeats, m.counter_gaps, m.samples_missed) == (1, 1, 2)


def test_wrap_with_a_gap() -> None:
    m = DataStreamMonitor()
    m.update(65530, 0.0)
    m.update(3, 0.01)  # 65531..65535, 0..2 missed: 8 samples
    assert (m.counter_gaps, m.samples_missed) == (1, 8)


def test_rate_over_the_window() -> None:
    m = DataStreamMonitor(rate_window=1.0)
    for k in range(300):  # 100 Hz for 3 s
        m.update(k, k * 0.01)
    assert m.rate(2.995) == pytest.approx(100.0)  # samples in (1.995, 2.995]: 100
    assert m.rate(3.5) == pytest.approx(49.0)  # stopped at 2.99: samples 2.51..2.99 remain
    assert m.rate(10.0) == 0.0


def test_bad_window() -> None:
    with pytest.raises(ConfigError):
        DataStreamMonitor(rate_window=0.0)
