"""The Python client speaks degrees, as every other place a user gives a heading (the
configuration's `trajectory.yaw_deg`, `gs goto --yaw`, a waypoint CSV's `yaw_deg`), while
the wire stays in radians: checked against a real request socket (pyzmq REP) whose
handler records what arrives and answers as the daemon's wire format does."""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator
from typing import Any

import pytest
from typer.testing import CliRunner

from groundstation.cli import app
from groundstation.client import BadRequest, Client
from groundstation.telemetry.requests import RequestServer

MOTION = {"id": 4, "kind": "go_to", "state": "moving", "reason": "", "target": [0.5, 0, -1],
          "target_yaw": -math.pi / 2, "duration_s": 2.0, "latency_s": None}
STATUS = {"ok": True, "state": "TRACK", "reason": "", "commanded": True,
          "estimate": {"position": [0.1, 0.2, -1.0], "velocity": [0, 0, 0], "yaw": math.pi},
          "reference": {"position": [0.0, 0.0, -1.0], "yaw": 3 * math.pi / 4},
          "ground": [0, 0, 0], "motion": MOTION, "health": {"battery_v": 11.1}}
"""Replies as the daemon's wire format (:mod:`groundstation.app.api`) writes them: rad."""


@pytest.fixture
def daemon() -> Iterator[tuple[str, list[dict[str, Any]]]]:
    """(endpoint, the requests received) of a request socket answering like a daemon."""
    seen: list[dict[str, Any]] = []

    def handler(request: dict[str, Any]) -> dict[str, Any]:
        seen.append(request)
        if request["request"] == "status":
            return STATUS
        return {"ok": True, "motion": MOTION}

    with RequestServer("tcp://127.0.0.1:*") as server:
        assert server.endpoint is not None
        stop = threading.Event()

        def serve() -> None:
            while not stop.wait(0.001):
                server.poll(handler)

        thread = threading.Thread(target=serve, daemon=True)
        thread.start()
        try:
            yield server.endpoint, seen
        finally:
            stop.set()
            thread.join(5.0)


def test_go_to_takes_degrees_and_sends_radians(daemon: tuple[str, list[dict[str, Any]]]
                                               ) -> None:
    endpoint, seen = daemon
    motion = Client(endpoint, timeout_s=5.0).go_to([0.5, 0.0, -1.0], yaw_deg=90.0)
    assert seen[-1]["yaw"] == pytest.approx(math.pi / 2)  # east, on the wire in radians
    assert motion.target_yaw_deg == pytest.approx(-90.0)  # reported back in degrees
    Client(endpoint).go_to([0.5, 0.0, -1.0])
    assert seen[-1]["yaw"] is None  # keep the heading


def test_status_reports_degrees(daemon: tuple[str, list[dict[str, Any]]]) -> None:
    status = Client(daemon[0], timeout_s=5.0).status()
    assert status.yaw_deg == pytest.approx(180.0)
    assert status.reference_yaw_deg == pytest.approx(135.0)
    assert status.motion is not None and status.motion.target_yaw_deg == pytest.approx(-90.0)
    assert status.raw["estimate"]["yaw"] == pytest.approx(math.pi)  # the wire, unchanged


def test_the_radian_spellings_still_work_with_a_warning(daemon: tuple[str, list[dict[str, Any]]]
                                                        ) -> None:
    endpoint, seen = daemon
    client = Client(endpoint, timeout_s=5.0)
    with pytest.warns(DeprecationWarning, match="yaw_deg"):
        client.go_to([0.5, 0.0, -1.0], yaw=math.pi / 4)
    assert seen[-1]["yaw"] == pytest.approx(math.pi / 4)
    status = client.status()
    with pytest.warns(DeprecationWarning, match="yaw_deg"):
        assert status.yaw == pytest.approx(math.pi)
    with pytest.warns(DeprecationWarning, match="reference_yaw_deg"):
        assert status.reference_yaw == pytest.approx(3 * math.pi / 4)
    with pytest.warns(DeprecationWarning, match="target_yaw_deg"):
        assert status.motion is not None and status.motion.target_yaw == \
            pytest.approx(-math.pi / 2)
    with pytest.raises(BadRequest, match="both"):
        client.go_to([0.5, 0.0, -1.0], yaw=0.1, yaw_deg=5.0)


def test_a_call_written_for_radians_fails_instead_of_turning_the_wrong_amount() -> None:
    """``go_to(p, 1.57)`` meant 90 degrees; read as degrees it would turn 1.57 degrees."""
    with pytest.raises(TypeError):
        Client("tcp://127.0.0.1:9").go_to([0.5, 0.0, -1.0], 1.57)  # type: ignore[misc]


def test_gs_goto_and_status_speak_degrees(daemon: tuple[str, list[dict[str, Any]]]) -> None:
    endpoint, seen = daemon
    runner = CliRunner()
    moved = runner.invoke(app, ["goto", "0.5", "0", "-1", "--yaw", "-45",
                                "--control", endpoint])
    assert moved.exit_code == 0, moved.output
    assert seen[-1]["yaw"] == pytest.approx(-math.pi / 4)
    now = runner.invoke(app, ["status", "--control", endpoint])
    assert now.exit_code == 0, now.output
    assert "heading +180 deg" in now.output and "heading +135 deg" in now.output
