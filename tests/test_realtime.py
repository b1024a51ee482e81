"""The daemon's requests to the OS and the interpreter: PM QoS CPU wake-up latency, the
real-time scheduling policy, the GIL switch interval, the paced garbage collector."""

from __future__ import annotations

import os
import resource
import struct
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from structlog.testing import capture_logs

from groundstation.app.realtime import (
    CPU_DMA_LATENCY,
    CollectorPacer,
    cpu_latency_request,
    fifo_priority,
    switch_interval,
)
from groundstation.config import ConfigError, validate_config


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


@pytest.mark.slow
def test_collector_pacer_freezes_and_runs_full_collections_only_after_a_command() -> None:
    """No full collection in the middle of a tick; young ones go on."""
    import gc

    thresholds = gc.get_threshold()
    full: list[str] = []

    def watch(phase: str, info: dict[str, int]) -> None:
        if phase == "stop" and info["generation"] == 2:
            full.append("full")

    gc.callbacks.append(watch)
    try:
        with CollectorPacer() as pacer:
            assert gc.get_freeze_count() > 1000  # the start-up objects
            full.clear()
            keep = []
            for k in range(200_000):  # promote plenty to the oldest generation
                cycle: list[object] = [k]
                cycle.append(cycle)
                keep.append(cycle)
                if len(keep) > 5000:
                    keep.clear()
            assert not full  # the interpreter started none on its own
            assert gc.get_count()[2] >= thresholds[2]  # ... though it wanted one
            pacer.after_command()
            assert full == ["full"]
            pacer.after_command()
            assert full == ["full"]  # not due again: nothing promoted since
        assert pacer.stats.full == 1 and pacer.stats.young > 10
        assert 0.0 < pacer.stats.longest_full_s < 0.5
    finally:
        gc.callbacks.remove(watch)
    assert gc.get_threshold() == thresholds and gc.get_freeze_count() == 0


def test_collector_pacer_disabled_leaves_the_interpreter_alone() -> None:
    import gc

    thresholds = gc.get_threshold()
    with CollectorPacer(enabled=False) as pacer:
        assert gc.get_threshold() == thresholds and gc.get_freeze_count() == 0
        pacer.after_command()
    assert pacer.stats.full == 0


def test_new_config_keys_defaults() -> None:
    cfg = validate_config({})
    assert cfg.realtime.paced_gc is True
    assert cfg.safety.second_signal_after_s == 0.5
    assert cfg.safety.battery_land_v == 10.5 and cfg.safety.battery_grace_s == 10.0
    assert validate_config({"safety": {"battery_land_v": None}}).safety.battery_land_v is None
    with pytest.raises(ConfigError) as err:
        validate_config({"safety": {"second_signal_after_s": -1, "battery_grace_s": 0}})
    assert "second_signal_after_s" in str(err.value) and "battery_grace_s" in str(err.value)


def _may_use_fifo() -> bool:
    """Whether this process may take SCHED_FIFO (root, CAP_SYS_NICE or RLIMIT_RTPRIO)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except OSError:
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


@pytest.mark.skipif(not _may_use_fifo(), reason="needs CAP_SYS_NICE or RLIMIT_RTPRIO")
def test_fifo_priority_holds_for_the_thread_and_its_children_and_is_restored() -> None:
    seen: list[tuple[int, int]] = []

    def child() -> None:  # os.sched_* on pid 0 read the calling thread (Linux)
        seen.append((os.sched_getscheduler(0), os.sched_getparam(0).sched_priority))

    before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
    with fifo_priority(7) as held:
        assert held
        assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) == \
            (os.SCHED_FIFO, 7)
        thread = threading.Thread(target=child)
        thread.start()
        thread.join()
    assert seen == [(os.SCHED_FIFO, 7)]  # the serial and Vicon threads inherit it
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) == before


REFUSED = """
import os, resource, sys
from structlog.testing import capture_logs
from groundstation.app.realtime import fifo_priority
resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))
if os.geteuid() == 0:
    os.setuid(65534)  # nobody: root's capabilities (CAP_SYS_NICE) are gone
with capture_logs() as logs, fifo_priority(10) as held:
    ran = True
    policy = os.sched_getscheduler(0)
print(held, ran, policy == os.SCHED_OTHER, [e["event"] for e in logs])
"""


def test_fifo_priority_without_the_privilege_warns_and_runs_the_block() -> None:
    """An unprivileged user (RLIMIT_RTPRIO 0, no CAP_SYS_NICE: as root, the child runs as
    nobody) gets a warning and the normal policy, never an error."""
    out = subprocess.run([sys.executable, "-c", REFUSED], capture_output=True, text=True,
                         timeout=60, check=False)
    assert out.returncode == 0, out.stderr
    held, ran, normal, events = out.stdout.split(" ", 3)
    assert (held, ran, normal) == ("False", "True", "True")
    assert "real-time priority not held" in events


def test_fifo_priority_none_asks_nothing() -> None:
    before = os.sched_getscheduler(0)
    with fifo_priority(None) as held:
        assert not held and os.sched_getscheduler(0) == before
    assert resource.getrlimit(resource.RLIMIT_RTPRIO) is not None
