"""Constant-memory timing statistics for the real-time loop.

A 30-minute flight has 180,000 ticks; keeping every sample would grow the
daemon's memory for the whole flight. :class:`TimingHistogram` keeps a fixed
set of logarithmic bins instead (1 us to 10 s, 2 % wide), so percentiles are
exact to within one bin and memory never grows. The exact maximum is kept too.
"""

from __future__ import annotations

import math

import numpy as np

_LO = 1e-6
_HI = 10.0
_RATIO = 1.02
_BINS = math.ceil(math.log(_HI / _LO) / math.log(_RATIO)) + 1
_LOG_LO = math.log(_LO)
_INV_LOG_RATIO = 1.0 / math.log(_RATIO)


class TimingHistogram:
    """Histogram of non-negative durations [s] with percentiles to within 2 %."""

    def __init__(self) -> None:
        self.counts = np.zeros(_BINS + 1, dtype=np.int64)  # last bin: above _HI
        self.n = 0
        self.max = 0.0
        self.total = 0.0

    def add(self, value: float) -> None:
        """Record one duration [s]; negative or NaN values are ignored."""
        if not value >= 0.0:
            return
        self.n += 1
        self.total += value
        if value > self.max:
            self.max = value
        if value <= _LO:
            index = 0
        else:
            index = min(int((math.log(value) - _LOG_LO) * _INV_LOG_RATIO) + 1, _BINS)
        self.counts[index] += 1

    def percentile(self, q: float) -> float:
        """The q-th percentile [s] (upper edge of its bin, capped at the maximum); NaN if empty."""
        if self.n == 0:
            return math.nan
        rank = q / 100.0 * self.n
        index = int(np.searchsorted(np.cumsum(self.counts), max(rank, 1.0)))
        if index >= _BINS:  # above the top edge: only the exact maximum is known
            return self.max
        return min(_LO * _RATIO**index, self.max)

    @property
    def mean(self) -> float:
        """Mean duration [s] (NaN if empty)."""
        return self.total / self.n if self.n else math.nan
