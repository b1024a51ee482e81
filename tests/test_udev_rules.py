"""The udev rules shipped in config/ read as udev reads them (udev(7): comma-separated
``KEY[{attribute}]OPERATOR"value"`` pairs; match keys compare, assignment keys assign),
and the radio's rule does what docs/lab-setup.md says: /dev/x3d for an FTDI FT232R, group
dialout, ModemManager kept off, a 1 ms latency timer for every ftdi_sio port."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
RULES = sorted((REPO / "config").glob("*.rules"))

# udev(7): the keys a rule may match on, and those it may assign
MATCH_KEYS = {"ACTION", "DEVPATH", "KERNEL", "KERNELS", "NAME", "SYMLINK", "SUBSYSTEM",
              "SUBSYSTEMS", "DRIVER", "DRIVERS", "ATTR", "ATTRS", "SYSCTL", "ENV", "CONST",
              "TAG", "TAGS", "TEST", "PROGRAM", "RESULT"}
ASSIGN_KEYS = {"NAME", "SYMLINK", "OWNER", "GROUP", "MODE", "SECLABEL", "ATTR", "SYSCTL",
               "ENV", "TAG", "RUN", "LABEL", "GOTO", "IMPORT", "OPTIONS"}
PAIR = re.compile(r'^(?P<key>[A-Z_]+)(?:\{(?P<attr>[^}]+)\})?(?P<op>==|!=|\+=|-=|:=|=)'
                  r'"(?P<value>[^"]*)"$')


def rules(path: Path) -> list[list[tuple[str, str | None, str, str]]]:
    """Each rule of ``path`` as its (key, attribute, operator, value) pairs."""
    out = []
    for line in path.read_text(encoding="utf-8").splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        pairs = []
        for token in (t.strip() for t in line.split(",")):
            m = PAIR.match(token)
            assert m is not None, f"{path.name}: not KEY[{{attr}}]OP\"value\": {token!r}"
            pairs.append((m["key"], m["attr"], m["op"], m["value"]))
        out.append(pairs)
    return out


@pytest.mark.parametrize("path", RULES, ids=lambda p: p.name)
def test_every_rule_is_well_formed(path: Path) -> None:
    found = rules(path)
    assert found, f"{path.name} has no rule"
    for rule in found:
        for key, _attr, op, _value in rule:
            matching = op in ("==", "!=")
            allowed = MATCH_KEYS if matching else ASSIGN_KEYS
            kind = "match" if matching else "assignment"
            assert key in allowed, f"{path.name}: {key}{op} is no udev {kind}"
        assert any(op in ("==", "!=") for _k, _a, op, _v in rule), "a rule matches something"


def test_the_radio_rule() -> None:
    name, latency = rules(REPO / "config" / "99-groundstation-radio.rules")
    as_dict = {(k, a, op): v for k, a, op, v in name}
    assert as_dict[("SUBSYSTEM", None, "==")] == "tty"
    assert as_dict[("ATTRS", "idVendor", "==")] == "0403"  # FTDI
    assert as_dict[("ATTRS", "idProduct", "==")] == "6001"  # FT232R, the XBee adapters'
    assert as_dict[("SYMLINK", None, "+=")] == "x3d"
    assert as_dict[("GROUP", None, "=")] == "dialout"
    assert as_dict[("MODE", None, "=")] == "0660"
    assert as_dict[("ENV", "ID_MM_DEVICE_IGNORE", "=")] == "1"
    timer = {(k, a, op): v for k, a, op, v in latency}
    assert timer[("SUBSYSTEM", None, "==")] == "usb-serial"
    assert timer[("DRIVER", None, "==")] == "ftdi_sio"
    assert timer[("ATTR", "latency_timer", "=")] == "1"
    # the service may open what the rule names (the symlink points at a ttyUSB node)
    service = (REPO / "config" / "groundstation.service").read_text(encoding="utf-8")
    assert "DeviceAllow=char-ttyUSB rw" in service
