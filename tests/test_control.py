"""Run-time requests to the daemon: the REP server the loop polls, the client, the handler."""

from __future__ import annotations

import threading
from typing import Any

import pytest
import zmq

from groundstation.config import validate_config
from groundstation.errors import TelemetryError
from groundstation.loop.daemon import FlightDaemon
from groundstation.telemetry.control import ControlServer, send_request


def _serve_until(server: ControlServer, answered: int,
                 handler: Any = lambda r: {"ok": True, "echo": r}) -> threading.Thread:
    """Poll like the flight loop (every ms) until ``answered`` requests are answered."""
    def run() -> None:
        stop = threading.Event()
        while server.answered < answered and not stop.wait(0.001):
            server.poll(handler)
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def test_request_round_trip() -> None:
    with ControlServer("tcp://127.0.0.1:*") as server:
        assert server.endpoint is not None and not server.endpoint.endswith("*")
        thread = _serve_until(server, 1)
        reply = send_request(server.endpoint, {"request": "channels", "auto": ["thrust"]})
        thread.join(5.0)
    assert reply == {"ok": True, "echo": {"request": "channels", "auto": ["thrust"]}}
    assert server.bad_requests == 0


def test_poll_without_a_request_returns_at_once() -> None:
    with ControlServer("tcp://127.0.0.1:*") as server:
        assert server.poll(lambda r: pytest.fail("no request was sent")) is False
    disabled = ControlServer(None)
    assert disabled.endpoint is None and disabled.poll(lambda r: {}) is False


@pytest.mark.parametrize("raw", [b"{not json", b"[1, 2]", b"\xff\xfe", b'"text"'])
def test_malformed_requests_get_an_error_reply_and_are_counted(raw: bytes) -> None:
    with ControlServer("tcp://127.0.0.1:*") as server:
        assert server.endpoint is not None
        ctx = zmq.Context()
        req = ctx.socket(zmq.REQ)
        req.setsockopt(zmq.LINGER, 0)
        req.connect(server.endpoint)
        try:
            req.send(raw)
            thread = _serve_until(server, 1)
            assert req.poll(5000)
            reply = req.recv_json()
            thread.join(5.0)
        finally:
            req.close(linger=0)
            ctx.term()
    assert isinstance(reply, dict) and reply["ok"] is False
    assert reply["error"].startswith("malformed request")
    assert server.bad_requests == 1


def test_a_failing_handler_is_answered_not_raised() -> None:
    def broken(request: dict[str, Any]) -> dict[str, Any]:
        raise RuntimeError("bug")

    with ControlServer("tcp://127.0.0.1:*") as server:
        assert server.endpoint is not None
        thread = _serve_until(server, 1, broken)
        reply = send_request(server.endpoint, {"request": "channels"})
        thread.join(5.0)
    assert reply == {"ok": False, "error": "request failed: bug"}
    assert server.bad_requests == 1


def test_no_daemon_is_a_clear_timeout() -> None:
    with ControlServer("tcp://127.0.0.1:*") as server:  # bound but never polled
        assert server.endpoint is not None
        with pytest.raises(TelemetryError, match=r"no reply .* within 0\.2 s"):
            send_request(server.endpoint, {"request": "channels"}, timeout_s=0.2)


def test_port_in_use_names_the_endpoint() -> None:
    with ControlServer("tcp://127.0.0.1:*") as first:
        assert first.endpoint is not None
        with pytest.raises(TelemetryError, match="cannot bind"):
            ControlServer(first.endpoint)


@pytest.mark.parametrize(("request_", "error"), [
    ({"request": "land"}, "unknown request 'land'"),
    ({"request": "channels", "auto": []}, "one or more"),
    ({"request": "channels", "auto": ["thrust", "elevator"]}, "one or more"),
    ({"request": "channels", "auto": ["thrust", "thrust"]}, "once each"),
    ({"request": "channels", "auto": "thrust"}, "one or more"),
])
def test_daemon_refuses_bad_channel_requests(request_: dict[str, Any], error: str) -> None:
    daemon = FlightDaemon(validate_config({}))
    before = daemon.core.auto_channels
    reply = daemon.handle_request(request_)
    assert reply["ok"] is False and error in reply["error"]
    assert daemon.core.auto_channels == before


def test_daemon_sets_and_reports_channels() -> None:
    daemon = FlightDaemon(validate_config({}))
    assert daemon.handle_request({"request": "channels"}) == {
        "ok": True, "auto": ["pitch", "roll", "yaw", "thrust"], "state": "PREFLIGHT"}
    reply = daemon.handle_request({"request": "channels", "auto": ["thrust", "yaw"]})
    assert reply == {"ok": True, "auto": ["yaw", "thrust"], "state": "PREFLIGHT"}
    assert set(daemon.core.auto_channels) == {"thrust", "yaw"}
