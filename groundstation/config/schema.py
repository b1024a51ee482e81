"""The whole configuration file: one field per section."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, SerializeAsAny, SkipValidation

from groundstation.config.base import ConfigModel
from groundstation.config.controller import ControllerConfig
from groundstation.config.link import ChannelsConfig, SerialConfig, ViconConfig
from groundstation.config.mission import SafetyConfig, TrajectoryConfig
from groundstation.config.services import ApiConfig, LoggingConfig, RealtimeConfig, TelemetryConfig
from groundstation.config.vehicle import EstimatorConfig, VehicleConfig


class GroundStationConfig(ConfigModel):
    """The whole configuration file."""

    serial: SerialConfig = SerialConfig()
    channels: ChannelsConfig = ChannelsConfig()
    vicon: ViconConfig = ViconConfig()
    vehicle: VehicleConfig = VehicleConfig()
    estimator: EstimatorConfig = EstimatorConfig()
    controller: ControllerConfig = ControllerConfig()
    trajectory: TrajectoryConfig = TrajectoryConfig()
    safety: SafetyConfig = SafetyConfig()
    telemetry: TelemetryConfig = TelemetryConfig()
    logging: LoggingConfig = LoggingConfig()
    realtime: RealtimeConfig = RealtimeConfig()
    api: ApiConfig = ApiConfig()
    sim: SkipValidation[SerializeAsAny[BaseModel] | dict[str, Any] | None] = None
    # the virtual lab's section (config/sim.yaml): the ground station never reads it; kept
    # as given here, validated by the installed lab where the configuration is assembled
    # (groundstation.flight.assembly.check_config), as the lab's own model from then on


