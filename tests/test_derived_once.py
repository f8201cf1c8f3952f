"""The twist step of a pose grid is one rule, on its twist axis (:meth:`TwistAxis.step_deg_for`)."""

from __future__ import annotations

from patterns.geometry import square
from patterns.raster import mask_from_geometry
from simulator.landscape import PoseGrid, build_landscape
from simulator.scene import Effects, Scene, TwistAxis


def small_scene(**kw) -> Scene:
    """A 200 um square on its own pad at 4 um/px, untwisted: cheap to build."""
    kw.setdefault("effects", Effects(twist=False))
    return Scene(pattern=mask_from_geometry(square(200), 4.0, margin_um=20), chip=mask_from_geometry(square(200), 4.0), **kw)


# ---------------------------------------------------------------- the twist step
def test_one_rule_for_the_twist_step_of_a_pose_grid():
    axis = TwistAxis(None, 2.0, -22, 45, True, 90.0, True)
    assert axis.grid_step_deg == axis.step_deg_for(45) == 2.0
    whole = PoseGrid((45, 3, 3), 1.0, axis, wrap=True)
    one = PoseGrid((1, 3, 3), 1.0, axis, t_first=4)
    assert whole.twist_step_deg == axis.grid_step_deg == 2.0
    assert one.twist_step_deg == axis.step_deg_for(1) == 1.0
    untwisted = small_scene().twist_axis
    assert untwisted.count == 1 and untwisted.grid_step_deg == 1.0 == build_landscape(small_scene()).twist_step_deg


