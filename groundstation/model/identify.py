"""Identification of the thrust polynomial (App. C.1) and induced inflow (App. C.2).

Used by ``gs identify thrust|inflow``. Fits return frozen records with a
human-readable :meth:`report`; bad data raises
:class:`groundstation.errors.IdentificationError` with a message naming the
file, row and column.

CSV formats (header row required, extra columns ignored, ``#`` lines skipped):

* thrust: ``u_thrust`` [RC units] and either ``force_n`` (body-z force [N],
  negative = up) or ``delta_m_kg`` (scale reading drop [kg], force = -delta_m g,
  the App. C.1 experiment). Repeated ``u_thrust`` values (several series) are fine.
* inflow: ``f_net_n`` (net vertical force ``F_lift + m g`` [N], Table C.2's first
  column - the thesis mislabels it ``F_lift``) and ``v3_mps`` (steady body-z
  velocity [m/s]). ``I_i = -f_net / v3`` per row; the constant is their mean (eq. C.6, C.8).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from groundstation.errors import IdentificationError
from groundstation.model.quadrotor import QuadrotorParams
from groundstation.model.thrust import THRUST_POLY_EQ37, ThrustMap
from groundstation.types import FloatArray

__all__ = [
    "InflowFit",
    "ThrustFit",
    "fit_induced_inflow",
    "fit_thrust_polynomial",
    "identify_inflow_csv",
    "identify_thrust_csv",
]

_U_SCALE = 1000.0  # fit in kilo-units so the Vandermonde matrix is well conditioned


@dataclass(frozen=True, slots=True)
class ThrustFit:
    """Least-squares cubic ``F_lift(u)`` fit.

    coeffs : (a3, a2, a1, a0) [N per unit^k]; n : number of points;
    rms_residual, max_residual : fit residuals [N]; u_range : (min, max) stick in the data.
    """

    coeffs: tuple[float, float, float, float]
    n: int
    rms_residual: float
    max_residual: float
    u_range: tuple[float, float]

    def thrust_map(self) -> ThrustMap:
        """The fitted polynomial as a :class:`ThrustMap`."""
        return ThrustMap(self.coeffs)

    def max_deviation(
        self,
        reference: tuple[float, float, float, float] = THRUST_POLY_EQ37,
        u_lo: float = 0.0,
        u_hi: float = 4000.0,
    ) -> float:
        """Largest ``|F_fit(u) - F_ref(u)|`` [N] over ``u_lo..u_hi`` (1-unit grid)."""
        u = np.arange(u_lo, u_hi + 1.0)
        return float(np.max(np.abs(np.polyval(self.coeffs, u) - np.polyval(reference, u))))

    def report(self) -> str:
        """Multi-line summary: coefficients, residuals, comparison with eq. 3.7."""
        a3, a2, a1, a0 = self.coeffs
        m = self.thrust_map()
        return "\n".join(
            [
                f"thrust polynomial fit, {self.n} points, u in "
                f"[{self.u_range[0]:.0f}, {self.u_range[1]:.0f}]",
                f"  a3 = {a3:.4e}   (eq. 3.7: {THRUST_POLY_EQ37[0]:.4e})",
                f"  a2 = {a2:.4e}   (eq. 3.7: {THRUST_POLY_EQ37[1]:.4e})",
                f"  a1 = {a1:.4e}   (eq. 3.7: {THRUST_POLY_EQ37[2]:.4e})",
                f"  a0 = {a0:.4e}   (eq. 3.7: {THRUST_POLY_EQ37[3]:.4e})",
                f"  residual rms {self.rms_residual:.4f} N, max {self.max_residual:.4f} N",
                f"  max |F_fit - F_eq3.7| over u 0..4000: {self.max_deviation():.4f} N",
                f"  monotonic up to u = {m.u_max:.1f}",
            ]
        )


@dataclass(frozen=True, slots=True)
class InflowFit:
    """Induced-inflow constant ``I_i`` [N s/m] (eq. 3.9): mean of per-row values.

    per_row : ``-f_net / v3`` for each measurement; variance : sample variance (ddof=1).
    """

    inflow: float
    variance: float
    per_row: tuple[float, ...]

    def report(self) -> str:
        """Multi-line summary with the per-row values."""
        rows = ", ".join(f"{x:.3f}" for x in self.per_row)
        return "\n".join(
            [
                f"induced inflow fit, {len(self.per_row)} steps",
                f"  I_i = {self.inflow:.4f} N s/m   (thesis eq. C.8: -0.423)",
                f"  variance {self.variance:.4f}   per step: {rows}",
            ]
        )


def fit_thrust_polynomial(u: FloatArray, force: FloatArray) -> ThrustFit:
    """Least-squares cubic through ``(u, force)`` (eq. C.3).

    u : (n,) thrust stick [RC units]; force : (n,) body-z force [N, negative = up].
    Needs at least 4 distinct stick values. Raises ``IdentificationError``.
    """
    uu = np.asarray(u, dtype=float).ravel()
    ff = np.asarray(force, dtype=float).ravel()
    if uu.shape != ff.shape:
        raise IdentificationError(f"u has {uu.size} values but force has {ff.size}")
    if not (np.all(np.isfinite(uu)) and np.all(np.isfinite(ff))):
        raise IdentificationError("thrust data contains non-finite values")
    if np.unique(uu).size < 4:
        raise IdentificationError(
            f"a cubic needs at least 4 distinct u_thrust values, got {np.unique(uu).size}"
        )
    s = uu / _U_SCALE
    V = np.vander(s, 4)
    c_scaled, *_ = np.linalg.lstsq(V, ff, rcond=None)
    coeffs = tuple(float(c) / _U_SCALE**k for c, k in zip(c_scaled, (3, 2, 1, 0), strict=True))
    resid = V @ c_scaled - ff
    return ThrustFit(
        coeffs=(coeffs[0], coeffs[1], coeffs[2], coeffs[3]),
        n=int(uu.size),
        rms_residual=float(np.sqrt(np.mean(resid**2))),
        max_residual=float(np.max(np.abs(resid))),
        u_range=(float(uu.min()), float(uu.max())),
    )


def fit_induced_inflow(f_net: FloatArray, v3: FloatArray) -> InflowFit:
    """``I_i`` from steady climbs (eq. C.6): mean over rows of ``-f_net / v3``.

    f_net : (n,) net vertical force ``F_lift + m g`` [N]; v3 : (n,) steady body-z
    velocity [m/s], non-zero. Raises ``IdentificationError``.
    """
    f = np.asarray(f_net, dtype=float).ravel()
    v = np.asarray(v3, dtype=float).ravel()
    if f.shape != v.shape or f.size == 0:
        raise IdentificationError(f"need equal, non-empty f_net and v3 (got {f.size}, {v.size})")
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(v))):
        raise IdentificationError("inflow data contains non-finite values")
    if np.any(np.abs(v) < 1e-3):
        raise IdentificationError("v3 must be non-zero (|v3| >= 1e-3 m/s) in every row")
    per_row = -f / v
    var = float(np.var(per_row, ddof=1)) if per_row.size > 1 else math.nan
    return InflowFit(float(np.mean(per_row)), var, tuple(float(x) for x in per_row))


def identify_thrust_csv(path: str | Path, g: float = QuadrotorParams().g) -> ThrustFit:
    """Fit the thrust polynomial to a CSV file (format in the module docstring).

    g : gravity [m/s^2] to turn ``delta_m_kg`` into force (default the vehicle model's,
        Ch. 3.4).
    """
    cols = _read_csv(Path(path), [("u_thrust",), ("force_n", "delta_m_kg")])
    force = cols["force_n"] if "force_n" in cols else -g * cols["delta_m_kg"]
    try:
        return fit_thrust_polynomial(cols["u_thrust"], force)
    except IdentificationError as exc:
        raise IdentificationError(f"{path}: {exc}") from exc


def identify_inflow_csv(path: str | Path) -> InflowFit:
    """Fit the induced-inflow constant to a CSV file with ``f_net_n`` and ``v3_mps``."""
    cols = _read_csv(Path(path), [("f_net_n",), ("v3_mps",)])
    try:
        return fit_induced_inflow(cols["f_net_n"], cols["v3_mps"])
    except IdentificationError as exc:
        raise IdentificationError(f"{path}: {exc}") from exc


def _read_csv(path: Path, groups: list[tuple[str, ...]]) -> dict[str, FloatArray]:
    """Read numeric columns: for each group, the first column name present is taken."""
    try:
        with path.open(newline="") as fh:
            lines = [ln for ln in fh if ln.strip() and not ln.lstrip().startswith("#")]
    except OSError as exc:
        raise IdentificationError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    reader = csv.DictReader(lines)
    header = [h.strip() for h in (reader.fieldnames or [])]
    reader.fieldnames = header
    chosen: list[str] = []
    for group in groups:
        name = next((c for c in group if c in header), None)
        if name is None:
            raise IdentificationError(
                f"{path}: missing column {' or '.join(group)!r} (header: {header})"
            )
        chosen.append(name)
    values: dict[str, list[float]] = {c: [] for c in chosen}
    for row_no, row in enumerate(reader, start=2):
        for c in chosen:
            try:
                values[c].append(float((row.get(c) or "").strip()))
            except ValueError:
                raise IdentificationError(
                    f"{path}: row {row_no}, column {c!r}: not a number: {row.get(c)!r}"
                ) from None
    if not values[chosen[0]]:
        raise IdentificationError(f"{path}: no data rows")
    return {c: np.array(v) for c, v in values.items()}
