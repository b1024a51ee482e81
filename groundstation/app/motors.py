"""``gs motors start|stop``: the AscTec LL motor gesture, on an operator's request only.

The LL firmware starts the motors when it sees thrust 0 with the yaw stick held full one
way for about half a second (ctrl 0x0C: yaw and thrust from the serial link) and stops
them with the opposite yaw (``serial.ll.motor_start_yaw``; drivers disagree on the sign).
Nothing in a flight ever sends it. Refused, with nothing sent:

* while another process holds the serial port (a flight): the port is opened exclusively;
* while the vehicle reports that it is flying (LL_STATUS ``flying``);
* in the X-3D dialect, which has no such gesture (its pilot starts the motors).

The gesture is followed by ctrl mask 0 (everything back to the pilot), and the vehicle's
next LL_STATUS says whether the motors are in the state asked for.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from groundstation.asctec.ll import motor_gesture
from groundstation.asctec.ll_link import LlLink
from groundstation.asctec.messages import CommandMsg
from groundstation.asctec.params import LinkParams
from groundstation.errors import GroundStationError

STATUS_WAIT_S = 2.0
"""How long to wait for the vehicle's LL_STATUS before and after the gesture [s]."""

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2


def motor_gesture_command(link_params: LinkParams, *, start: bool,
                          echo: Callable[[str], None]) -> int:
    """Send the start (or stop) gesture over the link ``link_params`` describe (the
    flight's :attr:`~groundstation.flight.params.FlightParams.link`); return the exit
    code (see the module docstring)."""
    what = "start" if start else "stop"
    if link_params.protocol != "asctec-ll":
        echo(f"error: the {link_params.protocol} dialect has no motor gesture: the pilot "
             "starts and stops the motors (serial.protocol: asctec-ll has one)")
        return EXIT_USAGE
    ll = link_params.ll
    try:
        with LlLink.from_params(link_params) as link:
            link.start_stream()
            before = link.wait_status(STATUS_WAIT_S)
            if before is None:
                echo(f"refused: no LL_STATUS from the vehicle on {link_params.port} within "
                     f"{STATUS_WAIT_S:g} s; nothing sent")
                return EXIT_FAILED
            if before.flying:
                echo("refused: the vehicle reports that it is flying; nothing sent")
                return EXIT_FAILED
            gesture = motor_gesture(start, ll.motor_start_yaw)
            period = 1.0 / link_params.command_rate_hz
            end = time.monotonic() + ll.motor_gesture_s
            while time.monotonic() < end:
                link.send(gesture)
                time.sleep(period)
            link.send(CommandMsg.release())
            after = link.wait_status(STATUS_WAIT_S, newer_than=time.monotonic())
    except GroundStationError as exc:  # the port is absent or a flight holds it
        echo(f"refused: {exc}")
        return EXIT_FAILED
    if after is None:
        echo(f"sent the {what} gesture, but no LL_STATUS came back to confirm it")
        return EXIT_FAILED
    if bool(after.motors_on) != start:
        echo(f"sent the {what} gesture; the vehicle reports motors "
             f"{'on' if after.motors_on else 'off'}")
        return EXIT_FAILED
    echo(f"motors {'on' if start else 'off'} (LL_STATUS), vehicle handed back to the pilot")
    return EXIT_OK
