"""The daemon's requests to the OS: PM QoS CPU wake-up latency and the GIL switch interval."""

from __future__ import annotations

import os
import struct
import sys
from pathlib import Path

import pytest
from structlog.testing import capture_logs

from groundstation.config import ConfigError, validate_config
from groundstation.loop.realtime import CPU_DMA_LATENCY, cpu_latency_request, switch_interval


def _open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def test_request_writes_a_native_s32_and_closes_the_file(tmp_path: Path) -> None:
    device = tmp_path / "cpu_dma_latency"
    device.write_bytes(b"")
    before = _open_fds()
    with cpu_latency_request(25, device) as held:
        assert held
        assert _open_fds() == before + 1  # held open: closing it drops the request
        assert device.read_bytes() == struct.pack("=i", 25)
    assert _open_fds() == before


def test_no_request_when_disabled(tmp_path: Path) -> None:
    device = tmp_path / "cpu_dma_latency"
    with cpu_latency_request(None, device) as held:
        assert not held
    assert not device.exists()


def test_missing_device_warns_and_the_block_still_runs(tmp_path: Path) -> None:
    ran = False
    with capture_logs() as logs, cpu_latency_request(0, tmp_path / "absent") as held:
        ran = True
        assert not held
    assert ran
    warning = [e for e in logs if e["log_level"] == "warning"]
    assert len(warning) == 1
    assert warning[0]["device"] == str(tmp_path / "absent")
    assert "No such file" in warning[0]["reason"]


@pytest.mark.skipif(not os.access(CPU_DMA_LATENCY, os.W_OK),
                    reason="needs write access to /dev/cpu_dma_latency")
def test_kernel_applies_the_request() -> None:
    """Reading the device returns the aggregate bound of every holder (the kernel's
    cpu_latency_qos_read); while our request is held it cannot exceed ours."""
    def current() -> int:
        with open(CPU_DMA_LATENCY, "rb") as f:
            return int(struct.unpack("=i", f.read(4))[0])

    with cpu_latency_request(17) as held:
        assert held
        assert current() <= 17


def test_switch_interval_is_restored_even_on_error() -> None:
    previous = sys.getswitchinterval()
    with pytest.raises(RuntimeError), switch_interval(0.0005):
        assert sys.getswitchinterval() == pytest.approx(0.0005)
        raise RuntimeError("boom")
    assert sys.getswitchinterval() == previous


def test_config_defaults_and_errors() -> None:
    cfg = validate_config({})
    assert cfg.realtime.cpu_dma_latency_us == 0
    assert cfg.realtime.switch_interval_ms == 0.5
    assert validate_config({"realtime": {"cpu_dma_latency_us": None}}).realtime.cpu_dma_latency_us \
        is None
    with pytest.raises(ConfigError) as err:
        validate_config({"realtime": {"cpu_dma_latency_us": -1, "switch_interval_ms": 0}})
    paths = [path for path, _value, _reason in err.value.problems]
    assert paths == ["realtime.cpu_dma_latency_us", "realtime.switch_interval_ms"]
