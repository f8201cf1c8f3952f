"""The finite meniscus against Surface Evolver: pinned square and rectangular bridges under
shift and twist (validation/evolver_reference.csv, made by ``make validate``; no Evolver
needed here). Targets: shift force within 5 % up to x = 2h; torque within 10 % up to 2
degrees for h below 0.1 L, and the stated miss beyond (low by about h / L)."""

from __future__ import annotations

import csv
import functools
from pathlib import Path
from typing import Any

import pytest
from shapely.geometry import box

from patterns.geometry import mask_from_geometry
from simulator.landscape import build_landscape
from simulator.physics import Liquid, Materials
from simulator.scene import Effects, Scene, TwistGrid

#: Rerun by make test under each FFT backend (SELFALIGN_FFT_BACKEND; tests/conftest.py).
# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = [pytest.mark.fft, pytest.mark.xdist_group("meniscus_evolver")]

CSV = Path(__file__).resolve().parents[1] / "validation" / "evolver_reference.csv"
with CSV.open() as _f:
    ROWS = list(csv.DictReader(_f))


@functools.cache
def _landscape(family: str, a: float, b: float, h: float, gamma: float):
    pat = mask_from_geometry(box(-a / 2, -b / 2, a / 2, b / 2), 1.0, margin_um=2)
    kw: dict[str, Any] = dict(
        chip_size_um=(a, b),
        materials=Materials(surface_tension_N_m=gamma),
        liquid=Liquid(height_um=h, pinned=True),
        dtype="float64",
    )
    if family == "twist":
        sc = Scene.from_inputs(
            pat, effects=Effects(meniscus=True), twist=TwistGrid(0.25, -4, 4), window_um=3, **kw
        )
    else:
        sc = Scene.from_inputs(
            pat, effects=Effects(twist=False, meniscus=True), window_um=2.2 * h + 4, **kw
        )
    return build_landscape(sc)


def _cases(family):
    for r in ROWS:
        if r["family"] != family:
            continue
        a, b, h = float(r["a_um"]), float(r["b_um"]), float(r["h_um"])
        x, y, t = float(r["x_um"]), float(r["y_um"]), float(r["twist_deg"])
        if family == "shift_x" and 0 < x <= 2 * h:
            yield pytest.param(
                a,
                b,
                h,
                x,
                float(r["force_x_N"]),
                float(r["gamma_N_per_m"]),
                id=f"{a:g}x{b:g}-h{h:g}-x{x:g}",
            )
        if family == "shift_y" and 0 < y <= 2 * h:
            yield pytest.param(
                a,
                b,
                h,
                y,
                float(r["force_y_N"]),
                float(r["gamma_N_per_m"]),
                id=f"{a:g}x{b:g}-h{h:g}-y{y:g}",
            )
        if family == "twist" and 0 < t <= 2:
            yield pytest.param(
                a,
                b,
                h,
                t,
                float(r["torque_Nm"]),
                float(r["gamma_N_per_m"]),
                id=f"{a:g}-h{h:g}-t{t:g}",
            )


def test_reference_covers_the_cases_the_model_claims():
    fams = {(r["family"], float(r["h_um"])) for r in ROWS}
    assert {
        ("shift_x", 10.0),
        ("shift_x", 20.0),
        ("shift_x", 40.0),
        ("shift_y", 20.0),
        ("twist", 10.0),
        ("twist", 20.0),
    } <= fams


@pytest.mark.parametrize(("a", "b", "h", "x", "force", "gamma"), list(_cases("shift_x")))
def test_shift_force_x_within_5_percent(a, b, h, x, force, gamma):
    model = -float(_landscape("shift", a, b, h, gamma).force_at(x, 0.0, 0.0)[0])
    assert model / -force == pytest.approx(1.0, abs=0.05)


@pytest.mark.parametrize(("a", "b", "h", "y", "force", "gamma"), list(_cases("shift_y")))
def test_shift_force_y_within_5_percent(a, b, h, y, force, gamma):
    model = -float(_landscape("shift", a, b, h, gamma).force_at(0.0, y, 0.0)[1])
    assert model / -force == pytest.approx(1.0, abs=0.05)


@pytest.mark.parametrize(("a", "b", "h", "t", "torque", "gamma"), list(_cases("twist")))
def test_torque_low_by_about_h_over_L(a, b, h, t, torque, gamma):
    ratio = float(_landscape("twist", a, b, h, gamma).torque_at(0.0, 0.0, t)) / torque
    # The stated law: the model's torque is low by about h / L (0.95 at h = 0.05 L, 0.90 at
    # 0.1 L, 0.82 at 0.2 L), so the 10 % target holds for h below 0.1 L.
    q = h / min(a, b)
    assert 1 - 1.15 * q < ratio < 1 - 0.7 * q
    if q <= 0.05:
        assert ratio == pytest.approx(1.0, abs=0.10)
