"""Run-time requests to the daemon: the REP server the loop polls, the client, the handler."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
import zmq

from groundstation.app.daemon import FlightDaemon
from groundstation.config import validate_config
from groundstation.endpoints import local_endpoint
from groundstation.errors import TelemetryError
from groundstation.flight.assembly import assemble
from groundstation.telemetry.curve import CurveClient, load_client_keys, load_server_keys
from groundstation.telemetry.requests import (
    FRAMES_PER_POLL,
    MAX_PARSED_BYTES,
    MAX_REQUEST_BYTES,
    RequestServer,
    send_request,
)


def _serve_until(server: RequestServer, answered: int,
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
    with RequestServer("tcp://127.0.0.1:*") as server:
        assert server.endpoint is not None and not server.endpoint.endswith("*")
        thread = _serve_until(server, 1)
        reply = send_request(server.endpoint, {"request": "channels", "auto": ["thrust"]})
        thread.join(5.0)
    assert reply == {"ok": True, "echo": {"request": "channels", "auto": ["thrust"]}}
    assert server.bad_requests == 0


def test_poll_without_a_request_returns_at_once() -> None:
    with RequestServer("tcp://127.0.0.1:*") as server:
        assert server.poll(lambda r: pytest.fail("no request was sent")) is False
    disabled = RequestServer(None)
    assert disabled.endpoint is None and disabled.poll(lambda r: {}) is False


@pytest.mark.parametrize("raw", [b"{not json", b"[1, 2]", b"\xff\xfe", b'"text"'])
def test_malformed_requests_get_an_error_reply_and_are_counted(raw: bytes) -> None:
    with RequestServer("tcp://127.0.0.1:*") as server:
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
    assert isinstance(reply, dict) and reply["ok"] is False and reply["kind"] == "request"
    assert reply["error"].startswith("malformed request")
    assert server.bad_requests == 1


def test_a_failing_handler_is_answered_not_raised() -> None:
    def broken(request: dict[str, Any]) -> dict[str, Any]:
        raise RuntimeError("bug")

    with RequestServer("tcp://127.0.0.1:*") as server:
        assert server.endpoint is not None
        thread = _serve_until(server, 1, broken)
        reply = send_request(server.endpoint, {"request": "channels"})
        thread.join(5.0)
    # every error reply has a kind: a handler's failure is ours ("internal"), not the client's
    assert reply == {"ok": False, "error": "internal error: RuntimeError: bug", "kind": "internal"}
    assert server.bad_requests == 1


def test_no_daemon_is_a_clear_timeout() -> None:
    with RequestServer("tcp://127.0.0.1:*") as server:  # bound but never polled
        assert server.endpoint is not None
        with pytest.raises(TelemetryError, match=r"no reply .* within 0\.2 s"):
            send_request(server.endpoint, {"request": "channels"}, timeout_s=0.2)


def test_port_in_use_names_the_endpoint() -> None:
    with RequestServer("tcp://127.0.0.1:*") as first:
        assert first.endpoint is not None
        with pytest.raises(TelemetryError, match="cannot bind"):
            RequestServer(first.endpoint)


@pytest.mark.parametrize(("request_", "error"), [
    ({"request": "jump"}, "unknown request 'jump'"),
    ({"request": "channels", "auto": []}, "one or more"),
    ({"request": "channels", "auto": ["thrust", "elevator"]}, "one or more"),
    ({"request": "channels", "auto": ["thrust", "thrust"]}, "once each"),
    ({"request": "channels", "auto": "thrust"}, "one or more"),
])
def test_daemon_refuses_bad_channel_requests(request_: dict[str, Any], error: str) -> None:
    daemon = FlightDaemon(assemble(validate_config({})))
    before = daemon.core.auto_channels
    reply = daemon.handle_request(request_)
    assert reply["ok"] is False and error in reply["error"]
    assert daemon.core.auto_channels == before


def test_daemon_sets_and_reports_channels() -> None:
    daemon = FlightDaemon(assemble(validate_config({})))
    assert daemon.handle_request({"request": "channels"}) == {
        "ok": True, "auto": ["pitch", "roll", "yaw", "thrust"], "state": "PREFLIGHT"}
    reply = daemon.handle_request({"request": "channels", "auto": ["thrust", "yaw"]})
    assert reply == {"ok": True, "auto": ["yaw", "thrust"], "state": "PREFLIGHT"}
    assert set(daemon.core.auto_channels) == {"thrust", "yaw"}


# --------------------------------------------------------------------------- hostile requests
# Nothing a client sends may raise out of the loop's poll, stall it, or leave
# the REP socket owing a reply; each bad request gets an error reply (or, too large, never
# reaches us) and is counted, and the server keeps serving.

ECHO: Any = lambda r: {"ok": True, "echo": r}  # noqa: E731  # the handler the tests serve


@contextmanager
def _serving(server: RequestServer, handler: Any = ECHO) -> Iterator[None]:
    """Poll ``server`` like the flight loop (every ms) in a thread; any exception out of
    :meth:`RequestServer.poll` fails the test."""
    stop = threading.Event()
    errors: list[BaseException] = []

    def run() -> None:
        try:
            while not stop.wait(0.001):
                server.poll(handler)
        except BaseException as exc:  # the loop would have died: report it
            errors.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(5.0)
    assert not errors, f"poll raised {errors[0]!r}"


def _raw(endpoint: str, frames: list[bytes], timeout_s: float = 5.0,
         curve: CurveClient | None = None) -> Any:
    """Send ``frames`` as one message from a fresh REQ socket; the decoded reply, or None."""
    ctx = zmq.Context()
    req = ctx.socket(zmq.REQ)
    try:
        req.setsockopt(zmq.LINGER, 0)
        if curve is not None:
            curve.apply(req)
        req.connect(endpoint)
        req.send_multipart(frames)
        if not req.poll(int(timeout_s * 1000)):
            return None
        return json.loads(req.recv())
    finally:
        req.close(linger=0)
        ctx.term()


def _served(endpoint: str) -> bool:
    return send_request(endpoint, {"request": "channels"})["ok"] is True


@pytest.mark.parametrize(("frames", "error"), [
    ([b'{"request": "channels"}', b"more"], "one message frame"),
    ([b'{"request": "channels"}', b"", b"x" * 60000], "one message frame"),
    ([b"\x00\xff\xfe\x80binary"], "not UTF-8"),
    ([b"[" * 4000], "nested too deeply"),
    ([b"[" * 60000], "60000 bytes, a request is at most 4096"),
    ([b'{"request": "channels"'], "malformed request"),
    ([b""], "malformed request"),
])
def test_bad_requests_get_an_error_reply_and_the_server_keeps_serving(
        frames: list[bytes], error: str) -> None:
    with RequestServer("tcp://127.0.0.1:*") as server, _serving(server):
        assert server.endpoint is not None
        reply = _raw(server.endpoint, frames)
        assert reply is not None and reply["ok"] is False and error in reply["error"], reply
        assert reply["kind"] == "request"
        assert len(reply["error"]) <= 300  # the reply does not echo a large request back
        assert _served(server.endpoint)
    assert (server.answered, server.bad_requests) == (2, 1)
    assert server.stats()["malformed"] == 1


@pytest.mark.slow
def test_a_request_over_64_kib_never_reaches_the_handler() -> None:
    seen: list[Any] = []

    def handler(request: dict[str, Any]) -> dict[str, Any]:
        seen.append(request)
        return {"ok": True}

    pad = {"request": "channels", "pad": ""}
    with RequestServer("tcp://127.0.0.1:*") as server, _serving(server, handler):
        assert server.endpoint is not None
        big = json.dumps({**pad, "pad": "x" * MAX_REQUEST_BYTES}).encode()
        assert _raw(server.endpoint, [big], timeout_s=0.5) is None  # the peer is dropped
        assert _raw(server.endpoint, [b"x" * 12_000_000], timeout_s=0.5) is None
        delivered = json.dumps({**pad, "pad": "x" * (MAX_REQUEST_BYTES - 100)}).encode()
        reply = _raw(server.endpoint, [delivered])  # delivered, answered unparsed
        assert reply is not None and "a request is at most 4096" in reply["error"]
        fits = json.dumps({**pad, "pad": "x" * (MAX_PARSED_BYTES - 100)}).encode()
        assert _raw(server.endpoint, [fits]) == {"ok": True}
    assert len(seen) == 1 and server.answered == 2 and server.bad_requests == 1


def test_a_multipart_flood_is_drained_a_bounded_number_of_frames_per_poll() -> None:
    frames = [b'{"request": "channels"}'] + [b""] * (10 * FRAMES_PER_POLL)
    with RequestServer("tcp://127.0.0.1:*") as server:
        assert server.endpoint is not None
        ctx = zmq.Context()
        req = ctx.socket(zmq.REQ)
        try:
            req.setsockopt(zmq.LINGER, 0)
            req.connect(server.endpoint)
            req.send_multipart(frames)
            polls = 0
            deadline = time.monotonic() + 5.0
            while server.stats()["frames_discarded"] == 0 and time.monotonic() < deadline:
                server.poll(ECHO)  # until the message has arrived and the drain began
                time.sleep(0.001)
            while not req.poll(0) and polls < 100:
                before = server.stats()["frames_discarded"]
                server.poll(ECHO)
                assert server.stats()["frames_discarded"] - before <= FRAMES_PER_POLL
                polls += 1
            reply = json.loads(req.recv())
        finally:
            req.close(linger=0)
            ctx.term()
    assert reply["ok"] is False and "one message frame" in reply["error"]
    assert polls >= 9  # 640 frames at most 64 a poll: the loop never spends long on it


def test_a_reply_that_cannot_be_sent_reopens_the_socket(monkeypatch: pytest.MonkeyPatch
                                                        ) -> None:
    with RequestServer("tcp://127.0.0.1:*") as server:
        assert server.endpoint is not None and server._socket is not None
        broken = server._socket

        def fail(*args: Any, **kwargs: Any) -> None:
            raise zmq.ZMQError(zmq.EFSM)

        monkeypatch.setattr(broken, "send", fail)
        with _serving(server):
            assert _raw(server.endpoint, [b'{"request": "channels"}'], timeout_s=0.5) is None
            assert _served(server.endpoint)  # a fresh socket on the same endpoint
        assert server._socket is not broken
    assert server.stats()["socket_errors"] == 1 and server.stats()["reopened"] == 1


# --------------------------------------------------------------------------- who may connect
@pytest.mark.parametrize(("endpoint", "local"), [
    ("tcp://127.0.0.1:5557", True), ("tcp://127.3.2.1:*", True), ("tcp://localhost:5557", True),
    ("tcp://[::1]:5557", True), ("tcp://lo:5557", True), ("ipc:///run/gs/control", True),
    ("inproc://control", True),
    ("tcp://*:5557", False), ("tcp://0.0.0.0:5557", False), ("tcp://[::]:5557", False),
    ("tcp://192.168.1.20:5557", False), ("tcp://eth0:5557", False), ("tcp://lab-pc:5557", False),
])
def test_local_endpoints(endpoint: str, local: bool) -> None:
    assert local_endpoint(endpoint) is local


@pytest.mark.parametrize("endpoint", ["tcp://0.0.0.0:*", "tcp://*:*"])
def test_a_bind_beyond_loopback_without_keys_is_refused(endpoint: str) -> None:
    with pytest.raises(TelemetryError, match="beyond loopback without CURVE"):
        RequestServer(endpoint)


@pytest.fixture
def keys(tmp_path: Path) -> dict[str, Path]:
    """CURVE key pairs made as a lab would (zmq.auth.create_certificates): the server's, an
    authorised client's (public key in the clients directory) and a stranger's."""
    import zmq.auth

    clients = tmp_path / "clients"
    clients.mkdir()
    out: dict[str, Path] = {"clients": clients}
    for name in ("server", "client", "stranger"):
        public, secret = zmq.auth.create_certificates(tmp_path, name)
        out[name], out[f"{name}_secret"] = Path(public), Path(secret)
    (clients / "client.key").write_bytes(out["client"].read_bytes())
    return out


@pytest.mark.slow
def test_with_curve_only_an_authorised_client_is_served(keys: dict[str, Path]) -> None:
    curve = load_server_keys(keys["server_secret"], keys["clients"])
    with RequestServer("tcp://127.0.0.1:*", curve=curve) as server, _serving(server):
        assert server.endpoint is not None
        good = load_client_keys(keys["client_secret"], keys["server"])
        assert send_request(server.endpoint, {"request": "channels"}, curve=good)["ok"]
        stranger = load_client_keys(keys["stranger_secret"], keys["server"])
        with pytest.raises(TelemetryError, match="no reply"):
            send_request(server.endpoint, {"request": "channels"}, 0.5, curve=stranger)
        with pytest.raises(TelemetryError, match="no reply"):  # no keys at all
            send_request(server.endpoint, {"request": "channels"}, 0.5)
        assert send_request(server.endpoint, {"request": "channels"}, curve=good)["ok"]
    assert server.answered == 2
    assert server.stats()["refused"] == 1  # the stranger (the keyless one never got to ZAP)


def test_key_files_that_cannot_be_used_are_named(keys: dict[str, Path], tmp_path: Path) -> None:
    with pytest.raises(TelemetryError, match="no secret key"):
        load_server_keys(keys["server"], keys["clients"])  # the public half only
    with pytest.raises(TelemetryError, match=r"absent\.key_secret.*no such file"):
        load_server_keys(tmp_path / "absent.key_secret", keys["clients"])
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(TelemetryError, match="no client public keys"):
        load_server_keys(keys["server_secret"], empty)
    with pytest.raises(TelemetryError, match="no secret key"):
        load_client_keys(keys["client"], keys["server"])


def test_the_daemon_handler_behind_a_real_socket_survives_hostile_clients() -> None:
    """The loop's call, ``control.poll(daemon.handle_request)``, against garbage and then a
    real request: the garbage is answered and counted, the request takes effect."""
    daemon = FlightDaemon(assemble(validate_config({})))
    with RequestServer("tcp://127.0.0.1:*") as server, \
            _serving(server, daemon.handle_request):
        assert server.endpoint is not None
        for frames in ([b"{}", b"{}"], [b"\xff"], [b"[" * 4000], [b'{"request": 7}'],
                       [b'{"request": "channels", "auto": [[], {}]}']):
            reply = _raw(server.endpoint, frames)
            assert reply is not None and reply["ok"] is False and reply["kind"] == "request"
        assert _raw(server.endpoint, [b"x" * (MAX_REQUEST_BYTES + 1)], timeout_s=0.3) is None
        reply = send_request(server.endpoint, {"request": "channels", "auto": ["thrust"]})
    assert reply == {"ok": True, "auto": ["thrust"], "state": "PREFLIGHT"}
    assert daemon.core.auto_channels == ("thrust",)
    stats = server.stats()
    assert stats["answered"] == 6 and stats["malformed"] == 3 and stats["failed"] == 0


def test_the_flight_summary_shows_the_control_counters() -> None:
    from groundstation.app.fly import summary_lines

    daemon = FlightDaemon(assemble(validate_config({})))
    summary = replace(daemon._summary(), control={"answered": 4, "malformed": 2, "refused": 1,
                                                  "failed": 0})
    line = next(x for x in summary_lines(summary) if "control socket" in x)
    assert line == "  control socket: 4 requests answered, 2 malformed, 1 refused"
    assert not any("control socket" in x for x in summary_lines(daemon._summary()))
