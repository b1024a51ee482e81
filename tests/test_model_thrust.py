"""Thrust map (eq. 3.7), its inverse, and identification from Tables C.1 and C.2."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from groundstation.errors import IdentificationError
from groundstation.model import (
    THRUST_POLY_EQ37,
    ThrustMap,
    fit_induced_inflow,
    fit_thrust_polynomial,
    identify_inflow_csv,
    identify_thrust_csv,
)

DATA = Path(__file__).parent / "data"


def _table(name: str) -> dict[str, np.ndarray]:
    """Read a tests/data CSV with the standard library (independent of the code under test)."""
    with (DATA / name).open() as fh:
        lines = [ln for ln in fh if not ln.startswith("#")]
    rows = list(csv.DictReader(lines))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
C1_PRINTED = (2.07e-10, -1.43e-6, -1.05e-3, -0.90)  # App. C.1's printed coefficients (typo)


def test_eq37_values_and_monotonic_range() -> None:
    m = ThrustMap()
    # hand evaluation of eq. 3.7 at u = 2000: 1.6584 - 4.572 - 2.108 - 0.903
    assert m.force(2000.0) == pytest.approx(-5.9246, abs=1e-4)
    assert m.force(0.0) == pytest.approx(-0.903)
    # dF/du = 3 a3 u^2 + 2 a2 u + a1 = 0, closed-form root
    a3, a2, a1, _ = THRUST_POLY_EQ37
    root = (-2 * a2 + math.sqrt(4 * a2**2 - 12 * a3 * a1)) / (6 * a3)
    assert m.u_max == pytest.approx(root) and m.u_max == pytest.approx(4090.2, abs=0.1)
    u = np.linspace(0.0, m.u_max, 500)
    assert np.all(np.diff(np.polyval(THRUST_POLY_EQ37, u)) < 0)  # more stick, more lift


def test_inverse_roundtrip_and_clamping() -> None:
    m = ThrustMap()
    for u in np.linspace(0.0, 4090.0, 97):
        assert m.stick(m.force(u)) == pytest.approx(u, abs=1e-4)
    assert m.stick(-100.0) == pytest.approx(m.u_max)  # more lift than possible -> u_max
    assert m.stick(+5.0) == 0.0  # downward force impossible -> idle
    assert m.hover_stick(0.60, 9.82) == pytest.approx(1989.6, abs=0.1)
    with pytest.raises(ValueError):
        ThrustMap((0.0, 0.0, 1e-3, 0.0))  # lift must grow with stick


def test_fit_table_c1_against_eq37() -> None:
    fit = identify_thrust_csv(DATA / "thrust_table_c1.csv")  # force = -delta_m * 9.82
    assert fit.n == 18
    a3, a2, a1, a0 = fit.coeffs
    e3, e2, e1, e0 = THRUST_POLY_EQ37
    assert a3 == pytest.approx(e3, rel=0.07)
    assert a2 == pytest.approx(e2, rel=0.03)  # and far from App. C.1's -1.43e-6
    assert a1 == pytest.approx(e1, rel=0.08)
    assert a0 == pytest.approx(e0, rel=0.02)
    # The brief asked for 0.1 N; the raw table cannot give it. The least-squares
    # cubic of Table C.1 (both series, g = 9.82) stays within 0.15 N of eq. 3.7
    # (worst at u ~ 2380). The two series themselves differ by up to 0.108 N and eq.
    # 3.7 has an rms residual of 0.128 N on the table (vs 0.091 N for the fit), so
    # eq. 3.7 was not a least-squares fit of these 18 points (probably of the
    # continuous scale log of Fig. C.2). No g in 9.3..9.9 brings it under 0.1 N.
    assert fit.max_deviation() < 0.16
    assert fit.rms_residual < 0.1
    assert "a2 = -1.1661e-06" in fit.report()


def test_table_c1_decides_the_a2_erratum() -> None:
    rows = _table("thrust_table_c1.csv")
    force = -rows["delta_m_kg"] * 9.82
    np.testing.assert_allclose(rows["initial_kg"] - rows["scale_kg"], rows["delta_m_kg"], atol=1e-9)

    def rms(c: tuple[float, ...]) -> float:
        return float(np.sqrt(np.mean((np.polyval(c, rows["u_thrust"]) - force) ** 2)))

    assert rms(THRUST_POLY_EQ37) < 0.15  # eq. 3.7 fits the table
    assert rms(C1_PRINTED) > 1.5  # App. C.1's a2 = -1.43e-6 misses it by ~2 N rms


def test_fit_recovers_exact_polynomial() -> None:
    u = np.linspace(0, 4000, 41)
    fit = fit_thrust_polynomial(u, np.polyval(THRUST_POLY_EQ37, u))
    np.testing.assert_allclose(fit.coeffs, THRUST_POLY_EQ37, rtol=1e-8)
    assert fit.max_deviation() < 1e-9


def test_inflow_table_c2() -> None:
    fit = identify_inflow_csv(DATA / "inflow_table_c2.csv")
    assert fit.inflow == pytest.approx(-0.423, abs=5e-4)  # eq. C.8
    assert fit.variance == pytest.approx(0.004, abs=5e-4)  # eq. C.8: sigma^2 = 0.004
    printed = _table("inflow_table_c2.csv")
    np.testing.assert_allclose(fit.per_row, printed["inflow_printed"], atol=6e-4)
    assert "-0.4230" in fit.report()


def test_fit_input_errors() -> None:
    with pytest.raises(IdentificationError, match="distinct"):
        fit_thrust_polynomial(np.array([0, 0, 1, 1.0]), np.zeros(4))
    with pytest.raises(IdentificationError):
        fit_thrust_polynomial(np.arange(5.0), np.array([0, 1, np.nan, 3, 4]))
    with pytest.raises(IdentificationError, match="non-zero"):
        fit_induced_inflow(np.array([-0.3]), np.array([0.0]))
    with pytest.raises(IdentificationError):
        fit_induced_inflow(np.array([-0.3, 1.0]), np.array([1.0]))


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("", "missing column"),
        ("u_thrust,weight\n0,1\n", "force_n"),
        ("u_thrust,force_n\n", "no data rows"),
        ("u_thrust,force_n\n0,-1\n500,abc\n", "row 3, column 'force_n'"),
        ("u_thrust,force_n\n0,-1\n500,-2\n", "at least 4 distinct"),
    ],
)
def test_bad_thrust_csv(tmp_path: Path, text: str, match: str) -> None:
    p = tmp_path / "t.csv"
    p.write_text(text)
    with pytest.raises(IdentificationError, match=match):
        identify_thrust_csv(p)


def test_bad_inflow_csv_and_missing_file(tmp_path: Path) -> None:
    p = tmp_path / "i.csv"
    p.write_text("f_net_n\n-0.4\n")
    with pytest.raises(IdentificationError, match="v3_mps"):
        identify_inflow_csv(p)
    with pytest.raises(IdentificationError, match="cannot read"):
        identify_inflow_csv(tmp_path / "nope.csv")
    q = tmp_path / "f.csv"
    rows = "".join(f"{u},{-1 - u / 1000}\n" for u in range(0, 4001, 500))
    q.write_text("u_thrust,force_n\n" + rows)
    assert identify_thrust_csv(q).coeffs[2] == pytest.approx(-1e-3)
