"""Timing histogram: percentiles within one bin of numpy's exact ones, constant memory."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.timing import TimingHistogram


@pytest.mark.parametrize("q", [50.0, 90.0, 99.0, 99.9])
def test_percentiles_match_numpy_within_a_bin(q: float) -> None:
    rng = np.random.default_rng(4)
    samples = rng.lognormal(mean=math.log(150e-6), sigma=0.6, size=20_000)
    hist = TimingHistogram()
    for s in samples:
        hist.add(float(s))
    exact = float(np.percentile(samples, q))
    assert hist.percentile(q) == pytest.approx(exact, rel=0.025)
    assert hist.max == samples.max() and hist.n == samples.size
    assert hist.mean == pytest.approx(samples.mean())


def test_memory_does_not_grow_and_bad_values_are_ignored() -> None:
    hist = TimingHistogram()
    size = hist.counts.nbytes
    for v in (0.0, 1e-9, 5e-3, 20.0, -1.0, math.nan):
        hist.add(v)
    assert hist.counts.nbytes == size and hist.n == 4
    assert hist.percentile(100.0) == 20.0  # overflow bin, capped at the exact maximum
    assert math.isnan(TimingHistogram().percentile(50.0))
