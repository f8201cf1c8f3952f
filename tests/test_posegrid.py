"""The pose grid (simulator.landscape.PoseGrid): one object per landscape, carried by the
Landscape and passed to the steppers; its axes, validation, hashing and the twists a
build accepts."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

from foundation import InputError
from patterns.geometry import four_pad, mask_from_geometry, square
from simulator.landscape import PoseGrid, build_landscape, consecutive_runs, plan
from simulator.motion import field_and_grid
from simulator.scene import Scene, TwistAxis, TwistGrid

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("posegrid")


def scene(step_deg=5.0, **kw) -> Scene:
    return Scene(
        pattern=mask_from_geometry(four_pad(60, 10), 2.0),
        chip=mask_from_geometry(square(60), 2.0),
        twist=TwistGrid(step_deg=step_deg, **kw),
    )


def test_landscape_axes_are_its_grid_and_steps_are_the_scenes_exactly():
    s = scene(step_deg=0.1 * 30)  # 3.0000000000000004: a step that an array's ends would round
    ls = build_landscape(s)
    g = ls.grid
    assert isinstance(g, PoseGrid) and g.twist is s.twist_axis
    np.testing.assert_array_equal(ls.x_um, g.x_um())
    np.testing.assert_array_equal(ls.twist_deg, s.twist_axis.values())
    assert g.twist_step_deg == s.twist.step_deg and g.um_per_px == 2.0 and g.period_deg == 90.0
    assert g.rg_px == s.chip_rg_px > 0
    assert ls.energy.shape == g.shape
    idx = np.array([[0, 0, 0], [3, 5, 7], [g.shape[0] - 1, g.shape[1] - 1, g.shape[2] - 1]])
    np.testing.assert_allclose(g.to_index(g.to_pose(idx)), idx, atol=1e-12)
    np.testing.assert_array_equal(g.to_pose(idx)[:, 0], ls.x_um[idx[:, 2]])
    # The steppers' view carries the same grid.
    field, grid = field_and_grid(ls)
    assert grid is g and tuple(np.asarray(field.pin)) == (0.0, 0.0, 0.0) and not field.pinned


def test_a_run_of_the_axis_is_located_on_it_and_a_box_is_cut():
    s = scene()
    axis = s.twist_axis
    run = axis.values()[2:6]
    ls = build_landscape(s, twists=run, center_px=(0, 0), half_px=4)
    assert ls.grid.twist is axis and ls.grid.t_first == 2 and not ls.wrap
    np.testing.assert_array_equal(ls.twist_deg, run)  # bit for bit: the axis's own values
    assert ls.cut == ((True, True), (True, True), (True, True))
    full = build_landscape(s)
    assert full.wrap and full.cut == ((False, False),) * 3
    np.testing.assert_allclose(
        ls.energy,
        full.energy[
            2:6,
            full.grid.shape[1] // 2 - 4 : full.grid.shape[1] // 2 + 5,
            full.grid.shape[2] // 2 - 4 : full.grid.shape[2] // 2 + 5,
        ],
        rtol=0,
        atol=full.noise_floor_J,
    )


def test_twists_must_be_one_evenly_spaced_axis():
    s = scene()
    with pytest.raises(InputError, match="evenly spaced"):
        build_landscape(s, twists=[0.0, 5.0, 15.0])
    with pytest.raises(InputError, match="evenly spaced"):
        build_landscape(s, twists=[10.0, 5.0, 0.0])
    # Evenly spaced twists off the scene's axis get an axis of their own.
    ls = build_landscape(s, twists=[1.0, 3.0, 5.0])
    assert ls.grid.twist is not s.twist_axis and ls.twist_step_deg == pytest.approx(2.0)
    np.testing.assert_allclose(ls.twist_deg, [1.0, 3.0, 5.0], rtol=0, atol=1e-12)


def test_boxes_of_one_shape_share_a_compiled_stepper():
    g = build_landscape(scene(), center_px=(0, 0), half_px=4).grid
    moved = dataclasses.replace(g, x_first_px=g.x_first_px + 3, y_first_px=g.y_first_px - 2)
    assert moved == g and hash(moved) == hash(g)  # origins are host-side only
    assert moved.x0_um == g.x0_um + 6.0
    assert dataclasses.replace(g, rg_px=g.rg_px + 1) != g


def test_pose_grid_is_validated_and_frozen():
    axis = TwistAxis(None, 1.0, -2, 4, True, 4.0, False)
    PoseGrid((4, 3, 3), 1.0, axis, wrap=True)
    with pytest.raises(ValueError, match="three whole numbers"):
        PoseGrid((0, 3, 3), 1.0, axis)
    with pytest.raises(ValueError, match="um_per_px"):
        PoseGrid((4, 3, 3), float("nan"), axis)
    with pytest.raises(ValueError, match="wraps only"):
        PoseGrid((3, 3, 3), 1.0, axis, wrap=True)
    bounded = TwistAxis(-1.0, 0.5, 0, 5, False, 90.0, True)
    with pytest.raises(ValueError, match="outside the bounded axis"):
        PoseGrid((3, 3, 3), 1.0, bounded, t_first=3)
    g = PoseGrid((3, 3, 3), 1.0, bounded, t_first=2)
    np.testing.assert_array_equal(g.twist_deg(), [0.0, 0.5, 1.0])
    with pytest.raises(dataclasses.FrozenInstanceError):
        g.um_per_px = 2.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan(scene()).grid = g  # type: ignore[misc]


def test_twist_axis_values_locate_and_runs():
    axis = TwistAxis(None, 0.1, -450, 900, True, 90.0, True)
    v = axis.values()
    np.testing.assert_array_equal(axis.values_at(np.arange(900)), v)
    assert axis.values_at(450) == 0.0  # the axis holds 0 exactly
    assert axis.locate(v[10:20]) == 10 and axis.locate(v[10:20] + 0.05) is None
    assert axis.locate(axis.values_at(np.arange(-3, 2))) == -3  # periodic: continued past its start
    assert axis.cut_of(0, 900) == (False, False) and axis.cut_of(5, 10) == (True, True)
    bounded = TwistAxis(-2.0, 1.0, 0, 5, False, 360.0, False)
    assert bounded.locate([-3.0, -2.0]) is None and bounded.cut_of(0, 3) == (False, True)
    assert consecutive_runs([7, 0, 1, 3, 2, 9, 8]) == [[0, 1, 2, 3], [7, 8, 9]]


def test_importing_the_package_changes_no_jax_setting():
    code = (
        "import jax, simulator, simulator.motion, simulator.motion, simulator.motion, simulator.batch; "
        "print(jax.config.jax_enable_x64)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True
    )
    assert out.stdout.strip() == "False"
