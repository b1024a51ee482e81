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
"""

__version__ = "0.1.0"
