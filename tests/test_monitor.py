"""``gs monitor``: the pure view (fixed size whatever the payloads hold, units, attitude
against scipy, the final state), the plain status line, and the live loop over real
ZeroMQ sockets on tcp://127.0.0.1: redraw in place on a terminal, no escape codes
elsewhere, return at the flight's final message, Ctrl-C."""

from __future__ import annotations

import io
import math
import re
import signal
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from groundstation.cli import app
from groundstation.telemetry import (
    TelemetryPublisher,
    health_payload,
    render,
    run_monitor,
    state_payload,
)
from groundstation.telemetry.monitor import HEIGHT, WIDTH, status_line
from groundstation.types import Reference, StateEstimate, Sticks

ANY_PORT = "tcp://127.0.0.1:*"
ATTITUDE = Rotation.from_euler("ZYX", [135.0, -20.0, 10.0], degrees=True)  # yaw, pitch, roll
EST = StateEstimate(
    5.0, np.array([0.1, -0.2, -0.95]), np.roll(ATTITUDE.as_quat(), 1),  # scalar first
    np.array([0.3, 0.0, -0.1]), np.array([0.1, -0.2, 0.05]), np.array([0.01, -0.02, 0.005]),
    np.array([0.05, -0.05, 0.1]), np.full(16, 1e-4),
)
REF = Reference(2.0, np.array([0.5, 0.0, -1.0]), np.array([0.2, 0.0, 0.0]), yaw=0.1)
VEHICLE = {"battery_v": 11.784, "serial_active": True, "motors_on": True, "rc_valid": True,
           "applied_mask": 0b1111, "pilot_enabled": True}
FINAL = {"final": True, "outcome": "COMPLETED", "reason": "trajectory complete",
         "supervisor": {"state": 6, "name": "DONE"}}
"""What the daemon adds to its last ``state`` message."""


def state(**extra: Any) -> dict[str, Any]:
    """A TRACK ``state`` body 83.44 s into the flight, with ``extra`` keys."""
    body = state_payload(state=2, state_name="TRACK", estimate=EST, reference=REF,
                         sticks=Sticks(roll=-12, pitch=30, yaw=0, thrust=2010),
                         ctrl_mask=0b1111, sent=True, vehicle=VEHICLE)
    return {**body, "flight_time_s": 83.44, **extra}


def health() -> dict[str, Any]:
    return {**health_payload(
        link={"rate_hz": 99.5, "rejected": {"crc": 2, "length": 1}, "time_since_data_s": 0.01},
        vicon={"rate_hz": 100.0, "rejected": {}, "time_since_pose_s": None,
               "rivals": 1, "rival_events": 2, "rival_poses": 246, "outside": 0},
        estimator={"t": 5.0, "initialised": True, "updates": 1234, "last_nis": 2.31,
                   "time_since_fix": 0.012, "gated": 4, "resets": 0},
        loop={"ticks": 8344, "compute_time_s": 0.0011}),
        "telemetry": {"sent": 3336, "dropped": 2, "errors": 0}}


def line(lines: list[str], label: str) -> str:
    """The view's line with this label."""
    return next(text for text in lines if text.startswith(label))


def test_render_shows_the_view() -> None:
    lines = render(state(schema=1), health(), endpoint="tcp://x:1", received=7, age_s=0.05)
    assert lines[0] == "gs monitor  last 0.05 s ago              7 msgs  tcp://x:1"
    assert line(lines, "state") == "state     TRACK                   flight 01:23.4"
    assert line(lines, "position") == (
        "position  x  +0.100  y  -0.200  z  -0.950 m    (estimate, NED)")
    assert line(lines, "reference").endswith("z  -1.000 m    yaw   +5.7 deg")  # 0.1 rad
    # reference - estimate = (0.4, 0.2, -0.05) m, |e| = 0.450 m, shown in cm
    assert line(lines, "error") == (
        "error     x   +40.0  y   +20.0  z    -5.0 cm   |e|   45.0 cm")
    assert line(lines, "velocity").startswith("velocity  x  +0.300  y  +0.000  z  -0.100 m/s")
    assert line(lines, "attitude") == "attitude  roll  +10.0  pitch  -20.0  yaw +135.0 deg"
    # (0.1, -0.2, 0.05) rad/s in deg/s
    assert line(lines, "rates") == "rates     p    +5.7  q   -11.5  r    +2.9 deg/s"
    assert line(lines, "command") == (
        "command   pitch   +30  roll   -12  yaw    +0  thrust 2010 RC  mask 1111 sent")
    assert line(lines, "vehicle") == (
        "vehicle   battery 11.78 V  applies 1111  motors on  RC ok  switch on")
    assert line(lines, "link") == (
        "link        99.5 Hz  last  0.01 s  rejected 3 (crc 2, length 1)")
    assert line(lines, "vicon") == "vicon      100.0 Hz  last    -- s  rejected 0"
    assert line(lines, "streams") == (
        "streams   RIVAL STREAM x1  rival episodes 2  rival poses 246  outside 0")
    # zero counters and the filter time are left out
    assert line(lines, "estimator") == "estimator updates 1234  NIS   2.3  fix  0.01 s  gated 4"
    assert line(lines, "loop") == "loop      ticks 8344  compute_time 0.0011 s"
    assert line(lines, "telemetry") == "telemetry sent 3336  dropped 2  errors 0"
    assert len(lines) == HEIGHT


def test_render_marks_missing_stale_and_handed_back() -> None:
    handed = render(state(vehicle={**VEHICLE, "serial_active": False, "applied_mask": 0,
                                   "pilot_enabled": False}), health())
    assert line(handed, "vehicle").endswith("applies none (pilot)  motors on  RC ok  switch OFF")
    older = state()
    del older["flight_time_s"]  # a stream from before flight_time_s
    assert line(render(older, health()), "state").endswith("flight --:--.-")
    waiting = render(None, None)
    assert "waiting for telemetry" in waiting[0] and len(waiting) == HEIGHT
    assert line(waiting, "streams") == "streams   --"
    one = health()
    one["vicon"] = {**one["vicon"], "rivals": 0, "rival_events": 0, "rival_poses": 0,
                    "outside": 12}
    assert line(render(state(), one), "streams") == (
        "streams   one sender  rival episodes 0  rival poses 0  outside 12")
    assert line(waiting, "position") == (
        "position  x      --  y      --  z      -- m    (estimate, NED)")
    assert "NO DATA for 3.0 s" in render(state(), health(), age_s=3.0)[0]
    assert "NO DATA for 3600.0 s" in render(state(), health(), age_s=3600.0)[0]
    assert "[schema 2, expected 1]" in line(render(state(schema=2), None), "state")
    too_long_to_print = 10**5000  # str() refuses it; hypothesis cannot show it either
    absurd = render({"schema": too_long_to_print, "flight_time_s": too_long_to_print},
                    {"loop": {"ticks": too_long_to_print}}, received=too_long_to_print)
    assert line(absurd, "state").endswith("flight ###:##.#  [schema ?, expected 1]")
    assert line(absurd, "loop") == "loop      ticks inf" and absurd[0].endswith("inf msgs")


def test_render_shows_the_final_state() -> None:
    lines = render(state(**FINAL, flight_time_s=95.03), health(), received=9, age_s=5.0)
    assert "FLIGHT ENDED" in lines[0]  # not "NO DATA": the flight has ended
    assert line(lines, "state") == (
        "state     DONE (COMPLETED)        flight 01:35.0  trajectory complete")
    lost = {**FINAL, "supervisor": {"state": 9, "name": "LINK_LOST"}, "outcome": "FAILSAFE"}
    assert "LINK_LOST (FAILSAFE)" in line(render(state(**lost), health()), "state")
    no_outcome = {"final": True, "supervisor": {"state": 6, "name": "DONE"}}
    assert "DONE (final)" in line(render(state(**no_outcome), health()), "state")


def test_status_line() -> None:
    assert status_line(state(), health(), age_s=0.1) == (
        "TRACK      t 01:23.4  |e|  45.0 cm  11.78 V  link   99.5 Hz  vicon  100.0 Hz")
    assert status_line(state(), health(), age_s=3.0) == (
        "NO DATA for 3.0 s  last: TRACK  t 01:23.4  |e|  45.0 cm  11.78 V")
    assert status_line(state(**FINAL), health(), age_s=0.1) == (
        "ENDED  DONE (COMPLETED)  t 01:23.4  11.78 V  trajectory complete")
    assert status_line(None, None, received=0) == "waiting for telemetry (0 messages)"


def quaternion_line(q: list[float]) -> list[float]:
    """roll, pitch, yaw [deg] as the view shows them for the scalar-first ``q``."""
    text = line(render({"estimate": {"quaternion": q}}, None), "attitude")
    match = re.fullmatch(r"attitude  roll (.{6})  pitch (.{6})  yaw (.{6}) deg", text)
    assert match is not None, text
    return [float(v) for v in match.groups()]


unit = st.floats(-1.0, 1.0, allow_nan=False)


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:Gimbal lock")  # such cases are skipped below
@given(st.lists(unit, min_size=4, max_size=4), st.floats(1e-3, 1e3))
def test_attitude_matches_scipy(q: list[float], scale: float) -> None:
    norm = float(np.linalg.norm(q))
    assume(norm > 1e-3)
    yaw, pitch, roll = Rotation.from_quat([*q[1:], q[0]]).as_euler("ZYX", degrees=True)
    assume(abs(pitch) < 89.0)  # at gimbal lock the roll/yaw split is arbitrary
    shown = quaternion_line([scale * c for c in q])  # the view normalises the quaternion
    for got, want in zip(shown, (roll, pitch, yaw), strict=True):
        wrapped = (got - want + 180.0) % 360.0 - 180.0  # +180.0 and -180.0 are one angle
        assert abs(wrapped) <= 0.05 + 1e-6


def test_attitude_of_extreme_or_no_quaternion() -> None:
    for bad in ([0, 0, 0, 0], [1, 0, 0], [1, 0, 0, math.nan], [1, 0, 0, 10**400], None, "wxyz"):
        text = line(render({"estimate": {"quaternion": bad}}, None), "attitude")
        assert text == "attitude  roll     --  pitch     --  yaw     -- deg"
    assert quaternion_line([1e308, 1e308, 0, 0]) == [90.0, 0.0, 0.0]  # no overflow
    assert quaternion_line([1e-200, 0, 0, 1e-200]) == [0.0, 0.0, 90.0]  # no underflow


# -- adversarial payloads: fixed size, bounded width, nothing unprintable -----------

huge = st.sampled_from([10**400, -(10**4000), 2**64, 1e308, -1e308, 5e-324, 1e22])
number = st.one_of(st.none(), st.booleans(), st.integers(), huge,
                   st.floats(allow_nan=True, allow_infinity=True))
text = st.text(max_size=120)  # any code point: escapes, newlines, wide characters
junk = st.recursive(st.one_of(number, text),
                    lambda inner: st.lists(inner, max_size=5)
                    | st.dictionaries(st.one_of(text, st.integers()), inner, max_size=5),
                    max_leaves=12)


def vec(n: int) -> st.SearchStrategy[Any]:
    return st.one_of(junk, st.lists(number, min_size=n, max_size=n))


def section(**fields: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    """A mapping with these fields, any subset of them junk or missing, or junk itself."""
    return st.one_of(junk, st.fixed_dictionaries({}, optional={
        key: st.one_of(strategy, junk) for key, strategy in fields.items()}))


counts = st.dictionaries(text, number, max_size=8)
states = section(
    schema=number, supervisor=section(state=number, name=text), flight_time_s=number,
    final=st.booleans(), outcome=text, reason=text,
    estimate=section(position=vec(3), quaternion=vec(4), velocity_body=vec(3), omega=vec(3)),
    reference=section(position=vec(3), yaw=number), error=section(position=vec(3),
                                                                  distance=number),
    command=section(pitch=number, roll=number, yaw=number, thrust=number, mask=number,
                    sent=number),
    vehicle=section(battery_v=number, serial_active=number, motors_on=number, rc_valid=number,
                    applied_mask=number, pilot_enabled=number))
healths = section(
    schema=number,
    link=section(rate_hz=number, rejected=st.one_of(counts, number), time_since_data_s=number),
    vicon=section(rate_hz=number, rejected=counts, time_since_pose_s=number, rivals=number,
                  rival_events=number, rival_poses=number, outside=number),
    estimator=st.one_of(section(initialised=number, diverged=number, updates=number,
                                last_nis=number, time_since_fix=number), counts),
    loop=counts, telemetry=section(sent=number, dropped=number, errors=number))


def well_formed(lines: list[str], width: int = WIDTH) -> None:
    for text_line in lines:
        assert len(text_line) <= width, text_line
        assert all(" " <= c <= "~" for c in text_line), repr(text_line)


@pytest.mark.slow
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(states, healths, text, st.one_of(st.integers(), huge),
       st.one_of(st.none(), st.floats(allow_nan=True, allow_infinity=True)))
def test_any_payload_renders_in_fixed_size(
    state_body: Any, health_body: Any, endpoint: str, received: int, age_s: float | None,
) -> None:
    lines = render(state_body, health_body, endpoint=endpoint, received=received, age_s=age_s)
    assert len(lines) == HEIGHT
    well_formed(lines)
    well_formed([status_line(state_body, health_body, received=received, age_s=age_s)])
    narrow = render(state_body, health_body, endpoint=endpoint, width=40)
    assert len(narrow) == HEIGHT
    well_formed(narrow, 40)


# -- the live loop -------------------------------------------------------------------


Feed = Callable[..., None]


@pytest.fixture
def pub() -> Iterator[TelemetryPublisher]:
    with TelemetryPublisher(ANY_PORT, rate_hz=20.0) as publisher:
        yield publisher


@pytest.fixture
def feed(pub: TelemetryPublisher) -> Iterator[Feed]:
    """``feed(until, final=True)``: from a thread, publish a state and a health every
    10 ms until ``until()``, then (``final``) the flight's final state and health once,
    as the daemon does. Stopped and joined at teardown."""
    stop = threading.Event()
    threads: list[threading.Thread] = []

    def run(until: Callable[[], bool], final: bool) -> None:
        k = 0
        while not stop.is_set():
            if until():
                if final:
                    pub.publish("state", state(**FINAL), t=k * 0.01)
                    pub.publish("health", health(), t=k * 0.01)
                return
            pub.publish("state", state(), t=k * 0.01)
            pub.publish("health", health(), t=k * 0.01)
            k += 1
            stop.wait(0.01)

    def start(until: Callable[[], bool], final: bool = True) -> None:
        threads.append(threading.Thread(target=run, args=(until, final),
                                        name="telemetry-feed"))
        threads[-1].start()

    yield start
    stop.set()
    for thread in threads:
        thread.join()


@pytest.mark.slow
def test_run_monitor_redraws_in_place(
    pub: TelemetryPublisher, feed: Feed,
) -> None:
    feed(lambda: False)
    out = io.StringIO()
    received = run_monitor(pub.endpoint or "", duration=1.5, out=out, refresh_s=0.1, tty=True)
    text = out.getvalue()
    assert received > 0 and "TRACK" in text
    frames = text.count("gs monitor  ")
    assert frames >= 2 and text.count(f"\x1b[{HEIGHT}F") == frames - 1  # up over the view
    assert text.count("\n") == frames * HEIGHT  # every frame the same size
    well_formed(re.sub(r"\x1b\[\d*[A-Za-z]", "", text).splitlines())


@pytest.mark.slow
def test_piped_output_is_plain_status_lines(
    pub: TelemetryPublisher, feed: Feed,
) -> None:
    feed(lambda: False)
    out = io.StringIO()  # no terminal
    assert run_monitor(pub.endpoint or "", duration=1.0, out=out, refresh_s=0.2) > 0
    lines = out.getvalue().splitlines()
    assert "\x1b" not in out.getvalue()
    assert 3 <= len(lines) <= 6 and lines[-1].startswith("TRACK      t 01:23.4  |e|  45.0 cm")
    well_formed(lines)


@pytest.mark.parametrize("tty", [False, True])
def test_run_monitor_returns_at_the_final_state(
    pub: TelemetryPublisher, feed: Feed, tty: bool,
) -> None:
    out = io.StringIO()
    feed(lambda: "TRACK" in out.getvalue())  # the final state once the monitor shows data
    start = time.monotonic()
    received = run_monitor(pub.endpoint or "", duration=60.0, out=out, refresh_s=0.05,
                           tty=tty)
    assert time.monotonic() - start < 20.0 and received >= 2
    text = out.getvalue()
    if tty:
        last = text.split(f"\x1b[{HEIGHT}F")[-1].replace("\x1b[2K", "").splitlines()
        assert "FLIGHT ENDED" in last[0] and last[1].startswith("state     DONE (COMPLETED)")
    else:
        assert "\x1b" not in text
        assert text.splitlines()[-1] == (
            "ENDED  DONE (COMPLETED)  t 01:23.4  11.78 V  trajectory complete")


def test_cli_monitor_exits_0_at_the_final_state(
    pub: TelemetryPublisher, feed: Feed,
) -> None:
    shown = time.monotonic() + 0.5
    feed(lambda: time.monotonic() > shown)
    start = time.monotonic()
    result = CliRunner().invoke(app, ["monitor", "--endpoint", pub.endpoint or "",
                                      "--duration", "60"])
    assert result.exit_code == 0, result.output
    assert time.monotonic() - start < 20.0
    assert result.output.splitlines()[-1].startswith("ENDED  DONE (COMPLETED)")


@pytest.mark.slow
def test_no_messages_keeps_showing_stale(pub: TelemetryPublisher, feed: Feed) -> None:
    out = io.StringIO()
    feed(lambda: "TRACK" in out.getvalue(), final=False)  # then silence, no final state
    run_monitor(pub.endpoint or "", duration=2.5, out=out, refresh_s=0.1)
    lines = out.getvalue().splitlines()
    assert any(text.startswith("TRACK") for text in lines)
    assert lines[-1].startswith("NO DATA for ") and "last: TRACK  t 01:23.4" in lines[-1]


_MONITOR = textwrap.dedent("""
    import sys
    from groundstation.telemetry import run_monitor
    print("received", run_monitor(sys.argv[1], refresh_s=0.05), flush=True)
""")


@pytest.mark.slow
def test_monitor_stops_cleanly_on_ctrl_c(pub: TelemetryPublisher) -> None:
    proc = subprocess.Popen([sys.executable, "-c", _MONITOR, pub.endpoint or ""],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        for _ in range(3):  # wait until it is running: a pipe gets one line per interval
            assert proc.stdout.readline() == "waiting for telemetry (0 messages)\n"
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0
    assert out.splitlines()[-1] == "received 0" and "\x1b" not in out
