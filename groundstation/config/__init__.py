"""Configuration: pydantic models for every part of the ground station.

A configuration is one YAML file (``config/lab.yaml`` for the real lab,
``config/sim.yaml`` for the virtual lab). :func:`load_config` reads and
validates it; any problem raises :class:`~groundstation.errors.ConfigError`
whose message names the field path, the offending value and the reason, one
line per problem. Unknown keys are errors (a typo must not silently fall back
to a default), and so are a key given twice, a number that is a boolean, a
fraction where an integer is meant, any infinite or NaN number (see
:class:`ConfigModel`), and a number outside its physical range (each range with its
source: :mod:`.ranges`). :func:`check_files` checks the files a configuration names.

Every numeric default names its source in a comment: a thesis equation or
table ("eq. 3.7", "Table 6.2"), the spec, or the reason it was chosen where the
thesis is silent or its printed equation has a typo (derived again and tested).

Single fields can be overridden (the ``gs fly --serial-port ...`` options) with
:func:`apply_overrides`, which re-validates the whole model so an override is
checked exactly like the file.

This layer knows no module that uses it: it imports only the exception tree, the
shared types, the endpoint grammar and the model's declarations its defaults come from.
The configuration becomes the flight's parameter records in one place,
:mod:`groundstation.flight.assembly`, which also runs the checks that need other modules
(the virtual lab's ``sim:`` section, the CURVE key files).

Modules: :mod:`.ranges` (physical ranges), :mod:`.base` (the strict model),
:mod:`.link` (serial, channels, vicon), :mod:`.vehicle` (vehicle, estimator),
:mod:`.controller`, :mod:`.mission` (trajectory, safety), :mod:`.services` (telemetry,
logging, realtime, api), :mod:`.fleet` (this vehicle in a fleet), :mod:`.schema` (the
whole file), :mod:`.files` (reading it), and :mod:`.fleetfile` (a fleet's fleet.yaml: one
configuration for each of its vehicles).
"""

from groundstation.config.base import ConfigModel, Covariance, FieldValueError
from groundstation.config.controller import (
    ControllerConfig,
    ControllerType,
    ExternalForceConfig,
    HinfConfig,
    LqrConfig,
    LqrFfConfig,
    PidConfig,
)
from groundstation.config.files import (
    MAX_FILE_BYTES,
    MAX_YAML_VALUES,
    Problem,
    apply_overrides,
    check_files,
    describe_problems,
    dump_config,
    file_problems,
    key_lines,
    load_config,
    raise_problems,
    validate_config,
    validation_problems,
)
from groundstation.config.fleet import (
    FLEET_NAME,
    RESERVED_NAMES,
    FleetConfig,
    FleetName,
    ZenohConfig,
)
from groundstation.config.link import (
    ChannelsConfig,
    LlConfig,
    RotationConfig,
    SerialConfig,
    ViconConfig,
)
from groundstation.config.mission import SafetyConfig, TrajectoryConfig, TrajectoryName
from groundstation.config.ranges import (
    COMMAND_RATE_MAX_HZ,
    DAY_S,
    FLIGHT_MAX_S,
    LAB_EXTENT_M,
    NYQUIST_RAD_S,
    VICON_RATE_MAX_HZ,
    CommandDelay,
    DirectoryPath,
    FifoPriority,
    FilePath,
    HostAddress,
    LabCoordinate,
    LabLength,
    TurnDeg,
    ZenohEndpoint,
    ZmqEndpoint,
    magnitude_within,
    within,
)
from groundstation.config.schema import GroundStationConfig
from groundstation.config.services import ApiConfig, LoggingConfig, RealtimeConfig, TelemetryConfig
from groundstation.config.vehicle import EstimatorConfig, VehicleConfig
from groundstation.endpoints import zenoh_endpoint, zenoh_local, zmq_endpoint
from groundstation.errors import ConfigError
from groundstation.types import Channel

__all__ = [
    "COMMAND_RATE_MAX_HZ",
    "DAY_S",
    "FLEET_NAME",
    "FLIGHT_MAX_S",
    "LAB_EXTENT_M",
    "MAX_FILE_BYTES",
    "MAX_YAML_VALUES",
    "NYQUIST_RAD_S",
    "RESERVED_NAMES",
    "VICON_RATE_MAX_HZ",
    "ApiConfig",
    "Channel",
    "ChannelsConfig",
    "CommandDelay",
    "ConfigError",
    "ConfigModel",
    "ControllerConfig",
    "ControllerType",
    "Covariance",
    "DirectoryPath",
    "EstimatorConfig",
    "ExternalForceConfig",
    "FieldValueError",
    "FifoPriority",
    "FilePath",
    "FleetConfig",
    "FleetName",
    "GroundStationConfig",
    "HinfConfig",
    "HostAddress",
    "LabCoordinate",
    "LabLength",
    "LlConfig",
    "LoggingConfig",
    "LqrConfig",
    "LqrFfConfig",
    "PidConfig",
    "Problem",
    "RealtimeConfig",
    "RotationConfig",
    "SafetyConfig",
    "SerialConfig",
    "TelemetryConfig",
    "TrajectoryConfig",
    "TrajectoryName",
    "TurnDeg",
    "VehicleConfig",
    "ViconConfig",
    "ZenohConfig",
    "ZenohEndpoint",
    "ZmqEndpoint",
    "apply_overrides",
    "check_files",
    "describe_problems",
    "dump_config",
    "file_problems",
    "key_lines",
    "load_config",
    "magnitude_within",
    "raise_problems",
    "validate_config",
    "validation_problems",
    "within",
    "zenoh_endpoint",
    "zenoh_local",
    "zmq_endpoint",
]
