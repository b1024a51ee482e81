"""The volume check at its edge: a path that touches the allowed box exactly is inside (its
proven extent may pass the side by a fraction of a millimetre), a centimetre beyond is
outside. Sides and ceiling lose the margin; the floor has none."""

from __future__ import annotations

import pytest

from groundstation.control.feasibility import FlightLimits, Volume, check_feasibility
from groundstation.control.shaping import min_jerk_path
from groundstation.control.trajectories import waypoints_from_rows
from groundstation.errors import TrajectoryError

VOLUME = Volume(x=(-1.5, 1.5), y=(-1.5, 1.5), z=(-2.0, 0.05), margin_m=0.1, name="safety.volume")


def path_to(x: float, z: float) -> object:
    """Rest at 1 m, go to (x, 0, z) and back, 4 s a leg (corners passed at rest)."""
    return min_jerk_path(waypoints_from_rows([[0, 0, 0, -1], [4, x, 0, z], [8, 0, 0, -1]]))


@pytest.mark.parametrize(("x", "z"), [(1.4, -1.0), (0.0, -1.9), (0.0, 0.05)],
                         ids=["side", "ceiling", "floor"])
def test_a_path_that_touches_the_allowed_box_is_inside(x: float, z: float) -> None:
    check_feasibility(path_to(x, z), FlightLimits(), volume=VOLUME)  # type: ignore[arg-type]


@pytest.mark.parametrize(("x", "z", "text"), [
    (1.41, -1.0, "x = 1.41 m is outside safety.volume_x [-1.50, 1.50] less the 0.10 m margin"),
    (0.0, -1.91, "z = -1.91 m is outside safety.volume_z [-2.00, 0.05] less the 0.10 m margin"),
    (0.0, 0.06, "below the floor: outside safety.volume_z [-2.00, 0.05]"),
], ids=["side", "ceiling", "floor"])
def test_a_centimetre_beyond_is_outside(x: float, z: float, text: str) -> None:
    with pytest.raises(TrajectoryError, match="cannot be flown") as err:
        check_feasibility(path_to(x, z), FlightLimits(), volume=VOLUME)  # type: ignore[arg-type]
    assert text in str(err.value)
