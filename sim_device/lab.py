"""The virtual lab in-process: plant, firmware, radio and Vicon on a simulated clock.

:class:`VirtualLab` is the one simulation both modes run: tests and evaluations
drive it directly, faster than real time and deterministically for a seed;
:func:`sim_device.realtime.run_sim_device` drives the same object from the wall
clock and moves its bytes over a pty and UDP.

Scheduling: simulated time is integer nanoseconds, advanced in fixed plant
steps of ``dt``. At each step boundary, in this order: bytes that reached the
vehicle are decoded, the firmware arbitrates the channels (watchdog), a DATA
sample and a Vicon datagram are taken if due, the truth log records if due;
then the plant steps. Events due between two boundaries happen at the next one
(a 500 Hz scheduler, like the firmware's loop); periodic deadlines advance by
their period, so they never drift.

Example::

    lab = VirtualLab(seed=3)
    lab.send(ConfigMsg(sensor_mask=0x07, period_ms=10))
    lab.send(CommandMsg(thrust=2100, ctrl=0x0F))
    for t, msg in lab.advance_messages(0.05):   # DATA messages received by t
        ...
    for d in lab.vicon_datagrams():             # UDP payloads delivered so far
        ...
    lab.truth.position                          # the true NED position [m]

With ``serial.protocol: asctec-ll`` (``LinkParams.protocol``) the vehicle speaks the
AscTec LL dialect (:class:`sim_device.ll_firmware.LlFirmware`): it sends only what is
polled, and acknowledges each command::

    lab = VirtualLab(apply_overrides(cfg, {"serial.protocol": "asctec-ll"}))
    lab.poll(PollMask.IMU_RAWDATA | PollMask.LL_STATUS)
    lab.send(CommandMsg(thrust=2100, ctrl=0x0F))     # sent as ``>*>di`` + payload
    for t, packet in lab.advance_packets(0.05):      # LlStatus, ImuRawData, ..., Ack
        ...
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from groundstation.asctec.decoder import Ack, RejectedFrame, StreamDecoder, encode_frame
from groundstation.asctec.ll import LlDecoder, LlMessage, encode_command, encode_poll
from groundstation.asctec.messages import CommandMsg, DataMsg, Message
from groundstation.types import Sticks
from sim_device.firmware import Firmware
from sim_device.imu import ImuModel
from sim_device.link import ByteCorrupter, Downlink, Uplink, seconds_to_ns
from sim_device.ll_firmware import LlFirmware
from sim_device.params import LabParams, LossEncoding
from sim_device.pilot import Pilot, StickScript
from sim_device.plant import Plant
from sim_device.truth import TruthLog, TruthState, snapshot
from sim_device.vicon import ViconDatagram, VirtualVicon

if TYPE_CHECKING:
    from groundstation.config import GroundStationConfig

@dataclass(frozen=True, slots=True)
class LabStats:
    """Counters of one lab run (for tests, benchmarks and the real-time summary).

    data_sent : DATA frames put on the wire (LL dialect: answers and acknowledgements);
        data_dropped : of those, lost by the radio
    samples_busy : DATA samples skipped because the UART was still busy (baud limit; LL:
        answers that did not fit the transmit buffer)
    samples_stalled : DATA samples not taken during a stall (LL: polls not answered)
    bits_flipped : corrupted bytes, both directions
    commands, configs : valid COMMAND / CONFIG frames the vehicle accepted (LL: configs 0)
    uplink_rejected : rejected frame candidates on the uplink, by reason
    handbacks : times the applied ctrl mask fell to 0 (watchdog, switch or a mask-0 COMMAND)
    vicon_sent, vicon_lost : datagrams sent, and of those without a tracked pose
    polls : LL dialect: polls the vehicle received (X-3D: 0)
    """

    t: float
    data_sent: int
    data_dropped: int
    samples_busy: int
    samples_stalled: int
    bits_flipped: int
    commands: int
    configs: int
    uplink_rejected: dict[str, int]
    handbacks: int
    vicon_sent: int
    vicon_lost: int
    polls: int = 0


class VirtualLab:
    """The virtual X-3D (X-3D or AscTec LL dialect) and virtual Vicon on a simulated clock
    (see the module docstring).

    params : :class:`LabParams`, a :class:`~groundstation.config.GroundStationConfig`
        (its ``sim`` section and the vehicle model), or None for the defaults
    seed : overrides ``params.seed``; one seed gives one run, bit for bit
    """

    def __init__(self, params: LabParams | GroundStationConfig | None = None,
                 seed: int | None = None) -> None:
        if params is None:
            params = LabParams()
        elif not isinstance(params, LabParams):
            params = LabParams.from_config(params)
        self.params = params
        self.seed = params.seed if seed is None else seed
        rng_imu, rng_vicon, rng_up, rng_down, rng_drop = (
            np.random.default_rng(s) for s in np.random.SeedSequence(self.seed).spawn(5))
        self._dt_ns = seconds_to_ns(params.dt)
        self._t_ns = 0  # plant state time
        self._goal_ns = 0  # time the caller advanced to (<= _t_ns, < _t_ns + dt)
        self.plant = Plant(params.plant, self._dt_ns * 1e-9)
        self.pilot = Pilot(params.pilot)
        self._corrupt_up = ByteCorrupter(params.faults.corruption_rate, rng_up)
        self._corrupt_down = ByteCorrupter(params.faults.corruption_rate, rng_down)
        self.uplink = Uplink(params.link.baud, seconds_to_ns(params.link.command_delay),
                             self._corrupt_up)
        self.downlink = Downlink(params.link.baud, self._corrupt_down, rng_drop)
        firmware = LlFirmware if params.link.protocol == "asctec-ll" else Firmware
        self.firmware: Firmware | LlFirmware = firmware(
            params.link, self.plant, ImuModel(params.imu, rng_imu), self.pilot, self.downlink)
        self.vicon = VirtualVicon(params.vicon, rng_vicon)
        self.truth_log = TruthLog()
        self._truth_ns = seconds_to_ns(params.truth_period)
        self._next_truth_ns = 0
        self._ground_decoder = StreamDecoder(params.link.crc_profile)
        self._ll_decoder = LlDecoder(params.link.crc_profile)
        self._vicon_out: list[ViconDatagram] = []
        self.set_faults(drop_rate=params.faults.drop_rate, data_delay=params.faults.data_delay,
                        burst_delay_s=params.faults.burst_delay_s)
        if params.faults.stall_at is not None:
            self.stall_data(params.faults.stall_duration, start=params.faults.stall_at)
        self.firmware.update_control(0)

    # ------------------------------------------------------------------ time
    @property
    def t(self) -> float:
        """Simulated time the lab has been advanced to [s]."""
        return self._goal_ns * 1e-9

    @property
    def dt(self) -> float:
        """Plant step [s]."""
        return self._dt_ns * 1e-9

    def advance(self, dt: float) -> list[tuple[float, bytes]]:
        """Run ``dt`` seconds; return the serial bytes the ground station received meanwhile.

        Each item is (delivery time [s], one DATA frame's bytes as received, faults
        included), in order; a frame still on the wire at the end waits for a later call.
        """
        return self.advance_to(self.t + dt)

    def advance_to(self, t: float) -> list[tuple[float, bytes]]:
        """Run until simulated time ``t`` [s] (no-op if in the past); see :meth:`advance`."""
        goal = max(self._goal_ns, seconds_to_ns(t))
        self._run(goal)
        self._goal_ns = goal
        self._vicon_out.extend(self.vicon.pop_due(goal))
        return [(t_ns * 1e-9, data) for t_ns, data in self.downlink.pop_due(goal)]

    @property
    def protocol(self) -> str:
        """The dialect the vehicle speaks: "x3d" or "asctec-ll"."""
        return self.params.link.protocol

    def advance_messages(self, dt: float) -> list[tuple[float, DataMsg]]:
        """Like :meth:`advance` but decoded with the project's decoder: (time [s], DataMsg).

        Corrupted frames are rejected by the decoder and simply missing here. X-3D dialect
        only (an LL vehicle's packets are :meth:`advance_packets`).
        """
        self._require_protocol("x3d", "advance_messages", "advance_packets")
        out: list[tuple[float, DataMsg]] = []
        for t, data in self.advance(dt):
            out.extend((t, m) for m in self._ground_decoder.feed(data) if isinstance(m, DataMsg))
        return out

    def advance_packets(self, dt: float) -> list[tuple[float, LlMessage | Ack]]:
        """Like :meth:`advance` but decoded with the LL dialect's host decoder
        (:class:`~groundstation.asctec.ll.LlDecoder`): (time [s], packet or Ack).

        AscTec LL dialect only; corrupted frames are rejected and simply missing here.
        """
        self._require_protocol("asctec-ll", "advance_packets", "advance_messages")
        out: list[tuple[float, LlMessage | Ack]] = []
        for t, data in self.advance(dt):
            out.extend((t, m) for m in self._ll_decoder.feed(data)
                       if not isinstance(m, RejectedFrame))
        return out

    def _require_protocol(self, protocol: str, method: str, other: str) -> None:
        if self.protocol != protocol:
            raise RuntimeError(f"{method}: the virtual vehicle speaks {self.protocol}, "
                               f"not {protocol} (serial.protocol); use {other}")

    def _run(self, goal_ns: int) -> None:
        """Step the plant until its time reaches ``goal_ns``, handling events at each boundary."""
        plant, fw, up, vicon = self.plant, self.firmware, self.uplink, self.vicon
        dt_ns = self._dt_ns
        t_ns = self._t_ns
        while t_ns < goal_ns:
            due = up.next_due_ns
            if due is not None and due <= t_ns:
                fw.receive(t_ns, up.pop_due(t_ns))
            fw.update_control(t_ns)
            nxt = fw.next_sample_ns
            if nxt is not None and nxt <= t_ns:
                fw.sample(t_ns)
            if vicon.next_ns <= t_ns:
                vicon.sample(t_ns, plant)
            if self._next_truth_ns <= t_ns:
                self.truth_log.record(plant, fw.applied, fw.applied_mask)
                self._next_truth_ns += self._truth_ns
            plant.step()
            t_ns += dt_ns
            plant.t = t_ns * 1e-9
        self._t_ns = t_ns

    # ------------------------------------------------------------------ ground -> vehicle
    def write(self, data: bytes) -> None:
        """Bytes from the ground station at the current time :attr:`t` (paced, delayed)."""
        self.uplink.write(self._goal_ns, data)

    def send(self, msg: Message) -> None:
        """Encode ``msg`` with the project's codec and :meth:`write` it.

        In the AscTec LL dialect a COMMAND goes out as ``>*>di`` + its payload
        (:func:`~groundstation.asctec.ll.encode_command`); any other message is framed as
        in the X-3D dialect (the LL vehicle ignores it).
        """
        if self.protocol == "asctec-ll" and isinstance(msg, CommandMsg):
            self.write(encode_command(msg))
        else:
            self.write(encode_frame(msg, self.params.link.crc_profile))

    def poll(self, mask: int) -> None:
        """Write an LL poll ``>*>p`` + ``mask`` (:class:`~groundstation.asctec.ll.PollMask`
        bits); an X-3D vehicle ignores it."""
        self.write(encode_poll(mask))

    def vicon_datagrams(self) -> list[ViconDatagram]:
        """Vicon datagrams delivered since the last call, in order."""
        out, self._vicon_out = self._vicon_out, []
        return out

    # ------------------------------------------------------------------ truth
    @property
    def truth(self) -> TruthState:
        """The current true state (at the plant's step time, ``truth.t``)."""
        return snapshot(self.plant, self.firmware.applied, self.firmware.applied_mask)

    def place(self, position: Sequence[float], yaw: float = 0.0, *,
              quaternion: Sequence[float] | None = None,
              velocity_body: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        """Put the vehicle at ``position`` (NED [m]) with attitude ``quaternion`` (scalar
        first) or level at ``yaw`` [rad], moving at ``velocity_body`` (FRD [m/s]).

        Rates and lift are set to their current set points (no start-up transient).
        A position with z >= 0 rests on the floor.
        """
        p = self.plant
        self.firmware.update_control(self._t_ns)
        if quaternion is None:
            quaternion = (np.cos(0.5 * yaw), 0.0, 0.0, np.sin(0.5 * yaw))
        q = np.asarray(quaternion, dtype=float)
        q = q / np.linalg.norm(q)
        p.px, p.py, p.pz = (float(v) for v in position)
        p.q0, p.q1, p.q2, p.q3 = (float(v) for v in q)
        p.vx, p.vy, p.vz = (float(v) for v in velocity_body)
        p.wx, p.wy, p.wz = p.wx_sp, p.wy_sp, p.wz_sp
        p.lift = p.lift_sp
        p.on_ground = False
        if p.pz >= 0.0:
            p.land()

    # ------------------------------------------------------------------ pilot and faults
    def set_pilot(self, sticks: Sticks | None = None, *, serial_enable: bool | None = None,
                  rc_link: bool | None = None) -> None:
        """Change the pilot's held sticks, serial-enable switch or RC link (next step)."""
        if sticks is not None:
            self.pilot.sticks = sticks
        if serial_enable is not None:
            self.pilot.serial_enable = serial_enable
        if rc_link is not None:
            self.pilot.rc_link = rc_link

    def set_pilot_script(self, script: StickScript | None) -> None:
        """Let the pilot's sticks follow ``script(t)`` (t simulated [s]); None = held sticks."""
        self.pilot.script = script

    def stall_data(self, duration: float, start: float | None = None) -> None:
        """Stop the DATA stream for ``duration`` [s] from ``start`` (default: now); an LL
        vehicle answers no poll meanwhile (it still applies and acknowledges commands)."""
        begin = self._goal_ns if start is None else seconds_to_ns(start)
        self.firmware.stalls.append((begin, begin + seconds_to_ns(duration)))

    def thrust_fault(self, lift_scale: float, duration: float,
                     start: float | None = None) -> None:
        """The rotors give ``lift_scale`` times their lift for ``duration`` [s] from ``start``
        (default: now): a motor or ESC fault the ground station does not command."""
        self.plant.add_thrust_fault(self.t if start is None else start, duration, lift_scale)

    def vicon_outage(self, duration: float, start: float | None = None) -> None:
        """Lose Vicon tracking for ``duration`` [s] from ``start`` (default: now)."""
        self.vicon.add_outage(self.t if start is None else start, duration)

    def pause_vicon(self, duration: float, start: float | None = None) -> None:
        """Send no Vicon datagram at all for ``duration`` [s] from ``start`` (default: now);
        Tracker's frame number keeps counting (see :meth:`VirtualVicon.add_pause`)."""
        self.vicon.add_pause(self.t if start is None else start, duration)

    def inject_vicon(self, datagrams: Sequence[tuple[float, bytes]]) -> None:
        """Deliver foreign datagrams ``(t [s], bytes)`` among Vicon's own, as another sender
        on the Vicon port would (see :func:`sim_device.vicon.foreign_stream`)."""
        for t, data in datagrams:
            self.vicon.inject(t, data)

    def set_vicon(self, *, rate_hz: float | None = None,
                  loss_encoding: LossEncoding | None = None, noise: bool | None = None) -> None:
        """Change the Vicon rate [Hz], loss encoding or noise at run time."""
        if rate_hz is not None:
            self.vicon.set_rate(rate_hz)
        if loss_encoding is not None:
            self.vicon.loss_encoding = loss_encoding
        if noise is not None:
            self.vicon.noise = noise

    def set_faults(self, *, corruption_rate: float | None = None,
                   drop_rate: float | None = None, data_delay: float | None = None,
                   burst_delay_s: float | None = None) -> None:
        """Change link faults at run time (see :class:`~sim_device.params.FaultParams`)."""
        if corruption_rate is not None:
            self._corrupt_up.set_rate(corruption_rate)
            self._corrupt_down.set_rate(corruption_rate)
        if drop_rate is not None:
            self.downlink.drop_rate = drop_rate
        if data_delay is not None:
            self.downlink.delay_ns = seconds_to_ns(data_delay)
        if burst_delay_s is not None:
            self.downlink.burst_ns = seconds_to_ns(burst_delay_s)

    def stats(self) -> LabStats:
        """A snapshot of the counters."""
        fw = self.firmware
        return LabStats(
            t=self.t, data_sent=self.downlink.frames_sent,
            data_dropped=self.downlink.frames_dropped, samples_busy=fw.samples_busy,
            samples_stalled=fw.samples_stalled,
            bits_flipped=self._corrupt_up.flipped + self._corrupt_down.flipped,
            commands=fw.commands, configs=fw.configs,
            uplink_rejected={k: v for k, v in fw.decoder.counts().rejections.items() if v},
            handbacks=fw.handbacks, vicon_sent=self.vicon.sent, vicon_lost=self.vicon.lost,
            polls=fw.polls if isinstance(fw, LlFirmware) else 0,
        )
