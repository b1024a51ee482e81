"""COMMAND keep-alive policy (sans-IO, simulated time): rate guarantee, stale hand-back,
gap bookkeeping and warnings."""

from __future__ import annotations

import itertools

import pytest
from structlog.testing import capture_logs

from groundstation.asctec.keepalive import GAP_WARNING_S, WATCHDOG_S, CommandSchedule
from groundstation.asctec.messages import CommandMsg
from groundstation.errors import ConfigError

LOOP_CMD = CommandMsg(pitch=10, roll=-20, yaw=5, thrust=2100, ctrl=0x0F)
RELEASE = CommandMsg(0, 0, 0, 0, 0)


def test_watchdog_constants_match_the_spec() -> None:
    assert WATCHDOG_S == 0.1  # spec section 4: 100 ms
    assert GAP_WARNING_S == 0.05  # half of it


def simulate(
    schedule: CommandSchedule, loop_times: list[float], t_end: float
) -> list[tuple[float, CommandMsg, str]]:
    """Drive the schedule like the sender thread would, with exact wake-ups.

    The loop writes LOOP_CMD at ``loop_times``; the keep-alive wakes at each deadline.
    Returns (time, command, "loop" | "keepalive") for every write, in time order.
    """
    writes: list[tuple[float, CommandMsg, str]] = []
    pending = sorted(loop_times)
    schedule.arm(0.0)
    while True:
        deadline = schedule.next_deadline()
        assert deadline is not None
        if pending and pending[0] <= deadline:
            t = pending.pop(0)
            schedule.loop_command(LOOP_CMD, t)
            schedule.record_write(t)
            writes.append((t, LOOP_CMD, "loop"))
            continue
        if deadline > t_end:
            return writes
        msg = schedule.due(deadline)
        assert msg is not None  # due exactly at its deadline
        schedule.record_write(deadline)
        writes.append((deadline, msg, "keepalive"))


def test_keepalive_fills_in_for_a_silent_loop_then_hands_back() -> None:
    # 50 Hz guarantee, loop writes at 20 Hz until 0.5 s and then dies; stale after 0.25 s.
    schedule = CommandSchedule(command_rate=50.0, stale_after=0.25)
    loop_times = [0.05 * k for k in range(1, 11)]  # 0.05 .. 0.50
    writes = simulate(schedule, loop_times, t_end=1.0)
    times = [t for t, _, _ in writes]
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert max(gaps) <= 0.02 + 1e-12  # never longer than 1 / command_rate
    assert schedule.max_gap == pytest.approx(max(gaps))
    # Armed at 0 with no loop command yet: the first keep-alive is the hand-back.
    assert writes[0] == (0.0, RELEASE, "keepalive")
    for t, msg, source in writes[1:]:
        if source == "keepalive":
            previous = [tl for tl in loop_times if tl <= t]
            fresh = bool(previous) and t - previous[-1] < 0.25
            # Fresh: the loop's last command is repeated; none yet or stale: mask 0.
            assert msg == (LOOP_CMD if fresh else RELEASE), t
    last_loop = loop_times[-1]
    stale = [t for t, msg, _ in writes if msg == RELEASE and t > last_loop]
    assert stale and min(stale) >= last_loop + 0.25
    early = [t for t, msg, _ in writes if msg == RELEASE and t < loop_times[0]]
    assert early == [0.0, 0.02, 0.04]  # before the loop's first command at 0.05
    assert schedule.releases == len(stale) + len(early)
    assert schedule.resends == sum(1 for _, m, s in writes if s == "keepalive" and m == LOOP_CMD)


def test_a_loop_faster_than_the_rate_needs_no_keepalive() -> None:
    schedule = CommandSchedule(command_rate=50.0)
    writes = simulate(schedule, [0.0 + 0.01 * k for k in range(100)], t_end=0.99)
    assert [s for _, _, s in writes] == ["loop"] * 100
    assert schedule.resends == schedule.releases == 0


def test_disarmed_schedule_sends_nothing() -> None:
    schedule = CommandSchedule(command_rate=50.0)
    assert schedule.next_deadline() is None
    assert schedule.due(123.0) is None
    schedule.arm(1.0)
    assert schedule.armed
    schedule.disarm()
    assert schedule.due(5.0) is None


def test_gap_warning_and_max_gap_only_while_armed() -> None:
    schedule = CommandSchedule(command_rate=50.0)
    with capture_logs() as logs:
        schedule.record_write(0.0)
        schedule.record_write(0.5)  # disarmed: a long gap is expected, no warning
        schedule.arm(1.0)
        schedule.record_write(1.0)
        schedule.record_write(1.03)
        assert schedule.record_write(1.09) == pytest.approx(0.06)  # > 50 ms
    warnings = [e for e in logs if e["log_level"] == "warning"]
    assert len(warnings) == 1
    assert warnings[0]["gap_s"] == pytest.approx(0.06)
    assert schedule.gap_warnings == 1
    assert schedule.max_gap == pytest.approx(0.06)
    assert schedule.write_times() == (0.0, 0.5, 1.0, 1.03, 1.09)
    assert schedule.commands_sent == 5


@pytest.mark.parametrize(("rate", "stale"), [(10.0, 0.25), (5.0, 0.25), (50.0, 0.0)])
def test_unsafe_parameters_are_refused(rate: float, stale: float) -> None:
    # A period of 100 ms or more would let the 100 ms watchdog fire between commands.
    with pytest.raises(ConfigError):
        CommandSchedule(command_rate=rate, stale_after=stale)


def test_slack_lets_a_jittering_loop_send_its_own_commands() -> None:
    """A loop at 50 Hz whose COMMANDs follow jittering DATA frames (20 ms +- 2 ms) raced
    the keep-alive, which then wrote a copy just before the loop's own; with one DATA
    period (10 ms) of slack the keep-alive writes only for a loop that missed a tick."""
    jitter = [0.002 * ((-1) ** k) for k in range(50)]
    loop_times = [0.02 * k + j for k, j in enumerate(jitter, start=1)]
    racing = CommandSchedule(command_rate=50.0)
    assert any(s == "keepalive" for _, _, s in simulate(racing, loop_times, t_end=1.0))
    slack = CommandSchedule(command_rate=50.0, slack=0.01)
    writes = simulate(slack, [0.0, *loop_times], t_end=1.0)
    assert [s for _, _, s in writes] == ["loop"] * 51
    silent = CommandSchedule(command_rate=50.0, slack=0.01)
    writes = simulate(silent, [0.0, 0.02, 0.04], t_end=0.2)
    keepalive = [t for t, _, s in writes if s == "keepalive"]
    assert keepalive[0] == pytest.approx(0.07) and max(
        b - a for a, b in itertools.pairwise(t for t, _, _ in writes)) == pytest.approx(0.03)
    with pytest.raises(ConfigError):
        CommandSchedule(command_rate=20.0, slack=0.05)  # 100 ms: the watchdog itself
