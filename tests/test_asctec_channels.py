"""Channel handover: masks follow the automatic set, transfers are bumpless."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from groundstation.asctec.channels import ChannelHandover
from groundstation.asctec.messages import CommandMsg
from groundstation.errors import ConfigError, ProtocolError
from groundstation.types import CHANNELS, Channel, Sticks

PILOT = Sticks(roll=100, pitch=-50, yaw=10, thrust=2000)
CONTROLLER = Sticks(roll=500, pitch=150, yaw=-90, thrust=2600)


def value(cmd: CommandMsg, channel: Channel) -> int:
    return int(getattr(cmd, channel))


def test_starts_manual_and_sends_the_pilot_sticks() -> None:
    cmd = ChannelHandover().compose(0.0, CONTROLLER, PILOT)
    assert cmd == CommandMsg(pitch=-50, roll=100, yaw=10, thrust=2000, ctrl=0)


def test_bumpless_linear_blend_over_blend_time() -> None:
    h = ChannelHandover(blend_time=1.0)
    h.set_auto(["roll"])
    # Handover instant t0 = 10: offset = pilot - controller = 100 - 500 = -400.
    expected = {10.0: 100, 10.25: 200, 10.5: 300, 10.75: 400, 11.0: 500, 12.0: 500}
    for t, roll in expected.items():  # controller + offset * (1 - (t - t0) / 1.0)
        cmd = h.compose(t, CONTROLLER, PILOT)
        assert cmd.ctrl == 0b0010
        assert cmd.roll == roll
        assert (cmd.pitch, cmd.yaw, cmd.thrust) == (-50, 10, 2000)  # still the pilot's


def test_toggling_channels_gives_the_right_masks_and_values() -> None:
    h = ChannelHandover(blend_time=0.5)
    h.set_auto(["roll", "thrust"])
    first = h.compose(0.0, CONTROLLER, PILOT)
    assert first.ctrl == 0b1010
    assert (first.roll, first.thrust) == (PILOT.roll, PILOT.thrust)  # no jump
    # Yaw added later: its own handover instant; roll/thrust keep blending.
    h.set_auto(["roll", "thrust", "yaw"])
    second = h.compose(0.25, CONTROLLER, PILOT)
    assert second.ctrl == 0b1110
    assert second.yaw == PILOT.yaw
    assert second.roll == 300  # 500 - 400 * 0.5
    assert second.thrust == 2300  # 2600 - 600 * 0.5
    # Roll handed back to the pilot: cleared in the very next COMMAND.
    h.set_auto(["thrust", "yaw"])
    third = h.compose(0.3, CONTROLLER, PILOT)
    assert third.ctrl == 0b1100
    assert third.roll == PILOT.roll
    # Roll handed over again: a fresh bumpless start from the pilot's stick.
    h.set_auto(["roll", "thrust", "yaw"])
    fourth = h.compose(1.0, CONTROLLER, Sticks(roll=-700, pitch=0, yaw=0, thrust=0))
    assert fourth.roll == -700
    assert fourth.thrust == CONTROLLER.thrust  # blend finished at 0.5 s
    assert fourth.yaw == CONTROLLER.yaw  # yaw blend finished at 0.75 s
    h.set_auto([])
    assert h.compose(1.1, CONTROLLER, PILOT).ctrl == 0


def test_outputs_are_clamped_to_the_legal_ranges() -> None:
    h = ChannelHandover(blend_time=0.0)
    h.set_auto(CHANNELS)
    wild = Sticks(roll=9000, pitch=-9000, yaw=2048, thrust=-5)
    cmd = h.compose(0.0, wild, PILOT)  # blend_time 0: controller at once
    assert (cmd.roll, cmd.pitch, cmd.yaw, cmd.thrust) == (2047, -2048, 2047, 0)
    h.set_auto([])
    pilot_wild = Sticks(roll=-3000, pitch=3000, yaw=0, thrust=5000)
    cmd = h.compose(0.1, wild, pilot_wild)
    assert (cmd.roll, cmd.pitch, cmd.thrust) == (-2048, 2047, 4096)


def test_bad_arguments() -> None:
    with pytest.raises(ProtocolError):
        ChannelHandover().set_auto(["collective"])  # type: ignore[list-item]  # on purpose
    with pytest.raises(ConfigError):
        ChannelHandover(blend_time=-1.0)


stick = st.integers(-2048, 2047)
sticks = st.builds(Sticks, stick, stick, stick, st.integers(0, 4096))
channel_sets = st.frozensets(st.sampled_from(CHANNELS))


@pytest.mark.slow
@given(st.lists(st.tuples(channel_sets, sticks, sticks, st.floats(0.0, 0.5)), max_size=12))
def test_handover_invariants(steps: list[tuple[frozenset[Channel], Sticks, Sticks, float]]) -> None:
    blend = 0.4
    h = ChannelHandover(blend_time=blend)
    t = 0.0
    started: dict[Channel, tuple[float, int]] = {}  # channel -> (t0, pilot - controller at t0)
    for channels, controller, pilot, dt in steps:
        t += dt
        h.set_auto(channels)
        cmd = h.compose(t, controller, pilot)
        assert cmd.ctrl == sum(1 << CHANNELS.index(c) for c in channels)
        for c in CHANNELS:
            if c not in channels:
                started.pop(c, None)
                assert value(cmd, c) == getattr(pilot, c)  # manual: the pilot's stick
                continue
            if c not in started:  # handover instant: exactly the pilot's stick
                started[c] = (t, getattr(pilot, c) - getattr(controller, c))
                assert value(cmd, c) == getattr(pilot, c)
            t0, offset = started[c]
            weight = max(0.0, 1.0 - (t - t0) / blend)  # linear decay, closed form
            lo, hi = (0, 4096) if c == "thrust" else (-2048, 2047)  # spec 3.2 ranges
            ideal = min(hi, max(lo, getattr(controller, c) + offset * weight))
            assert abs(value(cmd, c) - ideal) <= 0.5
