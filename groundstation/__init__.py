"""Ground station for an AscTec X-3D quadrotor flown in a Vicon motion-capture lab.

Conventions used throughout the package (README, "Conventions"):

* SI units inside; RC stick units only at the serial-protocol edge.
* Earth frame NED (x north, y east, z down), body frame FRD (x forward, y right,
  z down). Hovering 1 m above the floor is ``z = -1``.
* Quaternions are scalar-first ``[q0, q1, q2, q3]``, Hamilton product, unit
  norm. ``q`` is the attitude of the body: its rotation matrix ``R(q)`` is
  ``eCb`` (body -> earth coordinates) and ``bCe = R(q).T``; in scipy,
  ``Rotation.from_quat(q, scalar_first=True).as_matrix() == eCb``. Kinematics:
  ``q_dot = 0.5 * q ⊗ [0, omega]`` with ``omega`` the body rates (FRD) [rad/s].
* Times are seconds on the monotonic clock (``time.monotonic()``).

The package stands in layers (:data:`LAYERS`, drawn in docs/architecture.md): a module
imports only its own unit and units of the layers below, never one above or beside it,
and nothing imports in a circle (``tests/test_layers.py`` checks it from the source).
"""

__version__ = "0.1.0"

LAYERS: tuple[tuple[str, ...], ...] = (
    ("errors", "types", "endpoints", "logs", "timing", "lazy"),  # the foundation: no
    # import of the package
    ("model",),  # physics and the thesis's numbers
    ("config", "asctec", "vicon", "estimation", "control"),  # the YAML schema; the pure
    # codecs, filters and controllers with their plain parameter records: none knows another
    ("telemetry", "lab"),  # the publisher, request socket and schema; the virtual lab's face
    ("flight",),  # the flight without I/O and its assembly
    ("fleet",),  # a vehicle's part in a fleet: Zenoh session, relay, pose source, peers, node
    ("app", "client"),  # the real-time daemon, gs fly, the in-process runner, the recorder;
    # the Python clients of one vehicle and of a fleet
    ("fleetops",),  # running a fleet: gs fleet up's processes, the virtual fleet, the demo
    ("evaluation", "export"),  # after a flight: metrics, figures, reports; CSV/Parquet/MCAP
    ("identification", "calibration", "linkcheck"),  # the lab's measuring tools
    ("cli",),  # the gs command
    ("__main__",),  # python -m groundstation
)
"""The package's units (its top-level subpackages and modules), bottom layer first."""
