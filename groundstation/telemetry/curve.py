"""CURVE authentication of the request socket (``gs channels``): key files and the ZAP check.

A request socket bound beyond loopback must authenticate its clients: the
daemon is the CURVE server and answers only clients whose public key lies in a
directory of authorised keys. Keys are the certificate files pyzmq writes::

    python -c "import zmq.auth; zmq.auth.create_certificates('.', 'server')"
    # -> server.key (public: give it to the clients), server.key_secret (the daemon's)
    python -c "import zmq.auth; zmq.auth.create_certificates('.', 'alice')"
    # -> alice.key (copy it into the daemon's clients directory), alice.key_secret (hers)

The daemon names ``telemetry.control_server_key`` (``server.key_secret``) and
``telemetry.control_client_keys`` (the directory of ``*.key``); a client runs
``gs channels --server-key server.key --client-key alice.key_secret``.

Loading checks what the socket would otherwise refuse later with a bare EINVAL: both
halves present, 40-character Z85 keys, a secret key that belongs to its public key.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import zmq
import zmq.auth
from zmq.utils import z85

from groundstation.errors import TelemetryError

T = TypeVar("T")


@dataclass(frozen=True)
class CurveServer:
    """The server's key pair (Z85 bytes) and the authorised clients' public keys."""

    public: bytes
    secret: bytes = field(repr=False)
    clients: frozenset[bytes]

    def apply(self, sock: zmq.Socket[Any]) -> None:
        """Make ``sock`` a CURVE server (before it binds)."""
        sock.setsockopt(zmq.CURVE_SERVER, 1)
        sock.setsockopt(zmq.CURVE_PUBLICKEY, self.public)
        sock.setsockopt(zmq.CURVE_SECRETKEY, self.secret)


@dataclass(frozen=True)
class CurveClient:
    """A client's key pair and the server's public key (Z85 bytes)."""

    public: bytes
    secret: bytes = field(repr=False)
    server: bytes

    def apply(self, sock: zmq.Socket[Any]) -> None:
        """Make ``sock`` a CURVE client of :attr:`server` (before it connects)."""
        sock.setsockopt(zmq.CURVE_SERVERKEY, self.server)
        sock.setsockopt(zmq.CURVE_PUBLICKEY, self.public)
        sock.setsockopt(zmq.CURVE_SECRETKEY, self.secret)


class ClientKeyCheck:
    """ZAP credentials provider: admits the public keys in ``clients``, counts refusals.

    Called from pyzmq's authenticator thread (``configure_curve_callback``).
    """

    def __init__(self, clients: frozenset[bytes]) -> None:
        self._clients = clients
        self.refused = 0
        """Handshakes refused for an unknown client key."""

    def callback(self, domain: str, key: bytes) -> bool:
        if key in self._clients:
            return True
        self.refused += 1
        return False


def _require_curve() -> None:
    if not zmq.has("curve"):
        raise ValueError("this libzmq was built without CURVE security")


def _z85_key(key: bytes) -> bytes:
    try:
        if len(key) == 40 and len(z85.decode(key)) == 32:
            return key
    except ValueError:
        pass
    raise ValueError("not a 40-character Z85 key")


def read_key_pair(path: str | os.PathLike[str]) -> tuple[bytes, bytes]:
    """(public, secret) Z85 keys from a ``.key_secret`` certificate file.

    Raises ValueError with the reason (no such file, no secret key, keys that do not
    belong together).
    """
    _require_curve()
    public, secret = _read_certificate(Path(path))
    if secret is None:
        raise ValueError("no secret key in it (the .key_secret file of "
                         "zmq.auth.create_certificates is needed)")
    if zmq.curve_public(_z85_key(secret)) != public:
        raise ValueError("its secret key does not belong to its public key")
    return public, secret


def read_public_key(path: str | os.PathLike[str]) -> bytes:
    """The public Z85 key of a certificate file (``.key`` or ``.key_secret``); ValueError."""
    return _read_certificate(Path(path))[0]


def read_public_keys(directory: str | os.PathLike[str]) -> frozenset[bytes]:
    """The public keys of every ``*.key`` certificate in ``directory``; ValueError naming a
    file that is not one, or if there are none."""
    folder = Path(directory)
    if not folder.is_dir():
        raise ValueError("not a directory" if folder.exists() else "no such directory")
    keys = set()
    for path in sorted(folder.glob("*.key")):
        try:
            keys.add(read_public_key(path))
        except ValueError as exc:
            raise ValueError(f"{path.name}: {exc}") from None
    if not keys:
        raise ValueError("holds no client public keys (*.key): nobody could connect")
    return frozenset(keys)


def _read_certificate(path: Path) -> tuple[bytes, bytes | None]:
    if not path.is_file():
        raise ValueError("no such file" if not path.exists() else "not a file")
    try:
        public, secret = zmq.auth.load_certificate(path)
    except OSError as exc:
        raise ValueError(f"cannot read it: {exc.strerror or exc}") from None
    except ValueError:
        raise ValueError("no public key in it (not a zmq certificate)") from None
    return _z85_key(public), secret


def _load(what: str, path: str | os.PathLike[str], read: Callable[[str | os.PathLike[str]], T]
          ) -> T:
    """``read(path)``, its ValueError raised again as a TelemetryError naming ``what``."""
    try:
        return read(path)
    except ValueError as exc:
        raise TelemetryError(f"{what} {str(path)!r}: {exc}") from None


def load_server_keys(secret_file: str | os.PathLike[str],
                     clients_dir: str | os.PathLike[str]) -> CurveServer:
    """The daemon's key pair and the authorised clients' public keys (``*.key``).

    Raises TelemetryError naming the file or directory that cannot be used.
    """
    public, secret = _load("control server key", secret_file, read_key_pair)
    return CurveServer(public, secret,
                       _load("control client keys", clients_dir, read_public_keys))


def load_client_keys(secret_file: str | os.PathLike[str],
                     server_public_file: str | os.PathLike[str]) -> CurveClient:
    """A client's key pair and the server's public key; TelemetryError naming a bad file."""
    public, secret = _load("client key", secret_file, read_key_pair)
    return CurveClient(public, secret,
                       _load("server key", server_public_file, read_public_key))
