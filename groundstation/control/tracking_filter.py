"""The steady-state alpha-beta filter: a value and its rate from noisy samples, in closed form.

A value ``d`` whose rate ``r`` is driven by white noise (the piecewise-constant white
acceleration model of target tracking), sampled every ``T`` with white noise of standard
deviation ``sigma``::

    d(k+1) = d(k) + T r(k) + T^2 / 2 w(k),    r(k+1) = r(k) + T w(k),    w ~ N(0, q)
    z(k)   = d(k) + v(k),                                                v ~ N(0, sigma^2)

has a steady-state Kalman filter whose gains depend only on the tracking index
``lambda = sqrt(q) T^2 / sigma`` (Kalata, "The tracking index: a generalized parameter for
alpha-beta and alpha-beta-gamma target trackers", IEEE Trans. AES 20(2), 1984)::

    r_ = (4 + lambda - sqrt(8 lambda + lambda^2)) / 4
    alpha = 1 - r_^2,    beta = 2 (2 - alpha) - 4 sqrt(1 - alpha)

and the filtered covariance ``P_dd = alpha sigma^2``, ``P_dr = beta sigma^2 / T``,
``P_rr = beta (2 alpha - beta) / (2 (1 - alpha)) sigma^2 / T^2``. White noise on a constant
leaves ``(2 alpha^2 + 2 beta - 3 alpha beta) / (alpha (4 - 2 alpha - beta)) sigma^2`` on the
value and ``2 beta^2 / (alpha (4 - 2 alpha - beta)) sigma^2 / T^2`` on the rate (the noise
gains: what a controller fed the estimate receives). One step is::

    predict  d_p = d + T r
    update   nu = z - d_p,   d = d_p + alpha nu,   r = r + (beta / T) nu

It follows a ramp without lag (a type-2 loop), which a first-order low-pass does not.
:func:`alpha_beta` gives the gains and the noise figures; the tests check them against
scipy's discrete Riccati solution and the bandwidth against the filter's frequency response.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from groundstation.errors import ControlError


@dataclass(frozen=True, slots=True)
class AlphaBeta:
    """A steady-state alpha-beta filter (see the module docstring).

    alpha, beta : the gains; period : T [s]; sigma : the sample noise it was designed for;
    value_sd, rate_sd : the Kalman filter's standard deviations of its value and rate
    errors under its own model [unit, unit/s]; innovation_sd : of ``nu``
    (``sqrt(P_pred + sigma^2)``); noise_sd, rate_noise_sd : what white noise ``sigma`` on
    a constant leaves on the value and the rate (the filter's noise gains, the sums of its
    impulse responses squared) [unit, unit/s]; bandwidth_rad_s : -3 dB frequency of the
    value's response [rad/s]
    """

    alpha: float
    beta: float
    period: float
    sigma: float
    value_sd: float
    rate_sd: float
    innovation_sd: float
    noise_sd: float
    rate_noise_sd: float
    bandwidth_rad_s: float


@functools.lru_cache(maxsize=64)  # a pure function whose bandwidth search costs ~10 ms
def alpha_beta(process_sd: float, sigma: float, period: float) -> AlphaBeta:
    """The steady-state filter for rate noise ``process_sd`` (``sqrt(q)`` [unit/s^2]),
    sample noise ``sigma`` [unit] and period ``period`` [s]; ControlError unless all > 0."""
    if not (process_sd > 0.0 and sigma > 0.0 and period > 0.0):
        raise ControlError(f"alpha-beta filter: need process_sd, sigma and period > 0, found "
                           f"{process_sd!r}, {sigma!r}, {period!r}")
    lam = process_sd * period * period / sigma
    r = (4.0 + lam - math.sqrt(8.0 * lam + lam * lam)) / 4.0
    alpha = 1.0 - r * r
    beta = 2.0 * (2.0 - alpha) - 4.0 * math.sqrt(1.0 - alpha)
    s2 = sigma * sigma
    rate_var = beta * (2.0 * alpha - beta) / (2.0 * (1.0 - alpha)) * s2 / (period * period)
    # predicted value variance: P_dd / (1 - alpha) (the update scales it by 1 - alpha)
    innovation = math.sqrt(alpha * s2 / (1.0 - alpha) + s2)
    # noise gains of the alpha-beta filter on white noise (Kalata 1984, eq. 30-31)
    d = alpha * (4.0 - 2.0 * alpha - beta)
    value_gain = (2.0 * alpha * alpha + 2.0 * beta - 3.0 * alpha * beta) / d
    rate_gain = 2.0 * beta * beta / (d * period * period)
    return AlphaBeta(alpha, beta, period, sigma, math.sqrt(alpha) * sigma,
                     math.sqrt(rate_var), innovation, math.sqrt(value_gain) * sigma,
                     math.sqrt(rate_gain) * sigma, _bandwidth(alpha, beta, period))


def frequency_response(alpha: float, beta: float, period: float,
                       omega: np.ndarray) -> np.ndarray:
    """The filtered value's response to the samples at ``omega`` [rad/s] (complex array):
    ``H(z) = z (alpha z + beta - alpha) / (z^2 + (alpha + beta - 2) z + 1 - alpha)``."""
    z = np.exp(1j * omega * period)
    out: np.ndarray = z * (alpha * z + beta - alpha) / (z * z + (alpha + beta - 2.0) * z
                                                         + 1.0 - alpha)
    return out


def _bandwidth(alpha: float, beta: float, period: float) -> float:
    """The lowest frequency [rad/s] where ``|H|`` falls to 1/sqrt(2) (bisection on a grid,
    then refined); Nyquist if it never does."""
    nyquist = math.pi / period
    grid = np.geomspace(1e-4 * nyquist, nyquist, 4000)
    below = np.flatnonzero(np.abs(frequency_response(alpha, beta, period, grid))
                           < math.sqrt(0.5))
    if below.size == 0:
        return nyquist
    hi = float(grid[below[0]])
    lo = float(grid[below[0] - 1]) if below[0] > 0 else 0.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if abs(frequency_response(alpha, beta, period, np.array([mid]))[0]) < math.sqrt(0.5):
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)
