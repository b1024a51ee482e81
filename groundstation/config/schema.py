"""The whole configuration file: one field per section."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, SerializeAsAny, SkipValidation, model_validator

from groundstation.config.base import ConfigModel, FieldValueError
from groundstation.config.controller import ControllerConfig
from groundstation.config.fleet import FleetConfig
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
    fleet: FleetConfig | None = None
    # this vehicle in a fleet (fleet.yaml writes it): null flies alone
    sim: SkipValidation[SerializeAsAny[BaseModel] | dict[str, Any] | None] = None
    # the virtual lab's section (config/sim.yaml): the ground station never reads it; kept
    # as given here, validated by the installed lab where the configuration is assembled
    # (groundstation.flight.assembly.check_config), as the lab's own model from then on

    @model_validator(mode="after")
    def _vicon_source(self) -> GroundStationConfig:
        if self.vicon.source == "zenoh" and self.fleet is None:
            raise FieldValueError("vicon.source", "zenoh", "takes the poses from the fleet's "
                                  "relay: it needs a fleet: section (name, zenoh endpoints)")
        return self
