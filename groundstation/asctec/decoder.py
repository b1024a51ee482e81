"""Sans-IO frame codec for the framed AscTec serial stream (X-3D spec section 2).

Both dialects frame their packets alike (``>*>``, length, descriptor, payload,
CRC16, ``<#<``) but give the descriptors different meanings, so a decoder takes
its dialect's descriptor table (:class:`FrameDecoder`): :class:`StreamDecoder`
is the X-3D's, :class:`groundstation.asctec.ll.LlDecoder` the AscTec LL
dialect's, and a packet of one dialect is never taken for the other's (the LL
IMU_RAWDATA and the X-3D DATA share descriptor 0x01). The LL decoder also finds
the 5-byte acknowledgements (``>a`` + byte + ``a<``) between frames.

A decoder is a pure state machine: ``feed(bytes)`` returns the
messages and :class:`RejectedFrame` records completed by those bytes, in stream
order. It never raises on bad input. After any rejection it resumes scanning at
the byte after the rejected start marker's first byte, so a valid frame that
begins inside a rejected candidate (or inside garbage) is still found. A length
field that no valid payload of the descriptor can have is rejected at once,
so a corrupted length never makes the decoder wait.

A candidate whose length is plausible holds back the bytes after it until it is
complete (at most :data:`MAX_FRAME_SIZE` bytes from its start); only then is it
accepted or rejected. In a live stream that costs at most one frame of latency.

:func:`encode_frame` is the inverse: message -> frame bytes.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Final, Generic, Protocol, TypeVar

from groundstation.asctec.crc import DEFAULT_PROFILE, crc16, profile_init
from groundstation.asctec.messages import (
    MAX_PAYLOAD_SIZE,
    MESSAGE_TYPES,
    Message,
    PayloadError,
    RejectReason,
)

START_MARKER: Final = b">*>"
END_MARKER: Final = b"<#<"
HEADER_SIZE: Final = 6  # start marker, uint16 length, uint8 descriptor
TRAILER_SIZE: Final = 5  # uint16 CRC, end marker
FRAME_OVERHEAD: Final = HEADER_SIZE + TRAILER_SIZE
MAX_FRAME_SIZE: Final = MAX_PAYLOAD_SIZE + FRAME_OVERHEAD

_LENGTH_DESCRIPTOR: Final = struct.Struct("<HB")
_CRC: Final = struct.Struct("<H")
ACK_START: Final = b">a"
ACK_END: Final = b"a<"
ACK_SIZE: Final = 5


class FrameType(Protocol):
    """A message class a decoder's descriptor table holds (a class, not an instance)."""

    DESCRIPTOR: ClassVar[int]
    NAME: ClassVar[str]
    PAYLOAD_SIZES: ClassVar[frozenset[int]]

    @classmethod
    def unpack(cls, payload: bytes) -> Any:
        """The message of a framed payload; PayloadError if it is not one."""
        ...


@dataclass(frozen=True, slots=True)
class Ack:
    """The LL dialect's acknowledgement of a command: ``>a`` + ``value`` + ``a<`` (the
    byte's meaning is not documented)."""

    value: int


class Packet(Protocol):
    """What a frame carries: a descriptor and a payload (any dialect's message)."""

    DESCRIPTOR: ClassVar[int]

    def pack(self) -> bytes:
        """The payload."""
        ...


def encode_frame(msg: Packet, profile: str = DEFAULT_PROFILE) -> bytes:
    """Frame bytes for ``msg``: marker, length, descriptor, payload, CRC16, end marker.

    profile : CRC profile name ("asctec", "kermit", "mcrf4xx").
    """
    payload = msg.pack()
    return b"".join(
        (
            START_MARKER,
            _LENGTH_DESCRIPTOR.pack(len(payload), msg.DESCRIPTOR),
            payload,
            _CRC.pack(crc16(payload, profile_init(profile))),
            END_MARKER,
        )
    )


@dataclass(frozen=True, slots=True)
class RejectedFrame:
    """A frame candidate the decoder rejected.

    reason : why (one counter per reason)
    descriptor : the descriptor byte of the candidate
    raw : the candidate's bytes from its start marker (as far as they were examined)
    """

    reason: RejectReason
    descriptor: int
    raw: bytes


@dataclass(frozen=True, slots=True)
class DecoderCounts:
    """Snapshot of a decoder's counters.

    bytes_in : bytes fed in total
    bytes_skipped : bytes that did not belong to an accepted frame
    frames : accepted messages by message name ("config", "command", "data")
    rejections : rejected candidates by :class:`RejectReason` value (every reason present)
    """

    bytes_in: int = 0
    bytes_skipped: int = 0
    frames: Mapping[str, int] = field(default_factory=dict)
    rejections: Mapping[str, int] = field(default_factory=dict)

    @property
    def rejected_total(self) -> int:
        """Sum of all rejection counters."""
        return sum(self.rejections.values())


M = TypeVar("M")


class FrameDecoder(Generic[M]):
    """Incremental decoder of a framed byte stream with one dialect's descriptor table.

    Parameters
    ----------
    types : descriptor -> message class (the dialect's table; nothing else is accepted).
    profile : CRC profile name ("asctec" default, "kermit", "mcrf4xx").
    acks : also recognise the LL dialect's 5-byte acknowledgements between frames
        (:class:`Ack`; a ``>a`` not followed two bytes later by ``a<`` is rejected as
        BAD_ACK).
    """

    def __init__(self, types: Mapping[int, type[FrameType]], profile: str = DEFAULT_PROFILE,
                 *, acks: bool = False) -> None:
        self._crc_init = profile_init(profile)
        self._buf = bytearray()
        self._types: dict[int, type[FrameType]] = dict(types)
        self._acks = acks
        self._bytes_in = 0
        self._skipped = 0
        self._frames: dict[int, int] = dict.fromkeys(self._types, 0)
        self._ack_count = 0
        self._rejections: dict[RejectReason, int] = dict.fromkeys(RejectReason, 0)

    @property
    def buffered(self) -> int:
        """Bytes held back waiting for the rest of a frame (always < the largest frame)."""
        return len(self._buf)

    def counts(self) -> DecoderCounts:
        """A snapshot of the counters (acknowledgements count as frames named "ack")."""
        frames = {self._types[d].NAME: n for d, n in self._frames.items()}
        if self._acks:
            frames["ack"] = self._ack_count
        return DecoderCounts(
            bytes_in=self._bytes_in,
            bytes_skipped=self._skipped,
            frames=frames,
            rejections={r.value: n for r, n in self._rejections.items()},
        )

    def feed(self, data: bytes | bytearray) -> list[M | RejectedFrame]:
        """Add received bytes; return what they completed, in stream order. Never raises."""
        buf = self._buf
        buf += data
        self._bytes_in += len(data)
        out: list[M | RejectedFrame] = []
        pos = 0
        n = len(buf)
        while True:
            start = buf.find(START_MARKER, pos)
            if self._acks:
                ack = buf.find(ACK_START, pos, start if start >= 0 else n)
                if ack >= 0:
                    start = ack
            if start < 0:
                # Keep a possible partial marker (up to 2 bytes) at the end.
                keep = max(pos, n - (len(START_MARKER) - 1))
                self._skipped += keep - pos
                pos = keep
                break
            self._skipped += start - pos
            pos = start
            if buf[pos + 1:pos + 2] == b"a":
                if n - pos < ACK_SIZE:
                    break
                item, pos = self._examine_ack(buf, pos)
                out.append(item)
                continue
            if n - pos < HEADER_SIZE:
                break
            examined = self._examine(buf, pos, n)
            if examined is None:  # incomplete candidate: wait for more bytes
                break
            frame, pos = examined
            out.append(frame)
        del buf[:pos]
        return out

    def _examine_ack(self, buf: bytearray, pos: int) -> tuple[M | RejectedFrame, int]:
        if buf[pos + 3:pos + ACK_SIZE] != ACK_END:
            self._rejections[RejectReason.BAD_ACK] += 1
            self._skipped += 1
            return RejectedFrame(RejectReason.BAD_ACK, -1, bytes(buf[pos:pos + ACK_SIZE])), pos + 1
        self._ack_count += 1
        ack: Any = Ack(buf[pos + 2])
        return ack, pos + ACK_SIZE

    def _examine(self, buf: bytearray, pos: int, n: int) -> tuple[M | RejectedFrame, int] | None:
        """Judge the candidate at ``buf[pos]`` (a start marker, header present).

        Returns (item, where to continue scanning), or None if more bytes are needed.
        """
        length, descriptor = _LENGTH_DESCRIPTOR.unpack_from(buf, pos + 3)
        cls = self._types.get(descriptor)
        if cls is None:
            return self._reject(RejectReason.UNKNOWN_DESCRIPTOR, buf, pos, HEADER_SIZE)
        if length not in cls.PAYLOAD_SIZES:
            return self._reject(RejectReason.BAD_LENGTH, buf, pos, HEADER_SIZE)
        end = pos + FRAME_OVERHEAD + length
        if end > n:
            return None
        if buf[end - 3 : end] != END_MARKER:
            return self._reject(RejectReason.BAD_END, buf, pos, end - pos)
        payload_end = pos + HEADER_SIZE + length
        payload = bytes(buf[pos + HEADER_SIZE : payload_end])
        if crc16(payload, self._crc_init) != buf[payload_end] | buf[payload_end + 1] << 8:
            return self._reject(RejectReason.BAD_CRC, buf, pos, end - pos)
        try:
            msg: M = cls.unpack(payload)
        except PayloadError as exc:
            return self._reject(exc.reason, buf, pos, end - pos)
        self._frames[descriptor] += 1
        return msg, end

    def _reject(
        self, reason: RejectReason, buf: bytearray, pos: int, size: int
    ) -> tuple[RejectedFrame, int]:
        """Count a rejection and resume scanning one byte after the rejected marker."""
        self._rejections[reason] += 1
        self._skipped += 1
        return RejectedFrame(reason, buf[pos + 5], bytes(buf[pos : pos + size])), pos + 1


class StreamDecoder(FrameDecoder[Message]):
    """Incremental decoder of an X-3D byte stream (either direction, all descriptors).

    Parameters
    ----------
    profile : CRC profile name ("asctec" default, "kermit", "mcrf4xx").
    """

    def __init__(self, profile: str = DEFAULT_PROFILE) -> None:
        super().__init__(MESSAGE_TYPES, profile)
