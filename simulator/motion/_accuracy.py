"""What limits a final pose's error: the grid, the floor the chip floats on, or the refinement.

Every command that reports a final pose (``simulate``, ``montecarlo``, ``evaluate``) says
what bounds its error, as ``error_limit = {"by": ..., "um": ...}`` (:func:`error_limit`):

* ``"grid"``: the run ended on a grid pose (greedy steps; the overlap model's V-shaped
  well, where a refinement would move the pose by round-off only): an error below the grid
  step ``um`` (the pixel size the landscape was computed at) is not resolved, so an error of
  0 means "within one grid step".
* ``"floor"``: the chip floats. With free contact lines the well has a flat floor (the
  landscape's poses within its noise floor of the global minimum,
  :meth:`~simulator.landscape.Landscape.floor_extent`): a run that stops anywhere on it
  is aligned, and ``um`` is the floor's reach from the global minimum along x or y (the
  largest of the four). With contact-angle hysteresis the pinning holds the chip anywhere
  within the align tolerance of :func:`simulator.physics.align_tolerance`, which is
  ``um`` when it is wider than a grid step.
* ``"refined"``: a gradient or dynamic run on a smooth (finite-meniscus) well, its final
  pose refined below the grid (:func:`simulator.landscape.refine_minimum`). What limits
  it is the landscape's round-off: energies within the noise floor ``dE`` of the
  minimum are ties, so the minimum is resolved to ``sqrt(2 dE / k)`` with ``k`` the well's
  smaller stiffness along x and y there (``um``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from simulator.core import UM

if TYPE_CHECKING:
    from simulator.landscape import Landscape
    from simulator.scene import Scene

#: The names of ``error_limit["by"]``.
LIMITS = ("grid", "floor", "refined")


def floor_reach_um(ls: Landscape) -> float:
    """The largest distance (um) along x or y from the landscape's global minimum to the
    edge of its floor (:meth:`~simulator.landscape.Landscape.floor_range`); 0 for a
    single pose (a cusp or a smooth well)."""
    _, iy, ix = ls.minimum_index()
    fr = ls.floor_range()
    x, y = float(ls.x_um[ix]), float(ls.y_um[iy])
    return max(x - fr["x_um"][0], fr["x_um"][1] - x, y - fr["y_um"][0], fr["y_um"][1] - y, 0.0)


def floats(scene: Scene, ls: Landscape) -> bool:
    """The chip floats on ``ls``: free contact lines (the scene's wall profile) and a
    floor wider than one pose in x or y."""
    return scene.wall_profile is not None and floor_reach_um(ls) > 0


def refined_limit_um(ls: Landscape, pose: tuple[float, float, float]) -> float | None:
    """``sqrt(2 dE / k)`` (um) at ``pose`` (x_um, y_um, twist_deg): the distance at which the
    well's energy rises by the landscape's noise floor ``dE``, ``k`` the smaller of its
    stiffnesses along x and y (:func:`simulator.landscape.stiffness`); None where the well
    is not curved upwards there."""
    from simulator.landscape import stiffness

    k = stiffness(ls, *pose)
    kk = min(k["x_N_per_m"], k["y_N_per_m"])
    if not (kk > 0 and math.isfinite(kk)):
        return None
    return math.sqrt(2.0 * ls.noise_floor_J / kk) / UM


def error_limit(
    scene: Scene,
    ls: Landscape | None = None,
    *,
    refined: tuple[float, float, float] | None = None,
    pin: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> dict:
    """``{"by": "grid" | "floor" | "refined", "um": ...}``: what limits the error of a final
    pose on the landscape ``ls`` (the one around the global minimum; None: a run that
    needs none of it, whose limit is the scene's grid step), refined to ``refined``
    (x_um, y_um, twist_deg) or not, under the pinning ``pin`` (per grid index,
    :func:`simulator.physics.pin_per_index`). The rules are the module's."""
    step = scene.um_per_px if ls is None else float(ls.um_per_px)
    if ls is not None:
        reach = floor_reach_um(ls) if scene.wall_profile is not None else 0.0
        if any(pin):
            from simulator.physics import align_tolerance

            held = align_tolerance(ls, pin)[1]  # px, at least one step
            if held > 1.0:
                reach = max(reach, held * step)
        if reach > 0:
            return {"by": "floor", "um": float(reach)}
        if refined is not None:
            um = refined_limit_um(ls, refined)
            if um is not None:
                return {"by": "refined", "um": float(um)}
    return {"by": "grid", "um": float(step)}


def error_limit_words(limit: dict | None) -> str:
    """The printed words for an :func:`error_limit`: 'limited by the 2 um grid step', ..."""
    if not limit:
        return ""
    um = limit["um"]
    if limit["by"] == "grid":
        return f"limited by the {um:.3g} um grid step (the run ends on the grid: an error below it is not resolved)"
    if limit["by"] == "floor":
        return f"limited by the floor: the chip floats within {um:.3g} um of the global minimum (no restoring force there)"
    return f"limited by the refinement below the grid: {um:.2g} um (the landscape's round-off over the well's stiffness)"
