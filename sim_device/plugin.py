"""The virtual lab as the ground station sees it: the :class:`groundstation.lab.LabPlugin`
registered under the entry point ``groundstation.labs: virtual`` (pyproject.toml).

Imports are deferred to each method, so ``gs`` loading the plugin to add the lab's
commands costs no simulator import.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from groundstation.config import GroundStationConfig
    from groundstation.lab import Lab, RunningLab
    from sim_device.config import SimConfig


class VirtualLabPlugin:
    """The bundled virtual lab: X-3D plant, firmware and link, Vicon (``sim_device``)."""

    def validate_section(self, data: Any) -> SimConfig:
        """The ``sim:`` section as :class:`sim_device.config.SimConfig`."""
        from sim_device.config import SimConfig

        return SimConfig.model_validate(data)

    def in_process(self, config: GroundStationConfig) -> Lab:
        """A :class:`sim_device.lab.VirtualLab` for ``config``."""
        from sim_device.lab import VirtualLab

        return VirtualLab(config)

    def start(self, config: GroundStationConfig, workdir: Path
              ) -> AbstractContextManager[RunningLab]:
        """``gs sim-device`` for ``config`` in a child process
        (:class:`sim_device.realtime.SimDeviceProcess`); its truth file is
        ``sim.truth_file`` or a stamped file in the flight-log directory."""
        from sim_device.realtime import SimDeviceProcess

        return SimDeviceProcess.for_config(config, workdir)

    def commands(self) -> Sequence[tuple[str, Callable[..., Any]]]:
        """``gs sim-device`` and ``gs eval`` (:mod:`sim_device.cli`)."""
        # groundstation.cli first: it adds these commands at the end of its own import,
        # and sim_device.cli takes its option types from it (no import cycle either way)
        import groundstation.cli  # noqa: F401
        from sim_device.cli import COMMANDS

        return COMMANDS


PLUGIN = VirtualLabPlugin()
"""The object the entry point names."""
