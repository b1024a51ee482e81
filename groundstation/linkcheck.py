"""``gs link-check``: listen to the vehicle's serial link and say whether it is fit to fly.

The X-3D byte layout is a reconstruction (``docs/protocol.md``) and the LL dialect's
flags are partly unverified, so before anything is commanded the link is checked with
the propellers off: the port is opened exclusively (an ``flock``, as ``gs fly`` does),
the data stream is asked for (X-3D: a CONFIG; AscTec LL: polls) and whatever arrives is
reported. Nothing that moves the vehicle is ever written: no COMMAND, not even one with
ctrl mask 0 (a link that never commanded writes nothing on close, so a vehicle flown
by another ground station is left alone).

What is judged, each against the figure the flight itself uses where there is one:

* the DATA rate against ``serial.data_period_ms``: at least the rate the preflight
  requires (80 % of it, the supervisor's ``min_data_rate_hz``), and no
  silence as long as ``safety.link_loss_s`` (what a flight calls a lost link);
* rejected frame candidates by reason (CRC, end marker, length, ...): at most
  :data:`MAX_REJECTED_SHARE` of the frames; X-3D DATA of another block mask (the LL
  dialect's IMU_RAWDATA can pass for it) and, in the LL dialect, unanswered polls;
* the blocks present (gyro and acc on every sample; STATUS and RC where configured);
* the pilot's serial-enable switch (as ``--expect-switch`` says: on, the default, for a
  flight; off for the hand-back test), the channels the vehicle applies (0: nobody
  else commands it), the RC-link flag (a pilot to hand back to), the battery against
  ``safety.battery_land_v`` (the preflight waits below it);
* the IMU: a count at the ADC's limits (saturated) or the same count on every sample (a
  stuck sensor) is a fault; readings that are not those of a vehicle at rest (gyro
  beyond :data:`REST_GYRO_RAD_S`, specific force off ``g`` by more than
  :data:`REST_FORCE_TOLERANCE`) are a warning: the vehicle moved, or the zeros are not
  yet calibrated (``gs calibrate imu``).

:func:`run_link_check` does the I/O; :class:`LinkObserver` (sans-IO) accumulates the
DATA messages and :func:`assess` turns them and the link's counters into a
:class:`LinkCheckReport`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from groundstation.asctec.blocks import block_names
from groundstation.asctec.dialect import open_link
from groundstation.asctec.messages import DataMsg
from groundstation.asctec.stats import LinkStats
from groundstation.errors import LinkError
from groundstation.flight.params import FlightParams

__all__ = ["LinkCheckReport", "LinkObserver", "assess", "run_link_check"]

MAX_REJECTED_SHARE = 0.01
"""Most rejected frame candidates accepted, as a share of all frames: a serial line or
radio in order loses next to nothing, and each lost DATA frame is a missing IMU sample
(the thesis saw corrupted frames as repeated samples, Ch. 7.3)."""
MAX_UNANSWERED_SHARE = 0.05
"""AscTec LL: most polls left unanswered, as a share of the polls sent."""
REST_GYRO_RAD_S = 0.1
"""At rest the gyro's mean reads below this on every axis [rad/s] (Table 6.3's noise
averages to mrad/s; uncalibrated zeros of a few counts give a few hundredths)."""
REST_FORCE_TOLERANCE = 0.2
"""At rest the specific force reads g within this fraction, even through uncalibrated
zeros and scales (as ``gs calibrate imu`` requires)."""
CONFIG_RESEND_S = 0.5
"""X-3D: CONFIG is sent again after this long without DATA [s], as a flight does."""
ADC_RANGE = {"x3d": (0, 4095), "asctec-ll": (-32768, 32767)}
"""Raw IMU count limits per dialect: 12-bit unsigned (spec 3.3), int16 (LL IMU_RAWDATA)."""


class LinkObserver:
    """Accumulates the DATA messages of a link check (sans-IO: times are passed in).

    Keeps the receive times, the raw IMU counts, how many samples carried each block,
    and the last STATUS and RC blocks with the range of the pilot's sticks.
    """

    def __init__(self) -> None:
        self.times: list[float] = []
        self.counts: list[tuple[int, int, int, int, int, int]] = []
        self.blocks: dict[str, int] = {}
        self.status: tuple[int, int, int] | None = None  # battery [mV], flags, applied mask
        self.switch: bool | None = None
        self.switch_changes = 0
        self.sticks: list[tuple[int, int, int, int]] = []  # roll, pitch, yaw, thrust
        self.applied_masks: set[int] = set()
        self.low_battery_mv: int | None = None

    def add(self, t: float, msg: DataMsg) -> None:
        """One DATA message received at monotonic ``t`` [s]."""
        self.times.append(t)
        for name in block_names(msg.mask):
            self.blocks[name] = self.blocks.get(name, 0) + 1
        if msg.gyro is not None and msg.acc is not None:
            g, a = msg.gyro, msg.acc
            self.counts.append((g.x, g.y, g.z, a.x, a.y, a.z))
        if (s := msg.status) is not None:
            self.status = (s.battery_mv, s.flags, s.ctrl_mask)
            self.applied_masks.add(s.ctrl_mask)
            if self.low_battery_mv is None or s.battery_mv < self.low_battery_mv:
                self.low_battery_mv = s.battery_mv
        if (rc := msg.rc) is not None:
            if self.switch is not None and rc.serial_enabled != self.switch:
                self.switch_changes += 1
            self.switch = rc.serial_enabled
            self.sticks.append((rc.roll, rc.pitch, rc.yaw, rc.thrust))


@dataclass(frozen=True)
class LinkCheckReport:
    """What a link check heard and its verdict.

    protocol, port : the dialect and the serial port; seconds : time listened [s]
    samples : IMU samples received; data_rate_hz : their rate [Hz] from the first one to
    the end; expected_rate_hz : ``1000 / serial.data_period_ms``; min_rate_hz : what the
    preflight requires; longest_gap_s : longest silence after the first sample (the end
    included) [s]; first_data_s : from the request to the first sample [s]
    frames, rejections : accepted frames by message name, rejected candidates by reason
    blocks : samples that carried each DATA block; switch : the serial-enable switch (None:
    not reported); applied_mask : the ctrl mask the vehicle last reported applying;
    flags : its STATUS flags (None: no STATUS); battery_v : lowest voltage reported [V]
    gyro_mean [rad/s], acc_mean [m/s^2] : (3,) FRD means through the configured scaling
    pilot : the pilot's sticks (roll, pitch, yaw, thrust) mean, min and max [RC units]
    sent : what was written to the vehicle, by kind ("config", "poll", "command": never)
    reasons : why the link is not fit to fly (empty: healthy); warnings : what to look at
    stats : the link's own counters
    """

    protocol: str
    port: str
    seconds: float
    samples: int
    data_rate_hz: float
    expected_rate_hz: float
    min_rate_hz: float
    longest_gap_s: float
    first_data_s: float
    frames: dict[str, int]
    rejections: dict[str, int]
    blocks: dict[str, int]
    switch: bool | None
    applied_mask: int | None
    flags: int | None
    battery_v: float
    gyro_mean: tuple[float, float, float] | None
    acc_mean: tuple[float, float, float] | None
    pilot: dict[str, dict[str, float]]
    sent: dict[str, int]
    reasons: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    stats: LinkStats | None = field(default=None, repr=False)

    @property
    def healthy(self) -> bool:
        """No reason against flying."""
        return not self.reasons

    def to_json(self) -> dict[str, Any]:
        """The report as one JSON-ready object (units in the key names)."""
        return {
            "healthy": self.healthy, "reasons": self.reasons, "warnings": self.warnings,
            "protocol": self.protocol, "port": self.port, "seconds": self.seconds,
            "samples": self.samples, "data_rate_hz": self.data_rate_hz,
            "expected_rate_hz": self.expected_rate_hz, "min_rate_hz": self.min_rate_hz,
            "longest_gap_s": self.longest_gap_s, "first_data_s": self.first_data_s,
            "frames": self.frames, "rejections": self.rejections, "blocks": self.blocks,
            "serial_enable_switch": self.switch, "applied_ctrl_mask": self.applied_mask,
            "status_flags": self.flags,
            "battery_v": None if math.isnan(self.battery_v) else self.battery_v,
            "gyro_mean_rad_s": self.gyro_mean, "acc_mean_m_s2": self.acc_mean,
            "pilot_sticks": self.pilot, "sent": self.sent,
        }

    def lines(self) -> list[str]:
        """The report for people: one line per subject, then the verdict."""
        sent = ", ".join(f"{n} {k}{'s' if n != 1 else ''}" for k, n in self.sent.items() if n)
        never = "" if self.sent.get("command") else " (never a command)"
        out = [f"link check on {self.port} ({self.protocol}), {self.seconds:.1f} s listening; "
               f"sent: {sent or 'nothing'}{never}"]
        out.append(f"  DATA      {self.samples} samples, {self.data_rate_hz:.1f} Hz (configured "
                   f"{self.expected_rate_hz:g} Hz, a flight needs {self.min_rate_hz:g} Hz); "
                   f"first after {1e3 * self.first_data_s:.0f} ms, longest gap "
                   f"{1e3 * self.longest_gap_s:.0f} ms")
        frames = ", ".join(f"{k} {v}" for k, v in sorted(self.frames.items()) if v)
        rejected = ", ".join(f"{k} {v}" for k, v in sorted(self.rejections.items()))
        out.append(f"  frames    {sum(self.frames.values())} accepted ({frames or 'none'}); "
                   f"{sum(self.rejections.values())} rejected"
                   + (f" ({rejected})" if rejected else ""))
        out.append("  blocks    " + (", ".join(f"{k} {v}" for k, v in self.blocks.items())
                                     or "none"))
        switch = {None: "not reported", True: "ON", False: "OFF"}[self.switch]
        out.append(f"  switch    serial-enable {switch}")
        if self.flags is not None:
            flags, mask = self.flags, self.applied_mask or 0
            who = "a ground station commands it" if mask else "the pilot has every channel"
            out.append(f"  vehicle   applies ctrl mask 0x{mask:X} ({who}); motors "
                       f"{'on' if flags & 0x02 else 'off'}; RC link "
                       f"{'valid' if flags & 0x04 else 'NOT valid'}")
        if not math.isnan(self.battery_v):
            out.append(f"  battery   {self.battery_v:.2f} V (lowest reported)")
        if self.pilot:
            out.append("  pilot     " + ", ".join(
                f"{k} {v['mean']:.0f} [{v['min']:.0f}, {v['max']:.0f}]"
                for k, v in self.pilot.items()) + " (RC units: mean [min, max])")
        if self.gyro_mean is not None and self.acc_mean is not None:
            g, a = self.gyro_mean, self.acc_mean
            out.append(f"  IMU       gyro ({g[0]:+.3f}, {g[1]:+.3f}, {g[2]:+.3f}) rad/s, acc "
                       f"({a[0]:+.2f}, {a[1]:+.2f}, {a[2]:+.2f}) m/s^2, |acc| "
                       f"{math.sqrt(sum(x * x for x in a)):.2f} m/s^2 (means, FRD)")
        out += [f"  warning: {w}" for w in self.warnings]
        if self.healthy:
            out.append("verdict: healthy")
        else:
            out.append("verdict: NOT healthy: " + "; ".join(self.reasons))
        return out


def _gaps(times: list[float], end: float) -> float:
    """Longest silence after the first sample, the time from the last one to ``end``
    included [s]."""
    if not times:
        return math.inf
    t = np.asarray([*times, max(end, times[-1])], dtype=float)
    return float(np.max(np.diff(t))) if len(t) > 1 else 0.0


def _stick_ranges(sticks: list[tuple[int, int, int, int]]) -> dict[str, dict[str, float]]:
    if not sticks:
        return {}
    s = np.asarray(sticks, dtype=float)
    return {name: {"mean": float(s[:, k].mean()), "min": float(s[:, k].min()),
                   "max": float(s[:, k].max())}
            for k, name in enumerate(("roll", "pitch", "yaw", "thrust"))}


def _link_reasons(report_rate: float, min_rate: float, gap: float, loss_s: float,
                  stats: LinkStats, samples: int, protocol: str) -> list[str]:
    """Why the data stream itself is not fit to fly."""
    reasons: list[str] = []
    accepted = sum(stats.frames.values())
    rejected = sum(stats.rejections.values())
    if samples == 0:
        if stats.bytes_in == 0:
            reasons.append("no byte arrived: is the vehicle on, the radio paired, the port "
                           "(serial.port) right?")
        elif accepted == 0 and stats.rejections.get("bad_crc", 0) > 0:
            reasons.append("every frame fails its CRC: try serial.crc_profile kermit or "
                           "mcrf4xx (docs/protocol.md)")
        elif stats.unexpected_data:
            reasons.append(f"{stats.unexpected_data} DATA frames of another block mask: does "
                           "the vehicle speak the AscTec LL dialect (serial.protocol)?")
        else:
            reasons.append(f"{stats.bytes_in} bytes arrived but no IMU sample: check the baud "
                           "(serial.baud), 8N1, the radio in transparent mode and "
                           "serial.protocol")
        return reasons
    if report_rate < min_rate:
        reasons.append(f"DATA at {report_rate:.1f} Hz, below the {min_rate:g} Hz a flight "
                       "needs (radio range, baud, serial.sensors too many for the line)")
    if gap >= loss_s:
        reasons.append(f"the DATA stream stalled for {1e3 * gap:.0f} ms (a flight calls "
                       f"{1e3 * loss_s:.0f} ms a lost link: safety.link_loss_s)")
    if rejected > MAX_REJECTED_SHARE * (accepted + rejected):
        share = 100.0 * rejected / (accepted + rejected)
        by = ", ".join(f"{k} {v}" for k, v in sorted(stats.rejections.items()) if v)
        reasons.append(f"{rejected} frame candidates rejected ({share:.1f} % of the frames, "
                       f"at most {100 * MAX_REJECTED_SHARE:g} %: {by}): noise on the line "
                       "or the radio")
    if protocol == "x3d" and stats.unexpected_data:
        reasons.append(f"{stats.unexpected_data} DATA frames of another block mask than "
                       "configured: another configuration, or the AscTec LL dialect")
    if stats.polls_sent and stats.polls_unanswered > MAX_UNANSWERED_SHARE * stats.polls_sent:
        reasons.append(f"{stats.polls_unanswered} of {stats.polls_sent} polls unanswered "
                       f"(at most {100 * MAX_UNANSWERED_SHARE:g} %)")
    return reasons


def _imu_findings(obs: LinkObserver, params: FlightParams
                  ) -> tuple[list[str], list[str], tuple[float, float, float] | None,
                             tuple[float, float, float] | None]:
    """(reasons, warnings, gyro mean, acc mean) from the raw IMU counts."""
    if not obs.counts:
        return [], [], None, None
    reasons: list[str] = []
    warnings: list[str] = []
    c = np.asarray(obs.counts, dtype=float)
    lo, hi = ADC_RANGE.get(params.link.protocol, ADC_RANGE["x3d"])
    names = ("gyro x", "gyro y", "gyro z", "acc x", "acc y", "acc z")
    for k, name in enumerate(names):
        column = c[:, k]
        if np.any((column <= lo) | (column >= hi)):
            reasons.append(f"{name} reads {int(column.min())}..{int(column.max())}: at the "
                           f"limits of its range ({lo}..{hi}): saturated or disconnected")
        elif len(column) >= 50 and np.all(column == column[0]):
            reasons.append(f"{name} reads {int(column[0])} on every sample: a stuck or "
                           "disconnected sensor (a live one shows noise)")
    scaling = params.imu
    gyro = np.asarray(scaling.gyro.scale) * (c[:, :3].mean(axis=0) - np.asarray(
        scaling.gyro.zero))
    acc = np.asarray(scaling.acc.scale) * (c[:, 3:].mean(axis=0) - np.asarray(scaling.acc.zero))
    g = params.vehicle.g
    norm = float(np.linalg.norm(acc))
    if np.any(np.abs(gyro) > REST_GYRO_RAD_S):
        warnings.append(f"the gyro does not read rest (|mean| up to "
                        f"{float(np.max(np.abs(gyro))):.2f} rad/s, at rest < "
                        f"{REST_GYRO_RAD_S:g}): the vehicle moved, or vehicle.gyro_zero is "
                        "not calibrated (gs calibrate imu)")
    if abs(norm - g) > REST_FORCE_TOLERANCE * g:
        warnings.append(f"the accelerometer reads {norm:.2f} m/s^2, not g = {g:g} (within "
                        f"{100 * REST_FORCE_TOLERANCE:.0f} %): not at rest, or vehicle.acc_zero "
                        "/ acc_scale not calibrated (gs calibrate imu)")
    return (reasons, warnings, (float(gyro[0]), float(gyro[1]), float(gyro[2])),
            (float(acc[0]), float(acc[1]), float(acc[2])))


def _vehicle_findings(obs: LinkObserver, params: FlightParams,
                      expect_switch: bool) -> tuple[list[str], list[str]]:
    """(reasons, warnings) from the STATUS and RC blocks."""
    reasons: list[str] = []
    warnings: list[str] = []
    if obs.switch is None:
        warnings.append("the serial-enable switch is not reported (no RC block: add rc to "
                        "serial.sensors); a flight would assume it on")
    elif obs.switch != expect_switch:
        if obs.switch:
            reasons.append("the serial-enable switch is ON where OFF was expected (the "
                           "hand-back test: the pilot's switch must take the vehicle back)")
        else:
            reasons.append("the serial-enable switch is OFF: the vehicle ignores the ground "
                           "station; a flight would end in PILOT before take-off")
    if obs.switch_changes:
        warnings.append(f"the serial-enable switch changed {obs.switch_changes} times "
                        "while listening")
    if obs.status is None:
        warnings.append("no STATUS block: battery, the applied channels and the RC link "
                        "are not reported (add status to serial.sensors)")
        return reasons, warnings
    _, flags, _ = obs.status
    others = sorted(m for m in obs.applied_masks if m)
    if others or flags & 0x01:
        masks = ", ".join(f"0x{m:X}" for m in others) or "?"
        reasons.append(f"the vehicle applies ctrl mask {masks} while this check commands "
                       "nothing: another ground station is commanding it")
    if not flags & 0x04:
        reasons.append("the vehicle does not receive the pilot's transmitter (STATUS RC-link "
                       "flag clear): nobody to hand back to")
    land_v = params.supervisor.battery_land_v
    if obs.low_battery_mv is not None and land_v is not None \
            and 1e-3 * obs.low_battery_mv < land_v:
        reasons.append(f"battery at {1e-3 * obs.low_battery_mv:.2f} V, below "
                       f"safety.battery_land_v {land_v:g} V: the preflight would wait")
    return reasons, warnings


def assess(obs: LinkObserver, stats: LinkStats, params: FlightParams, *,
           seconds: float, start: float, end: float, sent: dict[str, int],
           expect_switch: bool = True, failure: str | None = None) -> LinkCheckReport:
    """Judge a link check (see the module docstring).

    obs : the DATA received; stats : the link's counters at the end; seconds : the
    listening time [s]; start, end : monotonic times of the stream request and the end
    [s]; sent : what was written, by kind; expect_switch : the serial-enable switch
    position a healthy link shows; failure : the link's own failure, if it failed
    """
    link = params.link
    expected = 1000.0 / link.data_period_ms
    min_rate = params.supervisor.min_data_rate_hz
    samples = len(obs.times)
    rate = samples / (end - obs.times[0]) if samples and end > obs.times[0] else 0.0
    gap = _gaps(obs.times, end)
    reasons = [f"the serial link failed: {failure}"] if failure else []
    if sent.get("command"):  # nothing here sends one: this would be a bug, and loud
        reasons.append(f"{sent['command']} commands were written during a listen-only check")
    reasons += _link_reasons(rate, min_rate, gap, params.supervisor.link_loss_s, stats,
                             samples, link.protocol)
    imu_reasons, imu_warnings, gyro, acc = _imu_findings(obs, params)
    vehicle_reasons, vehicle_warnings = _vehicle_findings(obs, params, expect_switch)
    status = obs.status
    return LinkCheckReport(
        protocol=link.protocol, port=link.port, seconds=seconds, samples=samples,
        data_rate_hz=rate, expected_rate_hz=expected, min_rate_hz=min_rate,
        longest_gap_s=gap if samples else math.inf,
        first_data_s=obs.times[0] - start if samples else math.inf,
        frames=dict(stats.frames), rejections={k: v for k, v in stats.rejections.items() if v},
        blocks=dict(obs.blocks), switch=obs.switch,
        applied_mask=status[2] if status is not None else None,
        flags=status[1] if status is not None else None,
        battery_v=1e-3 * obs.low_battery_mv if obs.low_battery_mv is not None else math.nan,
        gyro_mean=gyro, acc_mean=acc, pilot=_stick_ranges(obs.sticks), sent=dict(sent),
        reasons=reasons + imu_reasons + vehicle_reasons,
        warnings=imu_warnings + vehicle_warnings, stats=stats)


def run_link_check(params: FlightParams, seconds: float, *,
                   expect_switch: bool = True) -> LinkCheckReport:
    """Open the configured link, ask for the data stream, listen for ``seconds`` [s] and
    judge what arrived (:func:`assess`). Only the stream request is ever written (X-3D:
    CONFIG, again after :data:`CONFIG_RESEND_S` of silence; LL: polls).

    Raises LinkError if the port cannot be opened (absent, no permission, in use by a
    flight: the port is locked as ``gs fly`` locks it); a link failing while listening
    is a reason in the report.
    """
    x3d = params.link.protocol != "asctec-ll"
    obs = LinkObserver()
    failure: str | None = None
    configs = 0
    with open_link(params.link) as link:
        start = time.monotonic()  # the clock of the links' receive times
        end = start + seconds
        try:
            link.start_stream()
            configs += 1
            asked = last = start
            while (now := time.monotonic()) < end:
                rx = link.get(min(0.05, end - now))
                if rx is not None:
                    obs.add(rx.t, rx.msg)
                    last = rx.t
                elif x3d and now - max(last, asked) > CONFIG_RESEND_S:
                    link.start_stream()  # the stream stopped or never started: ask again
                    configs += 1
                    asked = now
        except LinkError as exc:
            failure = str(exc)
            end = min(time.monotonic(), end)
        stats = link.stats()
    # commands_sent is 0: nothing here sends one (the report would show it otherwise)
    sent = {"config": configs} if x3d else {"poll": stats.polls_sent}
    sent["command"] = stats.commands_sent
    return assess(obs, stats, params, seconds=seconds, start=start, end=end, sent=sent,
                  expect_switch=expect_switch, failure=failure)
