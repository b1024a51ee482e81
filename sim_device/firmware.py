"""The vehicle side of the X-3D serial protocol (``docs/protocol.md``).

What the ResearchPilot-style firmware does with the messages the project's own
codec (:mod:`groundstation.asctec`) reads and writes:

* **CONFIG** sets the DATA block mask and period; period 0 stops the stream. A
  running stream keeps its phase, a stopped one starts at the next step.
* **COMMAND** (valid frames only: CRC, checksum and ranges are the decoder's)
  stores the command and feeds the watchdog.
* **Watchdog** (spec 4): while the last valid COMMAND is younger than 100 ms and
  the pilot's serial-enable switch is on, the channels whose ctrl bit is set take
  the command's value; every other channel, and every channel otherwise, takes
  the pilot's stick. STATUS reports the applied ctrl mask; flag bit0 is set
  while that mask is non-zero.
* **DATA** every period: the selected blocks from the plant's true state
  through the IMU model. The UART sends one frame at a time, so a sample that
  falls while the previous frame is still on the wire is skipped: a selection
  that does not fit the baud arrives at a lower rate, as on the radio. The
  sample counter counts frames sent (lost-in-the-radio frames leave gaps).

Applied sticks become plant set points: ``omega = K * (roll, pitch, yaw)``
(eq. 3.22) and ``lift = thrust_scale * F_lift(thrust)`` (eq. 3.7); thrust 0 stops
the motors.

The command store, watchdog, arbitration and plant inputs are :class:`FirmwareCore`,
which the AscTec LL dialect's firmware (:mod:`sim_device.ll_firmware`) shares.
"""

from __future__ import annotations

from typing import ClassVar

from groundstation.asctec.blocks import AxisCounts, RcBlock, StatusBlock
from groundstation.asctec.decoder import StreamDecoder, encode_frame
from groundstation.asctec.messages import CommandMsg, ConfigMsg, DataMsg
from groundstation.types import Sticks
from sim_device.imu import ImuModel
from sim_device.link import Downlink, seconds_to_ns
from sim_device.params import LinkParams
from sim_device.pilot import Pilot
from sim_device.plant import Plant

FLAG_SERIAL_ACTIVE = 0x01
FLAG_MOTORS_ON = 0x02
FLAG_RC_VALID = 0x04
SWITCH_ON = 4095
"""RC block serial-enable switch value when on (spec: > 2048 = enabled)."""
SWITCH_OFF = 0

BIT_PITCH, BIT_ROLL, BIT_YAW, BIT_THRUST = 0x1, 0x2, 0x4, 0x8
_NEVER = 1 << 62


def _clamp(value: int, lo: int, hi: int) -> int:
    return lo if value < lo else hi if value > hi else value


class FirmwareCore:
    """What every dialect's vehicle firmware shares: the last valid command, the watchdog,
    the per-channel arbitration (command vs pilot) and the plant's inputs.

    link : link/firmware parameters; plant, imu, pilot : the simulated hardware;
    downlink : the UART and radio towards the ground station. A dialect adds
    ``receive(t_ns, data)``, ``sample(t_ns)`` and a ``decoder`` with ``counts()``.
    """

    THRUST_MAX: ClassVar[int] = 4096
    """Largest applied thrust [RC units] (the X-3D's COMMAND range)."""

    def __init__(self, link: LinkParams, plant: Plant, imu: ImuModel, pilot: Pilot,
                 downlink: Downlink) -> None:
        self.params = link
        self.plant = plant
        self.imu = imu
        self.pilot = pilot
        self.downlink = downlink
        self._profile = link.crc_profile
        self._watchdog_ns = seconds_to_ns(link.watchdog)
        self.command: CommandMsg | None = None
        self.last_command_ns: int | None = None
        self.next_sample_ns: int | None = None  # next pushed sample [ns]; None = none due
        self.stalls: list[tuple[int, int]] = []  # (start, end) [ns] without data
        self.applied = Sticks()
        self.applied_mask = 0
        self._expiry_ns = 0  # next time the arbitration must be redone [ns]
        self._seen_sticks: Sticks | None = None
        self._seen_switch: bool | None = None
        self.configs = 0
        self.commands = 0
        self.uplink_ignored = 0
        self.samples_busy = 0
        self.samples_stalled = 0
        self.handbacks = 0
        plant.set_inputs(0.0, 0.0, 0.0, 0.0)

    def _command(self, t_ns: int, cmd: CommandMsg) -> None:
        """A valid command arrived at ``t_ns`` [ns]: store it, feed the watchdog."""
        self.command = cmd
        self.last_command_ns = t_ns
        self.commands += 1
        self._expiry_ns = t_ns  # re-arbitrate at this step

    def stalled(self, t_ns: int) -> bool:
        """``t_ns`` [ns] falls in a configured stall (the vehicle sends no data)."""
        return any(begin <= t_ns < end for begin, end in self.stalls)

    # ------------------------------------------------------------------ control
    def serial_alive(self, t_ns: int) -> bool:
        """A valid COMMAND arrived less than the watchdog time before ``t_ns``."""
        last = self.last_command_ns
        return last is not None and t_ns - last < self._watchdog_ns

    def update_control(self, t_ns: int) -> None:
        """Arbitrate every channel (command vs pilot) and pass changes to the plant.

        Fast path: nothing to do while no command arrived, the pilot's sticks and
        switch are the same objects/values as last time (no script) and the
        watchdog has not expired.
        """
        pilot_state = self.pilot
        if (t_ns < self._expiry_ns and pilot_state.script is None
                and pilot_state.sticks is self._seen_sticks
                and pilot_state.serial_enable is self._seen_switch):
            return
        cmd = self.command
        mask = 0
        if cmd is not None and pilot_state.serial_enable and self.serial_alive(t_ns):
            mask = cmd.ctrl
        if self.applied_mask & BIT_THRUST and not mask & BIT_THRUST and not self.plant.on_ground:
            pilot_state.take_over_thrust(self.applied.thrust)
        if self.applied_mask and not mask:
            self.handbacks += 1
        self.applied_mask = mask
        last = self.last_command_ns
        self._expiry_ns = last + self._watchdog_ns if mask and last is not None else _NEVER
        self._seen_sticks = pilot_state.sticks
        self._seen_switch = pilot_state.serial_enable
        applied = self._arbitrate(mask, pilot_state.sticks_at(t_ns * 1e-9))
        if applied != self.applied:
            self._apply(applied)

    def _arbitrate(self, mask: int, pilot: Sticks) -> Sticks:
        """Command values on the channels in ``mask``, the pilot's sticks on the others."""
        cmd = self.command
        if not mask or cmd is None:
            return pilot
        return Sticks(
            roll=cmd.roll if mask & BIT_ROLL else pilot.roll,
            pitch=cmd.pitch if mask & BIT_PITCH else pilot.pitch,
            yaw=cmd.yaw if mask & BIT_YAW else pilot.yaw,
            thrust=cmd.thrust if mask & BIT_THRUST else pilot.thrust,
        )

    def _apply(self, sticks: Sticks) -> None:
        roll = _clamp(sticks.roll, -2048, 2047)
        pitch = _clamp(sticks.pitch, -2048, 2047)
        yaw = _clamp(sticks.yaw, -2048, 2047)
        thrust = _clamp(sticks.thrust, 0, self.THRUST_MAX)
        self.applied = Sticks(roll=roll, pitch=pitch, yaw=yaw, thrust=thrust)
        kx, ky, kz = self.plant.params.k_rate
        self.plant.set_inputs(kx * roll, ky * pitch, kz * yaw, self.plant.lift_command(thrust))

    def _battery_mv(self) -> int:
        """The battery voltage now [mV]: full voltage drooping with the lift."""
        return min(0xFFFF, round(self.params.battery_mv * self.plant.battery_factor()))


class Firmware(FirmwareCore):
    """The X-3D dialect's firmware: CONFIG, COMMAND and the pushed DATA stream
    (see the module docstring).

    link : link/firmware parameters; plant, imu, pilot : the simulated hardware;
    downlink : the UART and radio towards the ground station.
    """

    def __init__(self, link: LinkParams, plant: Plant, imu: ImuModel, pilot: Pilot,
                 downlink: Downlink) -> None:
        self.decoder = StreamDecoder(link.crc_profile)
        super().__init__(link, plant, imu, pilot, downlink)
        self.sensor_mask = 0
        self.period_ns = 0
        self.counter = 0

    # ------------------------------------------------------------------ ground -> vehicle
    def receive(self, t_ns: int, data: bytes) -> None:
        """Bytes that reached the vehicle at ``t_ns``: decode and act on complete frames."""
        for item in self.decoder.feed(data):
            if isinstance(item, CommandMsg):
                self._command(t_ns, item)
            elif isinstance(item, ConfigMsg):
                self._configure(t_ns, item)
            else:  # a DATA frame or a rejected candidate: counted, otherwise ignored
                self.uplink_ignored += 1

    def _configure(self, t_ns: int, msg: ConfigMsg) -> None:
        self.configs += 1
        self.sensor_mask = msg.sensor_mask
        if msg.period_ms == 0:
            self.period_ns = 0
            self.next_sample_ns = None
            return
        self.period_ns = msg.period_ms * 1_000_000
        if self.next_sample_ns is None:
            self.next_sample_ns = t_ns

    # ------------------------------------------------------------------ vehicle -> ground
    def sample(self, t_ns: int) -> None:
        """The DATA tick due now: send a sample unless stalled or the UART is busy."""
        assert self.next_sample_ns is not None
        self.next_sample_ns += self.period_ns
        if self.next_sample_ns <= t_ns:  # fell behind (period < step): no burst of catch-ups
            self.next_sample_ns = t_ns + self.period_ns
        for begin, end in self.stalls:
            if begin <= t_ns < end:
                self.samples_stalled += 1
                return
        if self.downlink.busy(t_ns):
            self.samples_busy += 1
            return
        self.downlink.send(t_ns, encode_frame(self.data_message(), self._profile))
        self.counter = (self.counter + 1) & 0xFFFF

    def data_message(self) -> DataMsg:
        """The DATA message for the current state, with the configured blocks."""
        mask = self.sensor_mask
        plant = self.plant
        status = gyro = acc = rc = None
        pressure = None
        if mask & 0x01:
            status = StatusBlock(self._battery_mv(), self._flags(), self.applied_mask)
        if mask & 0x06:
            g, a = self.imu.sample((plant.wx, plant.wy, plant.wz), plant.specific_force())
            gyro = AxisCounts(*g) if mask & 0x02 else None
            acc = AxisCounts(*a) if mask & 0x04 else None
        if mask & 0x08:
            pressure = self.imu.pressure(plant.pz)
        if mask & 0x10:
            s = self.pilot.sticks_at(plant.t)
            rc = RcBlock(_clamp(s.pitch, -2048, 2047), _clamp(s.roll, -2048, 2047),
                         _clamp(s.yaw, -2048, 2047), _clamp(s.thrust, 0, 4096),
                         SWITCH_ON if self.pilot.serial_enable else SWITCH_OFF)
        return DataMsg(self.counter, status, gyro, acc, pressure, rc)

    def _flags(self) -> int:
        flags = FLAG_SERIAL_ACTIVE if self.applied_mask else 0
        if self.applied.thrust > 0:
            flags |= FLAG_MOTORS_ON
        if self.pilot.rc_link:
            flags |= FLAG_RC_VALID
        return flags

