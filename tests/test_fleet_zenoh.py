"""The fleet's parts over real Zenoh sessions on loopback (peer mode, no scouting, explicit
endpoints) and real UDP, nothing flying: the relay and the Zenoh pose source (the same
pose filter as a daemon reading Tracker itself), the peers' table, the daemon's node
answering queries and guarding motions, and TLS with the fleet's access rules."""

from __future__ import annotations

import shutil
import socket
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from groundstation.client import Fleet, TooClose
from groundstation.config import ZenohConfig, load_config, validate_config
from groundstation.config.fleetfile import load_fleet
from groundstation.endpoints import free_ports
from groundstation.errors import FleetError
from groundstation.fleet import keys
from groundstation.fleet.messages import Intent, PeerPose
from groundstation.fleet.node import FleetNode, parse_request
from groundstation.fleet.peers import TERMINAL_STATES, PeerTable
from groundstation.fleet.posesource import ZenohPoseSource
from groundstation.fleet.relay import ViconRelay
from groundstation.fleet.session import Membership, open_session
from groundstation.fleetops.virtual import write_fleet
from groundstation.flight.assembly import assemble, zenoh_params
from groundstation.flight.commander import CommandRefusedError, PlanBase, Rest, plan_go_to
from groundstation.flight.params import FlightParams, ZenohParams
from groundstation.flight.supervisor import TERMINAL
from groundstation.vicon.decoder import ObjectPose, encode_datagram
from groundstation.vicon.plausibility import Plausibility
from groundstation.vicon.posefilter import PoseFilter

REPO = Path(__file__).resolve().parents[1]
TIMEOUT = 5.0


def until(condition: Callable[[], bool], timeout: float = TIMEOUT) -> bool:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def heard(session: Any, key: str) -> bool:
    """Wait until a subscriber for ``key`` is known to ``session`` (a put made before its
    declaration arrived would be lost)."""
    publisher = session.declare_publisher(key)
    try:
        return until(lambda: bool(publisher.matching_status.matching))
    finally:
        publisher.undeclare()


@pytest.fixture
def pair() -> Iterator[tuple[Any, Any]]:
    """Two sessions of one fleet linked on loopback."""
    port = free_ports(1)[0]
    members = Membership("lab", ("v1", "v2"))
    a = open_session(zenoh_params(ZenohConfig(listen=[f"tcp/127.0.0.1:{port}"], connect=[])),
                     members)
    b = open_session(zenoh_params(ZenohConfig(listen=[], connect=[f"tcp/127.0.0.1:{port}"])),
                     members)
    try:
        yield a, b
    finally:
        b.close()
        a.close()


def item(frame: int, x_mm: float, name: str = "X3D-1",
         rotation: tuple[float, float, float] = (0.01, -0.02, 0.3)) -> ObjectPose:
    return ObjectPose(name, (x_mm, 250.0, 1000.0), rotation)


@pytest.mark.slow
def test_relayed_items_give_the_poses_tracker_itself_would(pair: tuple[Any, Any]) -> None:
    """The same datagrams, fed to a pose filter directly and through the relay to a Zenoh
    pose source: the same poses, frame numbers and stamps (the relay's receive time); an
    object lost (all zeros) is counted by the source's filter as Tracker's would be; an
    implausible item stops at the relay."""
    relay_session, daemon_session = pair
    cfg = validate_config({"fleet": {"name": "lab", "vehicle": "v1"},
                           "vicon": {"source": "zenoh", "object_name": "X3D-1"}})
    relay = ViconRelay(relay_session, "lab", "127.0.0.1", 0, Plausibility.create()).start()
    vicon = assemble(cfg).vicon
    source = ZenohPoseSource.for_fleet(daemon_session, "lab", vicon).start()
    direct = PoseFilter.from_params(vicon.filter)
    datagrams = [encode_datagram(k, [item(k, 100.0 + k), item(k, 0.0, "X3D-2")])
                 for k in range(1, 21)]
    datagrams.append(encode_datagram(21, [ObjectPose("X3D-1", (0.0,) * 3, (0.0,) * 3)]))
    datagrams.append(encode_datagram(22, [item(22, 1e9)]))  # a kilometre off: implausible
    try:
        assert heard(relay_session, keys.vicon_key("lab", "X3D-1"))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            for d in datagrams:
                sender.sendto(d, relay.address)
                time.sleep(0.005)
        assert until(lambda: source.health().datagrams == 21)  # the implausible one stopped
        relayed = []
        while (pose := source.get(0.0)) is not None:
            relayed.append(pose)
        expected = [p for d in datagrams[:21] if (p := direct.process(d, 0.0)) is not None]
        assert [p.frame for p in relayed] == [p.frame for p in expected] == list(range(3, 21))
        for got, want in zip(relayed, expected, strict=True):
            np.testing.assert_allclose(got.position, want.position, atol=1e-12)
            np.testing.assert_allclose(got.quaternion, want.quaternion, atol=1e-12)
        assert source.health().lost_zero == 1
        assert relay.counters()["implausible"] == 1
        assert relay.counters()["items"] == {"X3D-1": 21, "X3D-2": 20}
        # stamped with the relay's receive time on this machine's clock, less the latency
        assert all(0.0 <= time.monotonic() - (p.t + cfg.vicon.latency_s) < 2.0 for p in relayed)
        assert source.hop.n == 21 and source.hop.percentile(99.0) < 0.1
        relay_session.put(keys.vicon_key("lab", "X3D-1"), b"not a pose")
        assert until(lambda: source.malformed == 1)
    finally:
        source.close()
        relay.close()


@pytest.mark.slow
def test_the_peers_table_keeps_the_latest_pose_and_intent(pair: tuple[Any, Any]) -> None:
    a, b = pair
    table = PeerTable(["v2"]).subscribe(a, "lab")
    try:
        assert heard(b, keys.vehicle_key("lab", "v2", "pose"))
        assert heard(b, keys.vehicle_key("lab", "v2", "intent"))
        pose = PeerPose(2, 7, (0.5, 0.0, -1.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        b.put(keys.vehicle_key("lab", "v2", "pose"), pose.pack())
        b.put(keys.vehicle_key("lab", "v9", "pose"), pose.pack())  # not a peer
        b.put(keys.vehicle_key("lab", "v2", "intent"),
              Intent(1, 0.05, np.array([[0.5, 0.0, -1.0], [0.6, 0.0, -1.0]])).pack())
        assert until(lambda: table.views()[0].intent.shape == (2, 3) and table.ignored == 1)
        view = table.views()[0]
        assert view.name == "v2" and not view.ended and view.age_s < 1.0
        np.testing.assert_allclose(view.position, [0.5, 0.0, -1.0])  # type: ignore[arg-type]
        b.put(keys.vehicle_key("lab", "v2", "pose"), PeerPose(
            6, 8, (0.5, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0)).pack())
        assert until(lambda: table.views()[0].ended)  # DONE: on the floor, an obstacle
        assert table.views(time.monotonic() + 60.0)[0].silent(0.5) is False
    finally:
        table.close()
    assert {int(s) for s in TERMINAL} == TERMINAL_STATES


def fleet_config(tmp_path: Path) -> tuple[Path, dict[str, FlightParams]]:
    path = write_fleet(tmp_path, load_config(REPO / "config" / "sim.yaml"),
                       [(-0.5, 0.0), (0.5, 0.0)], separation_m=0.5)
    spec, base = load_fleet(path)
    return path, {n: assemble(spec.vehicle_config(base, n)) for n in spec.names}


@pytest.mark.slow
def test_requests_are_queries_answered_by_the_daemons_handler(tmp_path: Path) -> None:
    """What a query carries reaches the handler as the control socket's request; the
    reply comes back on the vehicle's own key; one query reaches every vehicle; a
    malformed payload is refused before the handler."""
    path, configs = fleet_config(tmp_path)
    seen: list[dict[str, Any]] = []

    def handler(name: str) -> Callable[[dict[str, Any]], dict[str, Any]]:
        def answer(request: dict[str, Any]) -> dict[str, Any]:
            seen.append(request)
            if request["request"] == "go_to":
                return {"ok": False, "error": "v1 says no", "kind": "separation"}
            return {"ok": True, "state": "TRACK", "who": name}
        return answer

    with FleetNode.open(configs["v1"]) as n1, FleetNode.open(configs["v2"]) as n2, \
            n1.serving(handler("v1")), n2.serving(handler("v2")), Fleet(path) as fleet:
        assert until(lambda: len(fleet.query("*", "channels", {}, 1.0)) == 2 and all(
            isinstance(r, dict) for r in fleet.query("*", "channels", {}, 1.0).values()))
        replies = fleet.query("*", "channels", {"auto": ["thrust"]}, 3.0)
        assert {n: r["who"] for n, r in replies.items()} == {"v1": "v1", "v2": "v2"}  # type: ignore[index]
        with pytest.raises(TooClose, match="v1 says no"):
            fleet["v1"].go_to([0.0, 0.0, -1.0])
        assert {"request": "go_to", "position": [0.0, 0.0, -1.0], "yaw": None,
                "duration": None} in seen
        assert {"request": "channels", "auto": ["thrust"]} in seen
        session = fleet._session
        bad = list(session.get(keys.request_key("demo", "v2", "status"), payload=b"[1, 2]",
                               timeout=3.0))
        assert b"malformed request" in bad[0].ok.payload.to_bytes()
    with pytest.raises(ValueError, match="at most 4096"):
        parse_request("status", b" " * 5000)
    with pytest.raises(ValueError, match="says 'land'"):
        parse_request("status", b'{"request": "land"}')


def _planned(params: FlightParams, target: list[float]) -> Any:
    """A go-to planned from rest 1 m above v1's home (the commander's own planner)."""
    base = PlanBase((Rest(0.0, np.array(params.commander.home), 0.0),), 0, 1.0, 0.0,
                    "TRACK", np.zeros(3), 1.0)
    return plan_go_to(base, np.array(target, dtype=float), None, None,
                      params.planner.limits)


def _repeat(action: Callable[[], object], period_s: float, done: threading.Event) -> None:
    """``action`` every ``period_s`` until ``done``."""
    while not done.is_set():
        action()
        done.wait(period_s)


@pytest.mark.slow
def test_the_guard_refuses_what_comes_near_a_peer_and_shares_what_it_flies(tmp_path: Path
                                                                           ) -> None:
    _path, configs = fleet_config(tmp_path)
    with FleetNode.open(configs["v1"]) as n1, FleetNode.open(configs["v2"]) as n2:
        with pytest.raises(CommandRefusedError) as silent:
            n1.check(_planned(configs["v1"], [-0.5, 0.5, -1.0]))
        assert silent.value.kind == "state"
        assert "v2 (never heard)" in str(silent.value)
        pose = PeerPose(2, 1, (0.5, 0.0, -1.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        assert heard(n2._session, keys.vehicle_key("demo", "v2", "pose"))
        # v2 keeps saying where it is, as a flying daemon does at its telemetry rate: one
        # pose put once goes silent after fleet.peer_timeout_s (0.5 s), which a loaded
        # machine can spend planning the next motion
        done = threading.Event()
        speaker = threading.Thread(target=_repeat, args=(lambda: n2._put("pose", pose.pack()),
                                                         0.05, done), daemon=True)
        speaker.start()
        try:
            assert until(lambda: n1.peers.views()[0].position is not None)
            with pytest.raises(CommandRefusedError) as close:
                n1.check(_planned(configs["v1"], [0.2, 0.0, -1.0]))  # 0.3 m from v2
            assert close.value.kind == "separation"
            clear = _planned(configs["v1"], [-0.5, -0.6, -1.0])
            n1.check(clear)
            assert heard(n1._session, keys.vehicle_key("demo", "v1", "intent"))
            n1.installed(clear)  # flies: v2 hears where v1 will be
            assert until(lambda: len(n2.peers.views()[0].intent) > 10)
        finally:
            done.set()
            speaker.join()
        intent = n2.peers.views()[0].intent
        assert np.min(np.linalg.norm(intent - [-0.5, -0.6, -1.0], axis=1)) < 0.01
        assert np.min(np.linalg.norm(intent - [-0.5, 0.0, -1.0], axis=1)) < 0.01


def test_a_port_taken_is_a_fleet_error() -> None:
    port = free_ports(1)[0]
    members = Membership("lab", ("v1",))
    settings = zenoh_params(ZenohConfig(listen=[f"tcp/127.0.0.1:{port}"], connect=[]))
    first = open_session(settings, members)
    try:
        with pytest.raises(FleetError, match="Address already in use"):
            open_session(settings, members)
    finally:
        first.close()


# --------------------------------------------------------------------------- TLS
def _certificates(directory: Path, names: list[str], ca: str = "ca") -> None:
    """A CA and a certificate for each name (its common name), signed by it, valid for
    127.0.0.1 and localhost: what a lab makes once with openssl (README "Fleet")."""
    def run(*args: str) -> None:
        subprocess.run(["openssl", *args], check=True, capture_output=True, cwd=directory)

    run("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes",
        "-keyout", f"{ca}.key", "-out", f"{ca}.pem", "-days", "2", "-subj", f"/CN={ca}")
    (directory / "ext.cnf").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n"
                                       "extendedKeyUsage=serverAuth,clientAuth\n")
    for name in names:
        run("req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes",
            "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj", f"/CN={name}")
        run("x509", "-req", "-in", f"{name}.csr", "-CA", f"{ca}.pem", "-CAkey", f"{ca}.key",
            "-CAcreateserial", "-out", f"{name}.pem", "-days", "2", "-extfile", "ext.cnf")


def _tls(directory: Path, name: str, listen: list[str], connect: list[str],
         ca: str = "ca") -> ZenohParams:
    return zenoh_params(ZenohConfig(
        listen=listen, connect=connect, tls_root_ca=directory / f"{ca}.pem",
        tls_certificate=directory / f"{name}.pem", tls_private_key=directory / f"{name}.key",
        operators=["alice"]))


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs openssl for certificates")
def test_tls_and_the_access_rules_decide_who_may_say_what(tmp_path: Path) -> None:
    """mTLS: a certificate of another CA does not connect. Access rules by common name:
    the relay's Vicon poses arrive, the same key from a vehicle's certificate does not; a
    vehicle's pose under its own key arrives, under another's it does not; the operator's
    request is answered, a vehicle's certificate cannot query v1."""
    _certificates(tmp_path, ["v1", "v2", "relay", "alice", "mallory"])
    (tmp_path / "evil").mkdir()
    _certificates(tmp_path / "evil", ["v2"], ca="evil")
    port = free_ports(1)[0]
    members = Membership("lab", ("v1", "v2"), operators=("alice",))
    at = [f"tls/127.0.0.1:{port}"]
    v1 = open_session(_tls(tmp_path, "v1", at, []), members)
    others = {n: open_session(_tls(tmp_path, n, [], at), members)
              for n in ("relay", "v2", "alice", "mallory")}
    forged = open_session(_tls(tmp_path / "evil", "v2", [], at, ca="evil"), members)
    got: list[tuple[str, bytes]] = []
    subs = [v1.declare_subscriber("lab/**", lambda s: got.append(
        (str(s.key_expr), s.payload.to_bytes())))]
    subs.append(v1.declare_queryable("lab/v1/cmd/status", lambda q: q.reply(
        "lab/v1/cmd/status", b'{"ok": true}')))
    try:
        assert until(lambda: len(v1.info.peers_zid()) >= 4)
        time.sleep(0.5)
        assert len(v1.info.peers_zid()) == 4  # the forged v2 (another CA) is not among them
        others["relay"].put("lab/vicon/X3D-1", b"relay")
        others["v2"].put("lab/vicon/X3D-1", b"v2 forging Vicon")
        others["v2"].put("lab/v2/pose", b"v2")
        others["v2"].put("lab/v1/pose", b"v2 posing as v1")
        others["mallory"].put("lab/v2/pose", b"mallory")
        forged.put("lab/v2/pose", b"forged")
        assert until(lambda: len(got) >= 2)
        time.sleep(0.5)
        assert sorted(got) == [("lab/v2/pose", b"v2"), ("lab/vicon/X3D-1", b"relay")]
        answered = list(others["alice"].get("lab/v1/cmd/status", timeout=2.0))
        assert [r.ok.payload.to_bytes() for r in answered if r.ok] == [b'{"ok": true}']
        refused = list(others["mallory"].get("lab/v1/cmd/status", timeout=1.0))
        assert not [r for r in refused if r.ok]
    finally:
        for s in subs:
            s.undeclare()
        for session in (forged, *others.values(), v1):
            session.close()


@pytest.mark.slow
def test_gs_fleet_land_asks_every_vehicle_at_once_and_waits_for_their_ends(tmp_path: Path
                                                                           ) -> None:
    """Both vehicles get one land query; with --wait their final ``state`` messages end
    it (exit 0 when both ended DONE, COMPLETED); a vehicle that does not answer is named
    and exit 1."""
    import threading

    from typer.testing import CliRunner

    from groundstation.cli import app

    path, configs = fleet_config(tmp_path)
    final = {"state": {"supervisor": {"state": 6, "name": "DONE"}, "final": True,
                       "outcome": "COMPLETED", "reason": "landed and disarmed"}}

    def lands(node: FleetNode) -> Callable[[dict[str, Any]], dict[str, Any]]:
        def answer(request: dict[str, Any]) -> dict[str, Any]:
            if request["request"] == "land":
                threading.Timer(0.3, node.publish_end, (final, 6)).start()
            return {"ok": True, "state": "TRACK"}
        return answer

    with FleetNode.open(configs["v1"]) as n1, FleetNode.open(configs["v2"]) as n2, \
            n1.serving(lands(n1)), n2.serving(lands(n2)):
        with Fleet(path) as probe:
            assert until(lambda: all(isinstance(r, dict) for r in
                                     probe.query("*", "status", {}, 1.0).values()))
        result = CliRunner().invoke(app, ["fleet", "land", str(path), "--wait",
                                          "--wait-timeout", "10"])
        time.sleep(0.5)  # the timers' messages are out before the nodes close
    assert result.exit_code == 0, result.output
    assert result.output.splitlines() == [
        "v1: ended DONE (COMPLETED): landed and disarmed",
        "v2: ended DONE (COMPLETED): landed and disarmed"]
    with FleetNode.open(configs["v1"]) as n1, n1.serving(lands(n1)):
        result = CliRunner().invoke(app, ["fleet", "land", str(path), "--timeout", "1"])
        time.sleep(0.5)
    assert result.exit_code == 1
    assert "v1: landing (from TRACK)" in result.output
    assert "v2: v2 did not answer 'land' within 1 s" in result.output
