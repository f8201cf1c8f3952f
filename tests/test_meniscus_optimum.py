"""The global minimum of a meniscus scene without its whole landscape (simulator.landscape,
simulator.landscape): the footprint's block maxima and mass bound the energy as the
chip raster's do, and every box of the landscape agrees with the landscape to round-off."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from simulator.landscape import build_landscape, global_minimum
from simulator.physics import Liquid
from simulator.scene import Effects, Scene

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("meniscus_optimum")

LIB = Path(__file__).resolve().parents[1] / "patterns" / "library"


def _scene(name: str, chip: float, volume: float, pinned: bool, s: float) -> Scene:
    return Scene.from_inputs(
        LIB / f"{name}.png",
        chip_size_um=chip,
        resolution_um=s,
        effects=Effects(meniscus=True),
        liquid=Liquid(volume_nl=volume, pinned=pinned),
        dtype="float64",
    )


CASES = {
    "four-pad 730/50, free lines, 20 nl": ("four_pad_730_50", 730, 20.0, False, 5.0),
    "defect C inward, pinned, 0.9 nl": ("defect_C_inward", 200, 0.9, True, 2.0),
    "defect B outward, free lines, 0.9 nl": ("defect_B_outward", 200, 0.9, False, 2.0),
    "random jagged s4, pinned, 0.5 nl": ("random_jagged_s4", 200, 0.5, True, 2.0),
}


@pytest.mark.parametrize("case", list(CASES))
def test_meniscus_global_minimum_is_proved_without_the_landscape(case):
    name, chip, volume, pinned, s = CASES[case]
    sc = _scene(name, chip, volume, pinned, s)
    ls = build_landscape(sc)
    x, y, t, e = ls.global_minimum()
    g = global_minimum(sc)
    assert g.pose == (x, y, t)
    assert g.energy_J == pytest.approx(e, rel=0, abs=ls.noise_floor_J)
    assert g.how in ("absolute bound", "cell bound") and g.poses < 0.01 * ls.energy.size


@pytest.mark.parametrize("pinned", [True, False])
def test_boxes_of_a_meniscus_landscape_agree_with_it_to_round_off(pinned):
    # The footprint is made on one canvas for every build (the K_h tail would otherwise wrap
    # differently around a smaller FFT canvas: 3e-5 of the energy before), so a box of a
    # band of twists holds the landscape's own energies.
    sc = _scene("defect_C_inward", 200, 0.9, pinned, 2.0)
    full = build_landscape(sc)
    k = len(full.twist_deg) // 2
    tw = full.twist_deg[k - 2 : k + 3]
    box = build_landscape(sc, twists=tw, center_px=(-3, 2), half_px=10)
    xx, yy = np.meshgrid(box.x_um, box.y_um)
    for i, t in enumerate(tw):
        ref = full.energy_at(xx, yy, np.full_like(xx, t))
        assert np.max(np.abs(ref - box.energy[i])) <= 1e-12 * np.abs(full.energy).max()
