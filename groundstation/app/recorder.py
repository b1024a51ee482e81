"""Flight recorder: one row per control tick, written incrementally to a ``.npy`` file.

A flight is one directory ``<log_dir>/<UTC start, YYYYMMDDTHHMMSSZ>/`` holding

``flight.npy``
    a numpy structured array, one row per tick, one *scalar* column per value
    (:data:`FLAT_DTYPE`), so ``np.load(path)`` and ``pandas.DataFrame(np.load(path))``
    read it in one line. The header is written once with a fixed-width shape field;
    every :meth:`FlightRecorder.flush` appends the buffered rows and then rewrites
    only the row count, so the file is loadable after every flush and a process
    killed with SIGKILL leaves everything up to the last flush (at most
    ``flush_interval_s`` = 1 s is lost).
``config.yaml``
    the configuration the flight used, verbatim.
``meta.json``
    package version, start wall-clock time (ISO 8601 UTC) and monotonic time,
    the unit of every column, the caller's metadata (by convention
    ``supervisor_states``: the state names, indexed by the ``state`` column) and,
    after a clean close, end times and counters (``rows``, ``rows_dropped``,
    ``lost_rows_by_reason``, ``bad_rows``, ``write_errors``).

A full disk loses rows, never the end of the flight. The recorder keeps
:data:`RESERVE_ROWS` rows of ``flight.npy`` allocated (``posix_fallocate``) beyond
those written and only its last flush may use them, so the flight's last second (its
landing and final row) is written after the disk filled; and meta.json's final
version is written into space allocated at the start (``meta.json.reserve``, renamed
over meta.json: atomic, and no empty temporary left). Rows that could not be written
are counted with their reason (:meth:`FlightRecorder.loss`).

In memory and from :func:`read_flight` the same bytes are viewed as
:data:`RECORD_DTYPE`, whose vector values are sub-array fields
(``data["est_position"]`` is an ``(N, 3)`` array). Both dtypes have identical
layouts; the flat column of a vector field is ``<field>_<component>``
(``est_position_x``, ``est_quaternion_q0``, ``est_covariance_diag_bgx``).

Fields (frames: NED earth, FRD body; quaternions scalar-first, R(q) = eCb)::

    t                    s        time.monotonic() when the tick was recorded
    imu_t                s        monotonic receive time of the IMU sample
    imu_counter          -        DATA sample counter (uint16, wraps)
    gyro_counts  (3,)    count    raw gyro ADC counts, FRD axes (X-3D 12-bit, LL int16)
    acc_counts   (3,)    count    raw accelerometer counts, FRD axes (X-3D 12-bit, LL int16)
    gyro         (3,)    rad/s    scaled body rates, FRD
    acc          (3,)    m/s^2    scaled specific force, FRD
    vicon_valid          bool     a Vicon pose was used this tick
    vicon_t              s        monotonic measurement time of that pose (NaN if none)
    vicon_position (3,)  m        pose position, NED (NaN if none)
    vicon_quaternion (4,) -       pose attitude, scalar-first (NaN if none)
    vicon_nis            -        the estimator's normalised innovation squared
                                  y^T S^-1 y (6 dof) of the last pose it judged this
                                  tick (NaN if none, or none computed)
    vicon_refused        count    poses the estimator refused this tick (gated,
                                  repeated, lost tracking, too old, invalid, ...)
    est_position (3,)    m        estimate, NED (NaN before the estimator runs)
    est_quaternion (4,)  -        estimated attitude, scalar-first
    est_velocity_body (3,) m/s    velocity relative to earth, FRD axes
    est_omega    (3,)    rad/s    bias-corrected body rates, FRD
    est_gyro_bias (3,)   rad/s    FRD
    est_acc_bias (3,)    m/s^2    FRD
    est_covariance_diag (16,)     P diagonal [p(3) m^2, q(4) -, v(3) (m/s)^2,
                                  gyro bias(3) (rad/s)^2, acc bias(3) (m/s^2)^2]
    ref_position (3,)    m        reference, NED (NaN when there is none)
    ref_velocity (3,)    m/s      reference velocity, NED
    ref_yaw              rad      reference heading
    ref_acceleration (3,) m/s^2   reference acceleration, NED
    ref_jerk     (3,)    m/s^3    reference jerk, NED
    ref_yaw_rate         rad/s    reference heading rate
    preview_*                     the reference the controller looked ahead to for its
                                  feed-forward (lead_s later), same fields and units as
                                  ref_*; NaN when it asked for none or did not run
    cmd_pitch, cmd_roll, cmd_yaw  RC unit  the COMMAND's stick values, -2048..2047
                                  (thesis signs; after the channel handover)
    cmd_thrust           RC unit  0..4096
    cmd_mask             bits     ctrl mask (bit0 pitch .. bit3 thrust)
    cmd_sent             bool     a COMMAND frame was written this tick
    cmd_automatic        bool     the controller stepped for it and was told it went out
                                  with every channel its own (no pilot, no handover blend)
    ctrl_pitch, ctrl_roll, ctrl_yaw, ctrl_thrust
                         RC unit  the controller's sticks before the handover blend
                                  (0 when the controller did not run this tick)
    battery_v            V        battery voltage the X-3D reports (STATUS; NaN without it)
    vehicle_flags        bits     STATUS flags: bit0 the X-3D applies ground-station
                                  commands, bit1 motors on, bit2 RC link valid
    vehicle_mask         bits     ctrl mask the X-3D applies (STATUS): 0 while the pilot
                                  has every channel, e.g. after its watchdog expired
    pilot_enabled        bool     the pilot's serial-enable switch (RC block; True without it)
    pilot_pitch, pilot_roll, pilot_yaw, pilot_thrust
                         RC unit  the pilot's sticks (RC block; 0 without it); with
                                  cmd_* and vehicle_mask, the sticks the vehicle applied
                                  (these: the last DATA frame that carried them)
    state                -        supervisor state (names in meta["supervisor_states"])
    compute_time         s        time spent computing this tick
    jitter               s        tick start minus its scheduled time
    latency              s        command write time minus IMU receive time
"""

from __future__ import annotations

import contextlib
import datetime as dt
import errno
import json
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt
import structlog

from groundstation import __version__
from groundstation.asctec.messages import CommandMsg
from groundstation.errors import RecorderError
from groundstation.types import ImuSample, Pose, Reference, StateEstimate, Sticks

log = structlog.get_logger(__name__)

SCHEMA_VERSION = 5
"""Bumped whenever :data:`RECORD_DTYPE` changes; stored in meta.json."""

_XYZ = ("x", "y", "z")
_NO_STICKS = Sticks(0, 0, 0, 0)
_Q = ("q0", "q1", "q2", "q3")
_COV = ("px", "py", "pz", "q0", "q1", "q2", "q3", "vx", "vy", "vz",
        "bgx", "bgy", "bgz", "bax", "bay", "baz")
_COV_UNITS = ("m^2",) * 3 + ("1",) * 4 + ("(m/s)^2",) * 3 + ("(rad/s)^2",) * 3 + ("(m/s^2)^2",) * 3

# (name, numpy type, components or None for a scalar, unit or per-component units)
_SCHEMA: tuple[tuple[str, str, tuple[str, ...] | None, str | tuple[str, ...]], ...] = (
    ("t", "<f8", None, "s"),
    ("imu_t", "<f8", None, "s"),
    ("imu_counter", "<u2", None, "1"),
    ("gyro_counts", "<i4", _XYZ, "count"),
    ("acc_counts", "<i4", _XYZ, "count"),
    ("gyro", "<f8", _XYZ, "rad/s"),
    ("acc", "<f8", _XYZ, "m/s^2"),
    ("vicon_valid", "|b1", None, "bool"),
    ("vicon_t", "<f8", None, "s"),
    ("vicon_position", "<f8", _XYZ, "m"),
    ("vicon_quaternion", "<f8", _Q, "1"),
    ("vicon_nis", "<f8", None, "1"),
    ("vicon_refused", "|u1", None, "count"),
    ("est_position", "<f8", _XYZ, "m"),
    ("est_quaternion", "<f8", _Q, "1"),
    ("est_velocity_body", "<f8", _XYZ, "m/s"),
    ("est_omega", "<f8", _XYZ, "rad/s"),
    ("est_gyro_bias", "<f8", _XYZ, "rad/s"),
    ("est_acc_bias", "<f8", _XYZ, "m/s^2"),
    ("est_covariance_diag", "<f8", _COV, _COV_UNITS),
    ("ref_position", "<f8", _XYZ, "m"),
    ("ref_velocity", "<f8", _XYZ, "m/s"),
    ("ref_yaw", "<f8", None, "rad"),
    ("ref_acceleration", "<f8", _XYZ, "m/s^2"),
    ("ref_jerk", "<f8", _XYZ, "m/s^3"),
    ("ref_yaw_rate", "<f8", None, "rad/s"),
    ("preview_position", "<f8", _XYZ, "m"),
    ("preview_velocity", "<f8", _XYZ, "m/s"),
    ("preview_yaw", "<f8", None, "rad"),
    ("preview_acceleration", "<f8", _XYZ, "m/s^2"),
    ("preview_jerk", "<f8", _XYZ, "m/s^3"),
    ("preview_yaw_rate", "<f8", None, "rad/s"),
    ("cmd_pitch", "<i2", None, "RC unit"),
    ("cmd_roll", "<i2", None, "RC unit"),
    ("cmd_yaw", "<i2", None, "RC unit"),
    ("cmd_thrust", "<i2", None, "RC unit"),
    ("cmd_mask", "|u1", None, "bits"),
    ("cmd_sent", "|b1", None, "bool"),
    ("cmd_automatic", "|b1", None, "bool"),
    ("ctrl_pitch", "<i2", None, "RC unit"),
    ("ctrl_roll", "<i2", None, "RC unit"),
    ("ctrl_yaw", "<i2", None, "RC unit"),
    ("ctrl_thrust", "<i2", None, "RC unit"),
    ("battery_v", "<f8", None, "V"),
    ("vehicle_flags", "|u1", None, "bits"),
    ("vehicle_mask", "|u1", None, "bits"),
    ("pilot_enabled", "|b1", None, "bool"),
    ("pilot_pitch", "<i2", None, "RC unit"),
    ("pilot_roll", "<i2", None, "RC unit"),
    ("pilot_yaw", "<i2", None, "RC unit"),
    ("pilot_thrust", "<i2", None, "RC unit"),
    ("state", "|u1", None, "enum"),
    ("compute_time", "<f8", None, "s"),
    ("jitter", "<f8", None, "s"),
    ("latency", "<f8", None, "s"),
)

_REFERENCE_FIELDS = {
    prefix: tuple(f"{prefix}_{name}" for name in
                  ("position", "velocity", "yaw", "acceleration", "jerk", "yaw_rate"))
    for prefix in ("ref", "preview")
}

RECORD_DTYPE = np.dtype([
    (name, typ) if comps is None else (name, typ, (len(comps),))
    for name, typ, comps, _ in _SCHEMA
])
"""One tick, vector values as sub-array fields (see the module docstring for units)."""

FLAT_DTYPE = np.dtype([
    (name if comps is None else f"{name}_{c}", typ)
    for name, typ, comps, _ in _SCHEMA
    for c in (comps or ("",))
])
"""The same bytes as :data:`RECORD_DTYPE` with one scalar column per value (on disk; the
columns of :mod:`groundstation.export`'s CSV and Parquet)."""

COLUMN_UNITS: dict[str, str] = {
    (name if comps is None else f"{name}_{c}"): (unit if isinstance(unit, str) else unit[k])
    for name, _, comps, unit in _SCHEMA
    for k, c in enumerate(comps or ("",))
}
"""Unit of every flat column, as stored in meta.json."""


FLIGHT_FILE = "flight.npy"
CONFIG_FILE = "config.yaml"
META_FILE = "meta.json"
META_RESERVE_FILE = "meta.json.reserve"
"""Space for the final meta.json, allocated at the start; renamed over meta.json at the
end (left behind only by a process killed in flight)."""

RESERVE_ROWS = 256
"""Rows of flight.npy kept allocated beyond the written ones for the last flush: 2.56 s
at 100 Hz, more than the 1 s of rows a flush holds (about 190 kB)."""

META_RESERVE_BYTES = 65536
"""Space allocated for the final meta.json [bytes] (a flight's is about 6 kB)."""

_NO_ROOM = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})
"""Errors that say the disk (or quota, or file size limit) has no room: rows are lost.
Any other error of ``posix_fallocate`` says it cannot allocate here (a device, a file
system without it): the recorder then writes without a reserve."""

# .npy v1.0 header with the shape first and fixed-width, so a flush rewrites only the
# digits at a fixed offset (np.load accepts the spaces: the header is a Python literal).
_SHAPE_WIDTH = 20
_HEADER_PREFIX = "{'shape': ("
_DESCR = repr(np.lib.format.dtype_to_descr(FLAT_DTYPE))


def _header_text(count: int) -> str:
    """The header dict for ``count`` rows; its length does not depend on ``count``."""
    shape = f"{_HEADER_PREFIX}{count:>{_SHAPE_WIDTH}},), "
    return shape + f"'fortran_order': False, 'descr': {_DESCR}, }}"


_MAGIC = np.lib.format.magic(1, 0)
_HEADER_LEN = -(-(len(_MAGIC) + 2 + len(_header_text(0)) + 1) // 64) * 64
_COUNT_OFFSET = len(_MAGIC) + 2 + len(_HEADER_PREFIX)
if _HEADER_LEN > 10_000 or FLAT_DTYPE.itemsize != RECORD_DTYPE.itemsize:  # pragma: no cover
    raise RuntimeError("recorder schema: header beyond np.load's limit or layouts differ")


def _header(count: int) -> bytes:
    """The complete .npy header (magic, length, dict, padding) for ``count`` rows."""
    text = _header_text(count)
    body_len = _HEADER_LEN - len(_MAGIC) - 2
    body = text.ljust(body_len - 1) + "\n"
    return _MAGIC + body_len.to_bytes(2, "little") + body.encode("latin1")


def _count_field(count: int) -> bytes:
    """The fixed-width row count written at ``_COUNT_OFFSET`` on every flush."""
    return f"{count:>{_SHAPE_WIDTH}}".encode("latin1")


def _new_flight_dir(log_dir: Path, start: dt.datetime) -> Path:
    """Create ``log_dir/<UTC stamp>`` (with ``-2``, ``-3``... if that exists)."""
    log_dir.mkdir(parents=True, exist_ok=True)
    stamp = start.strftime("%Y%m%dT%H%M%SZ")
    for k in range(1, 1000):
        path = log_dir / (stamp if k == 1 else f"{stamp}-{k}")
        try:
            path.mkdir()
        except FileExistsError:
            continue
        return path
    raise FileExistsError(f"{log_dir}: too many flights stamped {stamp}")


def _json_bytes(data: Mapping[str, Any]) -> bytes:
    return (json.dumps(data, indent=2, default=str) + "\n").encode("utf-8")


def _write_json(path: Path, data: Mapping[str, Any]) -> None:
    """Write JSON atomically (temporary file, then rename); no temporary file is left
    when it fails."""
    tmp = path.with_suffix(".json.tmp")
    try:
        tmp.write_bytes(_json_bytes(data))
        os.replace(tmp, path)
    except OSError:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def _why(exc: OSError) -> str:
    """The OS's words for an error (``No space left on device``)."""
    return exc.strerror or str(exc) or type(exc).__name__


def _reserve(fd: int, size: int) -> None:
    """Allocate ``size`` bytes of the new, empty file ``fd``: ``posix_fallocate``, or
    zeros written where it cannot allocate. OSError when there is no room."""
    try:
        os.posix_fallocate(fd, 0, size)
    except OSError as exc:
        if exc.errno in _NO_ROOM:
            raise
        _pwrite_all(fd, memoryview(bytes(size)), 0)


@dataclass(frozen=True)
class LogLoss:
    """What a flight log is missing.

    rows : rows written
    lost : rows not written: failed writes (a full disk, an I/O error) and rows whose
        values did not fit the record
    reasons : rows lost per reason (the OS's words, e.g. "No space left on device")
    meta_error : why the final meta.json could not be written ("" if it was)
    """

    rows: int = 0
    lost: int = 0
    reasons: dict[str, int] = field(default_factory=dict)
    meta_error: str = ""

    @property
    def complete(self) -> bool:
        """True when nothing is missing."""
        return self.lost == 0 and not self.meta_error

    def describe(self) -> str:
        """One clause for a summary: ``flight log incomplete: 570 of 3414 rows lost (No
        space left on device)``; empty when complete."""
        if self.complete:
            return ""
        parts = []
        if self.lost:
            why = ", ".join(reason if len(self.reasons) == 1 else f"{n} {reason}"
                            for reason, n in self.reasons.items())
            parts.append(f"{self.lost} of {self.rows + self.lost} rows lost ({why})")
        if self.meta_error:
            parts.append(f"meta.json not written ({self.meta_error})")
        return "flight log incomplete: " + "; ".join(parts)

    def as_meta(self) -> dict[str, object]:
        """For meta.json: ``complete``, ``rows``, ``rows_lost``, ``reasons``."""
        return {"complete": self.complete, "rows": self.rows, "rows_lost": self.lost,
                "reasons": dict(self.reasons)}


def _columns(buf: npt.NDArray[np.void]) -> dict[str, npt.NDArray[Any]]:
    """One view per field of ``buf`` (looked up per tick instead of ``buf[name]``)."""
    return {name: buf[name] for name in RECORD_DTYPE.names or ()}


def _pwrite_all(fd: int, data: memoryview, offset: int) -> None:
    """pwrite until every byte of ``data`` is at ``offset`` (regular files may write short)."""
    while data:
        written = os.pwrite(fd, data, offset)
        data = data[written:]
        offset += written


class FlightRecorder:
    """Writes one flight: rows to ``flight.npy``, plus ``config.yaml`` and ``meta.json``.

    Open one with :meth:`create`. Each tick call :meth:`append` (about 7 us: it copies
    the values into a preallocated row of a numpy buffer, no allocation, no I/O
    except when a flush is due). The buffer is written out when ``flush_interval_s``
    has passed since the last flush (judged on the ticks' own ``t``), when it is
    full, and on :meth:`finish` or :meth:`close`. Writes go straight to the kernel
    (``os.pwrite``), so a killed process loses only the rows since the last flush;
    :meth:`finish` also fsyncs. A failed write (disk full, I/O error) is logged and
    counted with its reason, never raised: the flight goes on without those rows, and
    the last flush writes into the reserve (see the module docstring).
    """

    def __init__(
        self, directory: Path, meta: dict[str, Any], *,
        flush_interval_s: float = 1.0, capacity: int = 1024, reserve_rows: int = RESERVE_ROWS,
    ) -> None:
        """Open ``directory/flight.npy`` and allocate the reserves (neither file may
        exist); prefer :meth:`create`. OSError when they cannot be written.

        flush_interval_s : longest time rows stay in memory [s], > 0
        capacity : rows buffered in memory, >= 1 (flushes early when full)
        reserve_rows : rows kept allocated for the last flush, >= 0
        """
        if not flush_interval_s > 0 or capacity < 1 or reserve_rows < 0:
            raise ValueError("flush_interval_s must be > 0, capacity >= 1, reserve_rows >= 0")
        self.directory = directory
        self.path = directory / FLIGHT_FILE
        self.meta = meta
        self._interval = float(flush_interval_s)
        self._capacity = int(capacity)
        self._buf = np.zeros(self._capacity, dtype=RECORD_DTYPE)
        self._bytes = self._buf.view(np.uint8)
        self._cols = _columns(self._buf)
        self._n = 0
        self._on_disk = 0
        self._flush_due = -np.inf  # the first row is written at once
        self._reserve = int(reserve_rows) * RECORD_DTYPE.itemsize
        self._allocated = 0  # bytes of flight.npy allocated (posix_fallocate)
        self._preallocate = True  # False where posix_fallocate cannot allocate
        self._failing = False  # the last write failed (a recovery is logged)
        self.rows_dropped = 0
        """Rows lost to failed writes."""
        self.lost_by_reason: dict[str, int] = {}
        """Rows lost to failed writes, per reason (the OS's words)."""
        self.bad_rows = 0
        """append() calls whose values did not fit the record (skipped)."""
        self.write_errors = 0
        """Failed flushes."""
        self.meta_error = ""
        """Why the final meta.json could not be written ("" if it was, or not yet)."""
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC
        self._meta_fd = os.open(directory / META_RESERVE_FILE, flags, 0o644)
        self._fd = -1
        try:
            _reserve(self._meta_fd, META_RESERVE_BYTES)
            self._fd = os.open(self.path, flags, 0o644)
            _pwrite_all(self._fd, memoryview(_header(0)), 0)
            self._allocate(_HEADER_LEN + self._reserve)
        except OSError:
            for fd in (self._fd, self._meta_fd):
                if fd >= 0:
                    os.close(fd)
            with contextlib.suppress(OSError):
                (directory / META_RESERVE_FILE).unlink()
            raise

    @classmethod
    def create(
        cls, log_dir: str | Path, config_yaml: str, meta: Mapping[str, Any] | None = None, *,
        flush_interval_s: float = 1.0, capacity: int = 1024, reserve_rows: int = RESERVE_ROWS,
    ) -> FlightRecorder:
        """Start a flight log in a new directory ``log_dir/<UTC start time>/``.

        config_yaml : the configuration text, stored verbatim as config.yaml
        meta : extra metadata for meta.json, e.g.
            ``{"supervisor_states": [s.name for s in State]}`` (JSON-serialisable;
            the recorder's own keys ``format``, ``schema_version``, ``version``,
            ``start_time``, ``start_monotonic``, ``units`` take precedence)
        reserve_rows : rows kept allocated for the last flush (:data:`RESERVE_ROWS`)
        Raises RecorderError if the directory, the files or the reserves cannot be
        written (a disk that cannot hold them is no place to start a flight).
        """
        start_wall = dt.datetime.now(dt.UTC)
        start_mono = time.monotonic()
        full = {
            **(meta or {}),
            "format": "groundstation flight log",
            "schema_version": SCHEMA_VERSION,
            "version": __version__,
            "start_time": start_wall.isoformat(),
            "start_monotonic": start_mono,
            "units": COLUMN_UNITS,
        }
        try:
            directory = _new_flight_dir(Path(log_dir), start_wall)
            (directory / CONFIG_FILE).write_text(config_yaml, encoding="utf-8")
            _write_json(directory / META_FILE, full)
            return cls(directory, full, flush_interval_s=flush_interval_s, capacity=capacity,
                       reserve_rows=reserve_rows)
        except OSError as exc:
            raise RecorderError(f"cannot start a flight log in {log_dir}: {exc}") from exc

    @property
    def rows(self) -> int:
        """Rows appended so far (written and buffered), excluding dropped ones."""
        return self._on_disk + self._n

    @property
    def closed(self) -> bool:
        """True after :meth:`close`."""
        return self._fd < 0

    def append(
        self, *, t: float, imu: ImuSample, gyro_counts: Sequence[int], acc_counts: Sequence[int],
        pose: Pose | None, estimate: StateEstimate | None, reference: Reference | None,
        command: CommandMsg, controller: Sticks | None, sent: bool, state: int,
        compute_time: float, jitter: float, latency: float, preview: Reference | None = None,
        automatic: bool = False, battery_v: float = np.nan, vehicle_flags: int = 0,
        vehicle_mask: int = 0, pilot_enabled: bool = True, pilot: Sticks | None = None,
        vicon_nis: float = np.nan, vicon_refused: int = 0,
    ) -> None:
        """Record one tick (hot path: no validation, no allocation).

        t : time.monotonic() of the tick [s]; also decides when to flush
        imu : the IMU sample of this tick; gyro_counts, acc_counts: its raw (3,) counts
        pose : the Vicon pose used this tick, or None (vicon_valid False, NaN values)
        estimate, reference : None before they exist (NaN values)
        preview : the controller's look-ahead reference, None if none (NaN values)
        command : the COMMAND of this tick; sent : whether it was written; automatic :
            see the ``cmd_automatic`` column
        controller : the controller's sticks before the handover (None: it did not run)
        state : supervisor state as an int; compute_time, jitter, latency [s]
        battery_v [V], vehicle_flags, vehicle_mask, pilot_enabled, pilot : what the
            vehicle last reported (STATUS and RC blocks; pilot None: no RC block)
        vicon_nis : the estimator's normalised innovation squared of the last pose it
            judged this tick (NaN: none); vicon_refused : poses it refused this tick
        Values that do not fit (wrong shape, out of the column's range) skip the row
        and count in :attr:`bad_rows`; appending after close is ignored.
        """
        i = self._n
        c = self._cols
        try:
            c["t"][i] = t
            c["imu_t"][i] = imu.t
            c["imu_counter"][i] = imu.counter
            c["gyro_counts"][i] = gyro_counts
            c["acc_counts"][i] = acc_counts
            c["gyro"][i] = imu.gyro
            c["acc"][i] = imu.acc
            self._put_pose(i, pose)
            c["vicon_nis"][i] = vicon_nis
            c["vicon_refused"][i] = vicon_refused
            self._put_estimate(i, estimate)
            self._put_reference(i, "ref", reference)
            self._put_reference(i, "preview", preview)
            c["cmd_pitch"][i] = command.pitch
            c["cmd_roll"][i] = command.roll
            c["cmd_yaw"][i] = command.yaw
            c["cmd_thrust"][i] = command.thrust
            c["cmd_mask"][i] = command.ctrl
            c["cmd_sent"][i] = sent
            c["cmd_automatic"][i] = automatic
            s = controller if controller is not None else _NO_STICKS
            c["ctrl_pitch"][i] = s.pitch
            c["ctrl_roll"][i] = s.roll
            c["ctrl_yaw"][i] = s.yaw
            c["ctrl_thrust"][i] = s.thrust
            c["battery_v"][i] = battery_v
            c["vehicle_flags"][i] = vehicle_flags
            c["vehicle_mask"][i] = vehicle_mask
            c["pilot_enabled"][i] = pilot_enabled
            p = pilot if pilot is not None else _NO_STICKS
            c["pilot_pitch"][i] = p.pitch
            c["pilot_roll"][i] = p.roll
            c["pilot_yaw"][i] = p.yaw
            c["pilot_thrust"][i] = p.thrust
            c["state"][i] = state
            c["compute_time"][i] = compute_time
            c["jitter"][i] = jitter
            c["latency"][i] = latency
        except (ValueError, TypeError, OverflowError, IndexError):
            self.bad_rows += 1  # IndexError: the buffer is gone after close()
            return
        self._n = i + 1
        if self._n == self._capacity or t >= self._flush_due:
            self.flush(t)

    def _put_reference(self, i: int, prefix: str, ref: Reference | None) -> None:
        c = self._cols
        names = _REFERENCE_FIELDS[prefix]
        if ref is None:
            for name in names:
                c[name][i] = np.nan
            return
        pos, vel, yaw, acc, jerk, rate = names
        c[pos][i] = ref.position
        c[vel][i] = ref.velocity
        c[yaw][i] = ref.yaw
        c[acc][i] = ref.acceleration
        c[jerk][i] = ref.jerk
        c[rate][i] = ref.yaw_rate

    def _put_pose(self, i: int, pose: Pose | None) -> None:
        c = self._cols
        if pose is None:
            c["vicon_valid"][i] = False
            c["vicon_t"][i] = c["vicon_position"][i] = c["vicon_quaternion"][i] = np.nan
        else:
            c["vicon_valid"][i] = True
            c["vicon_t"][i] = pose.t
            c["vicon_position"][i] = pose.position
            c["vicon_quaternion"][i] = pose.quaternion

    def _put_estimate(self, i: int, est: StateEstimate | None) -> None:
        c = self._cols
        if est is None:
            for name in _EST_FIELDS:
                c[name][i] = np.nan
        else:
            c["est_position"][i] = est.position
            c["est_quaternion"][i] = est.quaternion
            c["est_velocity_body"][i] = est.velocity_body
            c["est_omega"][i] = est.omega
            c["est_gyro_bias"][i] = est.gyro_bias
            c["est_acc_bias"][i] = est.acc_bias
            c["est_covariance_diag"][i] = est.covariance_diag

    def flush(self, t: float | None = None) -> None:
        """Write the buffered rows, then the new row count; the file is loadable after.

        t : the current monotonic time [s] (default time.monotonic()); the next
            automatic flush is due ``flush_interval_s`` after it.
        Rows are written only while the reserve stays allocated behind them (that is
        the last flush's, :meth:`finish`). A write error is logged and counted
        (:attr:`write_errors`, :attr:`rows_dropped`, :attr:`lost_by_reason`), never
        raised.
        """
        self._flush_due = (time.monotonic() if t is None else t) + self._interval
        self._write_rows(final=False)

    def _write_rows(self, *, final: bool) -> None:
        n = self._n
        if n == 0 or self._fd < 0:
            return
        self._n = 0
        size = RECORD_DTYPE.itemsize
        start = _HEADER_LEN + self._on_disk * size
        first = 0  # the rows before it are lost
        try:
            try:
                self._allocate(start + n * size + (0 if final else self._reserve))
            except OSError as exc:
                if not final:
                    raise
                # the last flush: the newest rows (the flight's end, its final row) into
                # what is allocated; the older ones only if the disk takes them
                first = max(0, n - max(0, self._allocated - start) // size)
                self._lost(first, _why(exc))
            _pwrite_all(self._fd, self._bytes[first * size: n * size].data, start)
            os.pwrite(self._fd, _count_field(self._on_disk + n - first), _COUNT_OFFSET)
        except OSError as exc:
            self.write_errors += 1
            self._lost(n - first, _why(exc))
            return
        self._on_disk += n - first
        if self._failing:
            self._failing = False
            log.warning("flight log writes resumed", path=str(self.path),
                        rows_lost=self.rows_dropped)

    def _lost(self, rows: int, reason: str) -> None:
        """Count ``rows`` lost for ``reason``; the first loss of each reason is logged."""
        if rows <= 0:
            return
        self.rows_dropped += rows
        self._failing = True
        if reason not in self.lost_by_reason:
            log.warning("flight log write failed: rows lost", path=str(self.path),
                        rows_lost=rows, error=reason)
        self.lost_by_reason[reason] = self.lost_by_reason.get(reason, 0) + rows

    def _allocate(self, end: int) -> None:
        """Have flight.npy allocated up to ``end`` bytes. OSError when the disk has no
        room; where posix_fallocate cannot allocate, plain writes from then on."""
        if not self._preallocate or end <= self._allocated:
            return
        try:
            os.posix_fallocate(self._fd, self._allocated, end - self._allocated)
        except OSError as exc:
            if exc.errno in _NO_ROOM:
                raise
            self._preallocate = False
            log.info("flight log: no space reserved (cannot allocate here)",
                     path=str(self.path), error=_why(exc))
            return
        self._allocated = end

    def finish(self) -> None:
        """End the rows: write the buffered ones (into the reserve), give the unused
        reserve back to the disk, fsync and close flight.npy. Idempotent; errors are
        logged and counted, not raised (it runs while landing or unwinding from another
        error). :meth:`loss` is final after it; :meth:`close` then writes meta.json."""
        if self._fd < 0:
            return
        self._flush_due = time.monotonic() + self._interval
        self._write_rows(final=True)
        try:  # the unused reserve back to the disk
            os.ftruncate(self._fd, _HEADER_LEN + self._on_disk * RECORD_DTYPE.itemsize)
        except OSError as exc:
            log.warning("flight log trim failed", path=str(self.path), error=_why(exc))
        try:
            os.fsync(self._fd)
        except OSError as exc:
            log.warning("flight log fsync failed", path=str(self.path), error=_why(exc))
        os.close(self._fd)
        self._fd = -1
        self._buf = self._buf[:0]  # later appends hit IndexError and are counted, not written
        self._cols = _columns(self._buf)

    def loss(self) -> LogLoss:
        """What the log is missing so far (final after :meth:`finish`; after
        :meth:`close` also whether meta.json was written)."""
        reasons = dict(self.lost_by_reason)
        if self.bad_rows:
            reasons["values that did not fit the record"] = self.bad_rows
        return LogLoss(rows=self._on_disk, lost=self.rows_dropped + self.bad_rows,
                       reasons=reasons, meta_error=self.meta_error)

    def close(self) -> None:
        """:meth:`finish`, then add end time and counters to meta.json and write it into
        its reserve, renamed over the old one (atomic).

        Idempotent. Errors are logged (and :attr:`meta_error` says why), not raised.
        """
        self.finish()
        if self._meta_fd < 0:
            return
        self.meta.update(
            end_time=dt.datetime.now(dt.UTC).isoformat(), end_monotonic=time.monotonic(),
            rows=self._on_disk, rows_dropped=self.rows_dropped,
            lost_rows_by_reason=dict(self.lost_by_reason),
            bad_rows=self.bad_rows, write_errors=self.write_errors,
        )
        fd, self._meta_fd = self._meta_fd, -1
        reserve = self.directory / META_RESERVE_FILE
        try:
            data = _json_bytes(self.meta)
            _pwrite_all(fd, memoryview(data), 0)
            os.ftruncate(fd, len(data))
            os.fsync(fd)
            os.replace(reserve, self.directory / META_FILE)
        except (OSError, TypeError, ValueError) as exc:
            self.meta_error = _why(exc) if isinstance(exc, OSError) else str(exc)
            log.warning("flight log meta.json not updated", path=str(self.directory),
                        error=self.meta_error)
            with contextlib.suppress(OSError):
                reserve.unlink()
        finally:
            os.close(fd)

    def __enter__(self) -> FlightRecorder:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


_EST_FIELDS = tuple(name for name, *_ in _SCHEMA if name.startswith("est_"))


def read_flight(path: str | Path) -> tuple[npt.NDArray[np.void], dict[str, Any], str]:
    """Read a flight log: ``(rows as RECORD_DTYPE, meta dict, config YAML text)``.

    path : the flight directory or its flight.npy. Works on the log of a flight
    still running or killed (rows up to the last flush), and on a log of an older
    schema whose columns this one has (the new columns filled: NaN, 0, False). Raises
    RecorderError if the files are missing or unreadable.
    """
    p = Path(path)
    if not p.exists():
        raise RecorderError(f"{p}: not a readable flight log: no such file or directory")
    directory = p if p.is_dir() else p.parent
    try:
        flat = np.load(directory / FLIGHT_FILE)
        meta = json.loads((directory / META_FILE).read_text(encoding="utf-8"))
        config = (directory / CONFIG_FILE).read_text(encoding="utf-8")
    except (OSError, ValueError) as exc:
        raise RecorderError(f"{directory}: not a readable flight log: {exc}") from exc
    if flat.dtype != FLAT_DTYPE:
        flat = _migrated(flat, directory, meta)
    return flat.view(RECORD_DTYPE), meta, config


def _migrated(flat: npt.NDArray[np.void], directory: Path,
              meta: dict[str, Any]) -> npt.NDArray[np.void]:
    """An older log read into this schema: its columns copied (widened where a column
    grew), columns it lacks filled (NaN, 0, False); ``meta["migrated_from_schema"]`` says
    so. RecorderError for a log whose columns this schema does not all have."""
    names = FLAT_DTYPE.names or ()
    old = flat.dtype.names or ()
    if not old or not set(old) <= set(names):
        raise RecorderError(f"{directory}: flight log schema {meta.get('schema_version')!r} "
                            f"is not this version's ({SCHEMA_VERSION}) and cannot be read "
                            "into it")
    out = np.zeros(len(flat), dtype=FLAT_DTYPE)
    for name in names:
        if FLAT_DTYPE[name].kind == "f":
            out[name] = np.nan
    for name in old:
        out[name] = flat[name]
    meta["migrated_from_schema"] = meta.get("schema_version")
    return out
