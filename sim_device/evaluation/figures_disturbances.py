"""Figures of the disturbance flights: a payload, wind, a gust, a sagging battery, ground effect,
Vicon lost.

One PNG per kind of disturbance, every controller on it (``lqr-ff`` drawn thick), the
targets as dashed red lines. Errors are the truth's distance from the reference [cm];
times are seconds from the disturbance (lab time ``Scenario.event_s``; a record's
``meta["lab_t0"]`` is the lab time at its clock's zero, 0 in-process) or, without one, from
the start of tracking. Under ``gs eval --perturb`` each record is its scenario's worst
flight and the legends name its seed.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from groundstation.evaluation.metrics import error_norms
from groundstation.evaluation.plotting import REF_STYLE, pyplot, save, since
from groundstation.evaluation.record import FlightRecord
from groundstation.flight.supervisor import State
from sim_device.evaluation.scenarios import DISTURBED, select

Records = Mapping[str, FlightRecord]
TAGS = tuple("hinf" if c == "hinf-rate-loop" else c for c in DISTURBED)
"""Scenario-name suffixes of the controllers, in :data:`DISTURBED` order."""
COLORS = {"lqr-ff": "C0", "lqr-cv": "C1", "lqr-cp": "C2", "pid": "C3", "hinf": "C4"}
TARGET_STYLE: dict[str, Any] = {"color": "C3", "ls": "--", "lw": 1.0}


def _label(name: str, r: FlightRecord) -> str:
    seed = r.meta.get("seed")
    return f"{name}" + (f" (seed {seed})" if seed is not None else "")


def _width(tag: str) -> float:
    return 2.0 if tag == "lqr-ff" else 1.0


def _from_event(name: str, r: FlightRecord) -> np.ndarray:
    """Tick times from the scenario's event [s] (lab time), or from tracking's start."""
    event = select([name])[0].event_s
    if event is None:
        return since(r)
    return np.asarray(r.t + float(r.meta.get("lab_t0", 0.0)) - event)


def _flown(r: FlightRecord) -> np.ndarray:
    return r.during(State.TRACK, State.HOLD)


def _error_panel(ax: Any, records: Records, kind: str, *, before: float, after: float,
                 target_cm: float | None, target: str = "") -> None:
    """|truth - reference| of every controller's ``<kind>-<tag>`` flight around its event."""
    for tag in TAGS:
        name = f"{kind}-{tag}"
        if name not in records:
            continue
        r = records[name]
        t = _from_event(name, r)
        w = _flown(r) & (t >= before) & (t <= after)
        ax.plot(t[w], 100.0 * error_norms(r.position[w], r.ref_pos[w]), color=COLORS[tag],
                lw=_width(tag), label=_label(tag, r))
    if target_cm is not None:
        ax.axhline(target_cm, label=target, **TARGET_STYLE)
    ax.set(ylabel="|truth - reference| [cm]", ylim=(0.0, None))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")


def _axes_panel(ax: Any, r: FlightRecord, name: str, *, before: float, after: float) -> None:
    """The truth's error per axis (lqr-ff's flight)."""
    t = _from_event(name, r)
    w = _flown(r) & (t >= before) & (t <= after)
    for k, axis in enumerate(("x north", "y east", "z down")):
        ax.plot(t[w], 100.0 * (r.position[w, k] - r.ref_pos[w, k]), lw=1.0, label=axis)
    ax.set(ylabel="truth - reference [cm]", title=f"{name}, per axis{_seed(r)}")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")


def _event_figure(records: Records, kind: str, path: Path, title: str, *,
                  target_cm: float, target: str, recovered_cm: float | None = None) -> list[Path]:
    names = [f"{kind}-{tag}" for tag in TAGS if f"{kind}-{tag}" in records]
    if not names:
        return []
    plt = pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 8), sharex=True)
    _error_panel(top, records, kind, before=-1.0, after=5.0, target_cm=target_cm,
                 target=target)
    if recovered_cm is not None:
        top.axhline(recovered_cm, color="0.4", ls=":", lw=1.0, label="1 cm")
    top.set(title=title)
    main = f"{kind}-lqr-ff"
    if main in records:
        _axes_panel(bottom, records[main], main, before=-1.0, after=5.0)
    bottom.set(xlabel="time from the disturbance [s]")
    return [save(fig, path)]


def payload_hover(records: Records, out: Path) -> list[Path]:
    """The +20 % payload in hover: every controller's error, lqr-ff's per axis."""
    return _event_figure(records, "payload-hover", out / "payload_hover.png",
                         "+20 % mass picked up in hover (Vicon 10 Hz)", target_cm=2.0,
                         target="target: peak 2 cm", recovered_cm=1.0)


def gust(records: Records, out: Path) -> list[Path]:
    """The 1 s, 4 m/s gust in hover."""
    return _event_figure(records, "gust-hover", out / "gust.png",
                         "A 1 s, 4 m/s gust from the south, in hover (drag on the airspeed)",
                         target_cm=2.0, target="target: peak 2 cm")


def payload_eight(records: Records, out: Path) -> list[Path]:
    """The payload mid-lap of the figure-eight: error of every controller around the step
    (the lap containing it), and lqr-ff's top view of that lap."""
    names = [f"payload-eight-{tag}" for tag in TAGS if f"payload-eight-{tag}" in records]
    if not names:
        return []
    plt = pyplot()
    fig, (err, top) = plt.subplots(1, 2, figsize=(14, 5.5),
                                   gridspec_kw={"width_ratios": [1.6, 1]})
    _error_panel(err, records, "payload-eight", before=-4.0, after=8.0, target_cm=None)
    err.set(xlabel="time from the step [s]", yscale="log", ylim=(0.05, None),
            title="+20 % mass picked up mid-lap of the 8 s figure-eight")
    main = "payload-eight-lqr-ff"
    if main in records:
        r = records[main]
        t = _from_event(main, r)
        lap = _flown(r) & (t >= -4.0) & (t <= 4.0)
        top.plot(r.ref_pos[lap, 1], r.ref_pos[lap, 0], **REF_STYLE)
        top.plot(r.position[lap, 1], r.position[lap, 0], color="C0", lw=1.3, label="lqr-ff")
        at = np.flatnonzero(lap & (t >= 0.0))
        if at.size:
            top.plot(r.position[at[0], 1], r.position[at[0], 0], "o", color="C3",
                     label="payload picked up")
        top.set(xlabel="y east [m]", ylabel="x north [m]",
                title=f"lqr-ff, 4 s either side of the step{_seed(r)}")
        top.set_aspect("equal", adjustable="datalim")
        top.grid(True, alpha=0.3)
        top.legend(fontsize=8)
    return [save(fig, out / "payload_eight.png")]


def _seed(r: FlightRecord) -> str:
    seed = r.meta.get("seed")
    return f", seed {seed}" if seed is not None else ""


def _whole_flight(records: Records, kind: str, path: Path, title: str,
                  target_cm: float | None, target: str = "") -> list[Path]:
    """The error over tracking for every controller (steady disturbances)."""
    names = [f"{kind}-{tag}" for tag in TAGS if f"{kind}-{tag}" in records]
    if not names:
        return []
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 5))
    for tag in TAGS:
        name = f"{kind}-{tag}"
        if name not in records:
            continue
        r = records[name]
        tr = r.during(State.TRACK)
        ax.plot(since(r)[tr], 100.0 * error_norms(r.position[tr], r.ref_pos[tr]),
                color=COLORS[tag], lw=_width(tag), label=_label(tag, r))
    if target_cm is not None:
        ax.axhline(target_cm, label=target, **TARGET_STYLE)
    ax.set(xlabel="time since tracking started [s]", ylabel="|truth - reference| [cm]",
           title=title, yscale="log")
    ax.grid(True, alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="upper right")
    return [save(fig, path)]


def wind(records: Records, out: Path) -> list[Path]:
    """Hover in a steady 3 m/s wind, every controller."""
    return _whole_flight(records, "wind-hover", out / "wind_steady.png",
                         "Hover in a steady 3 m/s wind from the south (drag on the airspeed)",
                         0.5, "target: 0.5 cm RMS (lqr-ff)")


def battery(records: Records, out: Path) -> list[Path]:
    """Hover while the battery loses 10 % of the lift in a minute."""
    return _whole_flight(records, "battery-sag", out / "battery_sag.png",
                         "Hover while the battery loses 10 % of the lift over a minute", None)


def ground_effect(records: Records, out: Path) -> list[Path]:
    """Height against the reference at take-off and landing, in ground effect."""
    names = [f"ground-effect-{tag}" for tag in TAGS if f"ground-effect-{tag}" in records]
    if not names:
        return []
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(13, 5), sharey=True)
    for ax, state, what in ((axes[0], State.TAKEOFF, "take-off"), (axes[1], State.LAND,
                                                                   "landing")):
        for tag in TAGS:
            name = f"ground-effect-{tag}"
            if name not in records:
                continue
            r = records[name]
            phase = r.during(state)
            if not phase.any():
                continue
            t = r.t[phase] - r.t[phase][0]
            ax.plot(t, -100.0 * r.position[phase, 2], color=COLORS[tag], lw=_width(tag),
                    label=_label(tag, r))
            if tag == "lqr-ff":
                ax.plot(t, -100.0 * r.ref_pos[phase, 2], **REF_STYLE)
        ax.set(xlabel=f"time since the {what} began [s]", title=f"{what} in ground effect")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set(ylabel="height above the floor [cm]")
    return [save(fig, out / "ground_effect.png")]


def vicon_loss(records: Records, out: Path) -> list[Path]:
    """Vicon lost for 1 s and 2 s in hover and mid-eight (lqr-ff): the estimate's distance
    from the truth (what dead reckoning let it drift) and the truth's from the reference."""
    names = [n for n in ("outage-1s-hover", "outage-2s-hover", "outage-1s-eight",
                         "outage-2s-eight") if n in records]
    if not names:
        return []
    plt = pyplot()
    fig, axes = plt.subplots(2, len(names), figsize=(4.5 * len(names), 7.5), sharex=True,
                             squeeze=False)
    for k, name in enumerate(names):
        r = records[name]
        s = select([name])[0]
        t = _from_event(name, r)
        w = (t >= -1.0) & (t <= (s.outage_s or 1.0) + 3.0) & r.during(
            State.TRACK, State.HOLD, State.LAND)
        est, err = axes[0][k], axes[1][k]
        ok = w & np.all(np.isfinite(r.est_pos), axis=1)
        est.plot(t[ok], 100.0 * error_norms(r.est_pos[ok], r.position[ok]), color="C1",
                 lw=1.2, label="|estimate - truth|")
        est.axhline(1.0, label="target: 1 cm (1 s, hover)", **TARGET_STYLE)
        err.plot(t[w], 100.0 * error_norms(r.position[w], r.ref_pos[w]), color="C0", lw=1.2,
                 label="|truth - reference|")
        for ax in (est, err):
            ax.axvspan(0.0, s.outage_s or 0.0, color="0.85", label="no Vicon")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7, loc="upper left")
        est.set(title=f"{name}{_seed(r)}", ylabel="estimate error [cm]", ylim=(0.0, None))
        err.set(xlabel="time from the loss [s]", ylabel="tracking error [cm]",
                ylim=(0.0, None))
    fig.suptitle("Vicon lost: dead reckoning on the IMU (lqr-ff; the reference holds where "
                 "HOLD began)")
    return [save(fig, out / "vicon_loss.png")]


def disturbance_figures(records: Records, out: Path) -> list[Path]:
    """Every figure of this module whose flights are present."""
    makers: list[Callable[[], list[Path]]] = [
        lambda: payload_hover(records, out), lambda: payload_eight(records, out),
        lambda: wind(records, out), lambda: gust(records, out),
        lambda: battery(records, out), lambda: ground_effect(records, out),
        lambda: vicon_loss(records, out)]
    paths: list[Path] = []
    for make in makers:
        paths += make()
    return paths


CAPTIONS: dict[str, str] = {
    "payload_hover.png": "+20 % mass picked up in hover: every controller's distance from "
                         "the reference around the step, and lqr-ff's error per axis.",
    "payload_eight.png": "+20 % mass picked up mid-lap of the 8 s figure-eight: every "
                         "controller's error, and lqr-ff's lap around the step.",
    "wind_steady.png": "Hover in a steady 3 m/s wind (drag on the airspeed): every "
                       "controller's error over tracking.",
    "gust.png": "A 1 s, 4 m/s gust in hover: every controller's error, lqr-ff's per axis.",
    "battery_sag.png": "Hover while the battery loses 10 % of the lift over a minute.",
    "ground_effect.png": "Take-off and landing in ground effect: height against the reference.",
    "vicon_loss.png": "Vicon lost for 1 s and 2 s in hover and mid-eight (lqr-ff): the "
                      "estimate's drift from the truth, and the truth's from the reference.",
}
"""Report captions by file name."""
