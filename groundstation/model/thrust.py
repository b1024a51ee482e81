"""Thrust stick -> lift force map (eq. 3.7) and its identification (Appendix C).

Sign convention: ``F_lift`` is the rotor force along body z [N]; body z points
down, so lift is *negative*. ``F_lift(u) = a3 u^3 + a2 u^2 + a1 u + a0`` with the
thrust stick ``u`` in RC units 0..4096.

Eq. 3.7: ``a3 = 2.073e-10, a2 = -1.143e-6, a1 = -1.054e-3, a0 = -0.903``. (Appendix
C.1 prints ``a2 = -1.43e-6``, a typo: it misses Table C.1 by ~1 N at mid-stick.)
The polynomial is monotonic (more stick, more lift) from 0 up to where
``dF/du = 0``, at u = 4090.2 for eq. 3.7; :class:`ThrustMap` inverts it only there.

Identification (see :mod:`groundstation.model.identify` for the fits and CSV
readers that ``gs identify`` uses).
"""

from __future__ import annotations

import math

__all__ = ["STICK_MAX", "THRUST_POLY_EQ37", "ThrustMap"]

THRUST_POLY_EQ37: tuple[float, float, float, float] = (2.073e-10, -1.143e-6, -1.054e-3, -0.903)
"""(a3, a2, a1, a0) of eq. 3.7 [N per unit^k]."""

STICK_MAX = 4096
"""Largest thrust stick value the protocol accepts (RC units)."""


class ThrustMap:
    """Cubic map between thrust stick [RC units] and body-z lift force [N, negative = up].

    coeffs : (a3, a2, a1, a0), highest power first.
    stick_max : the largest stick value to consider (default 4096).

    ``valid_range`` is ``(0, u_max)`` where ``u_max`` is the first zero of ``dF/du``
    above 0 (or ``stick_max`` if that comes first); ``F`` must decrease on it.
    """

    def __init__(
        self,
        coeffs: tuple[float, float, float, float] = THRUST_POLY_EQ37,
        stick_max: float = STICK_MAX,
    ) -> None:
        if len(coeffs) != 4 or not all(math.isfinite(c) for c in coeffs):
            raise ValueError(f"coeffs must be four finite numbers (a3, a2, a1, a0), got {coeffs!r}")
        self.coeffs = tuple(float(c) for c in coeffs)
        a3, a2, a1, _ = self.coeffs
        if not a1 < 0.0:
            raise ValueError(f"dF/du at u=0 must be negative (more stick = more lift), a1={a1}")
        self.u_max = min(float(stick_max), _first_stationary_point(a3, a2, a1))
        self.f_at_zero = self.force(0.0)
        self.f_at_max = self.force(self.u_max)

    @property
    def valid_range(self) -> tuple[float, float]:
        """Monotonic stick range ``(0, u_max)`` [RC units]."""
        return 0.0, self.u_max

    @property
    def force_range(self) -> tuple[float, float]:
        """Reachable force ``(F(u_max), F(0))`` [N]: most lift first (most negative)."""
        return self.f_at_max, self.f_at_zero

    def force(self, u: float) -> float:
        """``F_lift(u)`` [N] at thrust stick ``u`` [RC units] (Horner, no clamping)."""
        a3, a2, a1, a0 = self.coeffs
        return ((a3 * u + a2) * u + a1) * u + a0

    def slope(self, u: float) -> float:
        """``dF_lift/du`` [N per unit]."""
        a3, a2, a1, _ = self.coeffs
        return (3.0 * a3 * u + 2.0 * a2) * u + a1

    def stick(self, f_lift: float) -> float:
        """Stick value [RC units, float] that produces ``f_lift`` [N].

        ``f_lift`` is clamped to :attr:`force_range`, so the result lies in
        :attr:`valid_range`. Safeguarded Newton iteration on the bracket.
        """
        if f_lift <= self.f_at_max:
            return self.u_max
        if f_lift >= self.f_at_zero:
            return 0.0
        f = f_lift
        lo, hi = 0.0, self.u_max  # F(lo) >= f >= F(hi)
        u = 0.5 * (lo + hi)
        for _ in range(60):
            r = self.force(u) - f
            if abs(r) < 1e-10:
                break
            if r > 0.0:
                lo = u
            else:
                hi = u
            d = self.slope(u)
            step = u - r / d if d < 0.0 else -1.0
            u = step if lo < step < hi else 0.5 * (lo + hi)
        return u

    def hover_stick(self, mass: float, g: float) -> float:
        """Stick that balances gravity, ``F_lift = -m g`` [RC units]."""
        return self.stick(-mass * g)


def _first_stationary_point(a3: float, a2: float, a1: float) -> float:
    """Smallest positive root of ``3 a3 u^2 + 2 a2 u + a1`` (``inf`` if none)."""
    qa, qb, qc = 3.0 * a3, 2.0 * a2, a1
    if qa == 0.0:
        return -qc / qb if qb != 0.0 and -qc / qb > 0.0 else math.inf
    disc = qb * qb - 4.0 * qa * qc
    if disc < 0.0:
        return math.inf
    s = math.sqrt(disc)
    roots = sorted(r for r in ((-qb - s) / (2 * qa), (-qb + s) / (2 * qa)) if r > 0.0)
    return roots[0] if roots else math.inf
