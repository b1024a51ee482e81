"""The vehicle side of the AscTec AutoPilot "LL" serial dialect (``asctec-ll-protocol.md``).

What the LL processor's firmware does with the host's unframed requests, decoded by the
project's own codec (:class:`groundstation.asctec.ll.LlRequestDecoder`):

* **Poll** ``>*>p`` + mask: one framed packet per set bit this project knows
  (:data:`groundstation.asctec.ll.ANSWERS`), in ascending bit order, queued back to back
  on the UART. Nothing is ever sent unpolled (``next_sample_ns`` stays None). GPS and
  unknown bits are ignored (counted). During a stall no poll is answered. A packet that
  does not fit in the transmit buffer behind the bytes still queued
  (``LinkParams.tx_buffer``) is not sent: a host polling more than the baud carries
  loses answers instead of piling up delay.
* **Command** ``>*>di`` + the X-3D COMMAND's payload (valid checksum and ranges only):
  exactly the X-3D firmware's handling (:class:`~sim_device.firmware.FirmwareCore`:
  store, feed the watchdog, re-arbitrate per channel) with the fallback time
  ``LinkParams.watchdog`` (``serial.ll.fallback_ms``), then the 5-byte acknowledgement
  ``>a`` 0x00 ``a<`` (also during a stall: a stall silences the data, not the command
  path).
* **Emergency** ``>*>me``: counted only (unverified in the spec).

Packets, from the plant's true state and the pilot:

* IMU_RAWDATA: gyro and accelerometer counts from the same :class:`~sim_device.imu.ImuModel`
  as the X-3D (int16 range: ``ImuParams.count_range``), the raw pressure, magnetometer 0.
* LL_STATUS: the X-3D's battery model on both voltages, cpu_load 1000, flying (not on
  the floor), motors_on (started by the motor gesture, or applied thrust > 0),
  flightMode 0x20 (pilot's serial-enable switch) | 0x40 (a non-zero ctrl mask
  applied), up_time [s].
* RC_DATA: the pilot's sticks on ``LinkParams.rc_channels`` (pitch, roll, yaw as
  stick + 2048, thrust as is, clamped to 0..4095), the serial-enable switch (4095 on,
  0 off) on ``rc_switch_channel``, 2048 elsewhere; channels_in = channels_out; lock =
  RC link valid.
* CONTROLLER_OUTPUT: the applied sticks (nick = pitch, roll, yaw, thrust);
  IMU_CALCDATA: 92 zero bytes (not simulated).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

from groundstation.asctec.decoder import encode_frame
from groundstation.asctec.ll import (
    ANSWERS,
    FLIGHT_MODE_SERIAL_ACTIVE,
    FLIGHT_MODE_SERIAL_ENABLED,
    LL_THRUST_MAX,
    ControllerOutput,
    Emergency,
    ImuCalcData,
    ImuRawData,
    LlMessage,
    LlRequestDecoder,
    LlStatus,
    Poll,
    PollMask,
    RcData,
    encode_ack,
)
from groundstation.asctec.messages import CommandMsg
from sim_device.firmware import SWITCH_OFF, SWITCH_ON, FirmwareCore
from sim_device.imu import ImuModel
from sim_device.link import Downlink, seconds_to_ns
from sim_device.params import LinkParams
from sim_device.pilot import Pilot
from sim_device.plant import Plant

RC_CENTRE: Final = 2048
"""RC_DATA value of a centred stick (channels_out 0..4095)."""
RC_MAX: Final = 4095
CPU_LOAD: Final = 1000
"""LL_STATUS cpu_load: control cycles per second (the LL's 1 kHz loop)."""
TEMP_GYRO_RAW: Final = 25
TEMP_ADC_RAW: Final = 25
"""IMU_RAWDATA temperatures: plausible constants (raw units undocumented; unused)."""
IMU_CALCDATA_SIZE: Final = 92
INT16_MAX: Final = 0x7FFF

_KNOWN_BITS: Final = sorted(ANSWERS)
"""The poll bits this project answers, ascending."""
_KNOWN_MASK: Final = sum(int(bit) for bit in ANSWERS)


def _clamp(value: int, lo: int, hi: int) -> int:
    return lo if value < lo else hi if value > hi else value


class LlFirmware(FirmwareCore):
    """Vehicle firmware of the AscTec LL dialect: polls, commands, acknowledgements.

    link : link/firmware parameters (``protocol`` "asctec-ll"; ``watchdog`` is the LL
    fallback); plant, imu, pilot : the simulated hardware; downlink : the UART and
    radio towards the ground station.

    Counters beside :class:`~sim_device.firmware.FirmwareCore`'s: ``polls`` received,
    ``emergencies``, ``poll_bits_ignored`` (requested bits without a packet: GPS,
    unknown), ``acks_sent``, ``acks_dropped`` (no room in the transmit buffer),
    ``answers`` (packets queued, by packet name); ``samples_stalled`` counts polls not
    answered during a stall, ``samples_busy`` answers that did not fit the buffer.
    """

    THRUST_MAX = LL_THRUST_MAX

    def __init__(self, link: LinkParams, plant: Plant, imu: ImuModel, pilot: Pilot,
                 downlink: Downlink) -> None:
        self.decoder = LlRequestDecoder()
        super().__init__(link, plant, imu, pilot, downlink)
        self._tx_limit_ns = downlink.frame_ns(link.tx_buffer)
        self.polls = 0
        self.emergencies = 0
        self.poll_bits_ignored = 0
        self.acks_sent = 0
        self.acks_dropped = 0
        self.answers: dict[str, int] = {cls.NAME: 0 for cls in ANSWERS.values()}
        self.motors_started = False
        """Started by the motor gesture (they idle at thrust 0 until stopped by it)."""
        self._gesture: tuple[int, int] | None = None  # (sign, since [ns]) of a held gesture
        self._packets: dict[PollMask, Callable[[], LlMessage]] = {
            PollMask.LL_STATUS: self.ll_status, PollMask.IMU_RAWDATA: self.imu_rawdata,
            PollMask.IMU_CALCDATA: self.imu_calcdata, PollMask.RC_DATA: self.rc_data,
            PollMask.CONTROLLER_OUTPUT: self.controller_output,
        }

    # ------------------------------------------------------------------ host -> vehicle
    def receive(self, t_ns: int, data: bytes) -> None:
        """Bytes that reached the vehicle at ``t_ns`` [ns]: decode and act on complete
        requests (answers and acknowledgements are queued on the downlink)."""
        for item in self.decoder.feed(data):
            if isinstance(item, Poll):
                self._answer(t_ns, item.mask)
            elif isinstance(item, CommandMsg):
                self._command(t_ns, item)
                self._watch_gesture(t_ns, item)
                if self._queue(t_ns, encode_ack(0)):
                    self.acks_sent += 1
                else:
                    self.acks_dropped += 1
            elif isinstance(item, Emergency):
                self.emergencies += 1
            else:  # a rejected request (the decoder counts it by reason)
                self.uplink_ignored += 1

    def _watch_gesture(self, t_ns: int, cmd: CommandMsg) -> None:
        """The motor gesture: thrust 0 and the yaw stick full one way from the serial link
        (ctrl yaw and thrust) for ``link.motor_gesture`` seconds starts the motors (the
        configured sign) or stops them (the opposite)."""
        start = self.params.motor_start_yaw
        held = (cmd.ctrl & 0x0C == 0x0C and cmd.thrust == 0 and abs(cmd.yaw) >= 2000
                and self.pilot.serial_enable)
        sign = 1 if cmd.yaw * start > 0 else -1
        if not held:
            self._gesture = None
            return
        if self._gesture is None or self._gesture[0] != sign:
            self._gesture = (sign, t_ns)
        elif t_ns - self._gesture[1] >= seconds_to_ns(self.params.motor_gesture):
            self.motors_started = sign > 0

    def _answer(self, t_ns: int, mask: int) -> None:
        """One poll: queue a packet per known bit of ``mask``, ascending."""
        self.polls += 1
        self.poll_bits_ignored += (mask & ~_KNOWN_MASK).bit_count()
        if self.stalled(t_ns):
            self.samples_stalled += 1
            return
        self.update_control(t_ns)  # a command earlier in the same bytes shows in the answer
        for bit in _KNOWN_BITS:
            if mask & bit:
                packet = self._packets[bit]()
                if self._queue(t_ns, encode_frame(packet, self._profile)):
                    self.answers[packet.NAME] += 1
                else:
                    self.samples_busy += 1

    def _queue(self, t_ns: int, frame: bytes) -> bool:
        """Put ``frame`` behind the bytes on the UART if the transmit buffer holds it."""
        downlink = self.downlink
        if downlink.backlog_ns(t_ns) + downlink.frame_ns(len(frame)) > self._tx_limit_ns:
            return False
        downlink.send(t_ns, frame)
        return True

    def sample(self, t_ns: int) -> None:
        """Nothing: the LL vehicle pushes no data (``next_sample_ns`` is never due)."""

    # ------------------------------------------------------------------ packets
    def packet(self, bit: PollMask) -> LlMessage:
        """The packet poll bit ``bit`` asks for, from the current state (KeyError for GPS)."""
        return self._packets[bit]()

    def ll_status(self) -> LlStatus:
        """LL_STATUS now: battery [mV], flags, flightMode bits, up_time [s]."""
        battery = min(INT16_MAX, self._battery_mv())
        mode = FLIGHT_MODE_SERIAL_ENABLED if self.pilot.serial_enable else 0
        if self.applied_mask:
            mode |= FLIGHT_MODE_SERIAL_ACTIVE
        return LlStatus(battery_mv_1=battery, battery_mv_2=battery, status=0,
                        cpu_load=CPU_LOAD, compass_enabled=0, chksum_error=0,
                        flying=0 if self.plant.on_ground else 1,
                        motors_on=int(self.motors_started or self.applied.thrust > 0),
                        flight_mode=mode,
                        up_time=min(INT16_MAX, int(self.plant.t)))

    def imu_rawdata(self) -> ImuRawData:
        """IMU_RAWDATA now: gyro and accelerometer counts of the true body rates and
        specific force (through the IMU model), the raw pressure, magnetometer 0."""
        plant = self.plant
        gyro, acc = self.imu.sample((plant.wx, plant.wy, plant.wz), plant.specific_force())
        return ImuRawData(pressure=self.imu.pressure(plant.pz), gyro=gyro, mag=(0, 0, 0),
                          acc=acc, temp_gyro=TEMP_GYRO_RAW, temp_adc=TEMP_ADC_RAW)

    def rc_data(self) -> RcData:
        """RC_DATA now: the pilot's sticks and serial-enable switch, the RC lock."""
        s = self.pilot.sticks_at(self.plant.t)
        out = [RC_CENTRE] * 8
        pitch, roll, thrust, yaw = self.params.rc_channels
        out[pitch] = _clamp(s.pitch + RC_CENTRE, 0, RC_MAX)
        out[roll] = _clamp(s.roll + RC_CENTRE, 0, RC_MAX)
        out[yaw] = _clamp(s.yaw + RC_CENTRE, 0, RC_MAX)
        out[thrust] = _clamp(s.thrust, 0, RC_MAX)
        out[self.params.rc_switch_channel] = SWITCH_ON if self.pilot.serial_enable else SWITCH_OFF
        channels = tuple(out)
        return RcData(channels_in=channels, channels_out=channels,
                      lock=1 if self.pilot.rc_link else 0)

    def controller_output(self) -> ControllerOutput:
        """CONTROLLER_OUTPUT now: the applied sticks (nick = pitch)."""
        a = self.applied
        return ControllerOutput(nick=a.pitch, roll=a.roll, yaw=a.yaw, thrust=a.thrust)

    def imu_calcdata(self) -> ImuCalcData:
        """IMU_CALCDATA: not simulated, 92 zero bytes."""
        return ImuCalcData(bytes(IMU_CALCDATA_SIZE))
