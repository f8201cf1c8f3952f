"""The finite meniscus (simulator.physics): closed forms, the h -> 0 limit, sub-pixel
minima, the CLI and its refusals."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from shapely import affinity
from shapely.geometry import Polygon, box

from foundation import InputError
from patterns.geometry import mask_from_geometry
from simulator.landscape import build_landscape, refine_minimum, stiffness
from simulator.physics import (
    Liquid,
    flat_wall_energy_J,
    flat_wall_stiffness_N_m,
    flat_wall_twist_stiffness_Nm,
    kernel_image,
    kernel_spectrum,
    regime_warning,
)
from simulator.scene import Effects, Scene, TwistGrid

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("meniscus")

GAMMA = 0.0728


def _scene(
    pattern_geom,
    chip_size=None,
    chip_geom=None,
    h=5.0,
    pinned=True,
    twist=(0.5, -2, 2),
    window=40.0,
    meniscus=True,
    s=1.0,
):
    pat = mask_from_geometry(pattern_geom, s, margin_um=2)
    kw: dict[str, Any]
    if chip_size is not None:
        kw = {"chip_size_um": chip_size}
    else:
        assert chip_geom is not None
        kw = {"chip": mask_from_geometry(chip_geom, s)}
    tw = TwistGrid(*twist) if twist else TwistGrid()
    return Scene.from_inputs(
        pat,
        **kw,
        effects=Effects(twist=bool(twist), meniscus=meniscus),
        liquid=Liquid(height_um=h, pinned=pinned),
        twist=tw,
        window_um=window,
        dtype="float64",
    )


def _centre(ls):
    return (
        int(np.argmin(np.abs(ls.twist_deg))),
        int(np.argmin(np.abs(ls.y_um))),
        int(np.argmin(np.abs(ls.x_um))),
    )


def test_kernel_is_normalised_and_has_the_flat_wall_profile():
    h = 3.0
    k = kernel_image(h, 400)
    assert k.sum() == pytest.approx(1.0, abs=2e-4)  # tail beyond 400 px: h^2 / r^2 ~ 6e-5
    spec = kernel_spectrum(64, 64, h)
    assert spec[0, 0] == 1.0 and np.all(spec <= 1.0) and np.all(spec >= 0)
    # Profile across a line: the 1-D marginal is h^2 / (2 (d^2 + h^2)^1.5).
    d = np.arange(-400, 401)
    prof = k.sum(axis=0)
    assert np.allclose(prof[390:411], h**2 / (2 * (d[390:411] ** 2 + h**2) ** 1.5), rtol=2e-3)
    assert np.allclose(kernel_spectrum(32, 32, 1e-12), 1.0, atol=1e-12)


def test_zero_height_limit_is_the_overlap_landscape_to_round_off():
    sq = box(-40, -40, 40, 40)
    on = build_landscape(_scene(sq, chip_size=80, h=1e-9))
    off = build_landscape(_scene(sq, chip_size=80, meniscus=False))
    assert on.energy.shape == off.energy.shape
    assert np.max(np.abs(on.energy - off.energy)) <= 1e-12 * np.abs(off.energy).max()
    assert off.meniscus_height_um is None and on.meniscus_height_um == pytest.approx(1e-9)


def test_meniscus_off_is_bit_for_bit_the_overlap_model():
    sq = box(-30, -30, 30, 30)
    a = build_landscape(_scene(sq, chip_size=60, meniscus=False, pinned=False))
    b = build_landscape(
        Scene.from_inputs(
            mask_from_geometry(sq, 1.0, margin_um=2),
            chip_size_um=60,
            twist=TwistGrid(0.5, -2, 2),
            window_um=40.0,
            dtype="float64",
        )
    )
    assert np.array_equal(a.energy, b.energy)


@pytest.mark.parametrize("h", [4.0, 8.0])
def test_square_shift_energy_stiffness_and_saturation(h):
    L = 200.0
    ls = build_landscape(
        _scene(box(-L / 2, -L / 2, L / 2, L / 2), chip_size=L, h=h, twist=None, window=8 * h)
    )
    it, iy, ix = _centre(ls)
    e = ls.energy[it, iy] - ls.energy[it, iy, ix]
    x = ls.x_um
    # Flat-wall energy 2 gamma L (sqrt(x^2 + h^2) - h), with the model's corner factor
    # (1 - 2h / (pi L)) on the stiffness (the ends of the edges, derived in meniscus.py).
    corner = 1 - 2 * h / (math.pi * L)
    near = np.abs(x) <= 2 * h
    cf = flat_wall_energy_J(x, L, h, GAMMA)
    assert np.allclose(e[near], cf[near], rtol=h / L * 1.5, atol=1e-3 * cf[near].max())
    k = (e[ix + 1] + e[ix - 1]) / (1e-6) ** 2
    assert k == pytest.approx(flat_wall_stiffness_N_m(L, h, GAMMA) * corner, rel=2e-3)
    # Far out the force saturates at 2 gamma (L - h) (edges shortened by about h at the corners).
    F = -np.gradient(ls.energy[it, iy], x * 1e-6)
    far = np.argmin(np.abs(x - 7 * h))
    assert -F[far] == pytest.approx(2 * GAMMA * L * 1e-6 * (1 - h / L), rel=0.02)
    assert abs(F[far]) < 2 * GAMMA * L * 1e-6
    # The stiffness deficit against the flat wall shrinks like h / L.


def test_rectangle_stiffness_follows_the_edge_across_the_shift():
    a, b, h = 200.0, 100.0, 5.0
    ls = build_landscape(
        _scene(box(-a / 2, -b / 2, a / 2, b / 2), chip_size=(a, b), h=h, twist=None, window=20)
    )
    k = stiffness(ls, 0.0, 0.0, 0.0)
    # Along x the walls across the shift are the b-sides: 2 gamma b / h; along y, 2 gamma a / h.
    assert k["x_N_per_m"] == pytest.approx(
        flat_wall_stiffness_N_m(b, h, GAMMA) * (1 - 2 * h / (math.pi * b)), rel=0.01
    )
    assert k["y_N_per_m"] == pytest.approx(
        flat_wall_stiffness_N_m(a, h, GAMMA) * (1 - 2 * h / (math.pi * a)), rel=0.01
    )
    assert k["x_N_per_m"] / k["y_N_per_m"] == pytest.approx(b / a, rel=0.03)


def test_regular_hexagon_is_isotropic():
    r = 80.0
    hexagon = Polygon(
        [(r * math.cos(math.radians(60 * i)), r * math.sin(math.radians(60 * i))) for i in range(6)]
    )
    ls = build_landscape(_scene(hexagon, chip_geom=hexagon, h=6.0, twist=None, window=20))
    k = stiffness(ls, 0.0, 0.0, 0.0)
    assert k["x_N_per_m"] == pytest.approx(k["y_N_per_m"], rel=0.01)
    # Perimeter 6 r, stiffness sum_e L_e n n^T / h gamma: 3 r gamma / h along each axis (corners aside).
    assert k["x_N_per_m"] == pytest.approx(2 * GAMMA * 3 * r / 2 / 6.0, rel=0.12)


def test_twist_is_smooth_and_tends_to_the_flat_wall_stiffness():
    L = 200.0
    ratios = []
    for h in (5.0, 10.0):
        ls = build_landscape(
            _scene(
                box(-L / 2, -L / 2, L / 2, L / 2), chip_size=L, h=h, twist=(0.25, -2, 2), window=4
            )
        )
        it, iy, ix = _centre(ls)
        e = ls.energy[:, iy, ix] - ls.energy[it, iy, ix]
        # No cusp: energy even in twist, convex, and the first step rises no faster than quadratically.
        assert np.allclose(e, e[::-1], rtol=1e-6, atol=1e-20)
        assert e[it + 1] < e[it + 2] / 3.0
        kt = stiffness(ls, 0.0, 0.0, 0.0)["twist_Nm_per_rad"]
        ratios.append(kt / flat_wall_twist_stiffness_Nm(L, h, GAMMA))
    # gamma L^3 / (3 h) less a corner deficit of about 4.3 h / L (measured: 0.89 at h/L = 0.025, 0.78 at 0.05).
    assert 0.85 < ratios[0] < 0.93 and 0.74 < ratios[1] < 0.83
    assert (1 - ratios[1]) / (1 - ratios[0]) == pytest.approx(2.0, rel=0.15)


@pytest.mark.parametrize(("sx", "sy"), [(0.3, -0.2), (0.45, 0.1)])
def test_subpixel_shift_of_the_pattern_is_recovered(sx, sy):
    L = 100.0
    sc = _scene(
        affinity.translate(box(-L / 2, -L / 2, L / 2, L / 2), sx, sy),
        chip_size=L,
        h=4.0,
        pinned=True,
        window=10,
    )
    ls = build_landscape(sc)
    g = ls.global_minimum()
    assert (g[0], g[1]) == (0.0, 0.0)  # the grid cannot see it
    r = refine_minimum(ls, *g[:3])
    assert r["x_um"] == pytest.approx(sx, abs=0.1) and r["y_um"] == pytest.approx(sy, abs=0.1)
    assert abs(r["twist_deg"]) < 0.1


@pytest.mark.parametrize(("sx", "sy"), [(0.0, 0.0), (3.0, -2.0)])
def test_free_contact_lines_float_the_chip_within_the_substrate_reach(sx, sy):
    # Free lines on a wettable substrate stand d_s = h cot(theta_s) beyond the chip: a chip
    # on a same-size pad feels no force while both lines of an axis stand on the substrate,
    # |x - sx| < d_s, so the well has a flat floor of that half-width about the pad's centre.
    L, h = 100.0, 8.0
    sc = _scene(
        affinity.translate(box(-L / 2, -L / 2, L / 2, L / 2), sx, sy),
        chip_size=L,
        h=h,
        pinned=False,
        twist=None,
        window=20,
    )
    ds = h / math.tan(math.radians(sc.materials.substrate_angle_deg))
    assert sc.wall_profile is not None
    assert sc.wall_profile.substrate_reach_px * sc.um_per_px == pytest.approx(ds)
    ls = build_landscape(sc)
    fl = ls.floor_range()
    for (lo, hi), c in ((fl["x_um"], sx), (fl["y_um"], sy)):
        assert (lo + hi) / 2 == pytest.approx(c, abs=0.5)
        assert hi - lo == pytest.approx(2 * ds, abs=2 * sc.um_per_px)
    # Beyond the floor the force pulls back; on it there is none.
    assert (
        float(ls.force_at(sx + ds + 3, sy, 0.0)[0])
        < 0
        < float(ls.force_at(sx - ds - 3, sy, 0.0)[0])
    )
    assert float(ls.force_at(sx + ds - 2, sy, 0.0)[0]) == 0.0


def test_defect_moves_the_minimum_towards_the_flatter_side():
    # A 200 um pad missing a triangle (base 40 um) on its right edge: moving left costs
    # less (the chip's right edge enters the notch), so the minimum moves left by about
    # h r / sqrt(1 - r^2), r = (a - b) / (a + b) the slopes' asymmetry: 40 / 360.
    L, base, depth, h = 200.0, 40.0, 20.0, 10.0
    pad = box(-L / 2, -L / 2, L / 2, L / 2).difference(
        Polygon([(L / 2, -base / 2), (L / 2 - depth, 0), (L / 2, base / 2)])
    )
    ls = build_landscape(_scene(pad, chip_size=L, h=h, twist=(1.0, -2, 2), window=20))
    r = refine_minimum(ls, *ls.global_minimum()[:3])
    rr = base / (2 * L - base)
    expected = -h * rr / math.sqrt(1 - rr * rr)
    assert r["x_um"] < -0.3
    assert r["x_um"] == pytest.approx(expected, rel=0.5)
    assert abs(r["y_um"]) < 0.05 and abs(r["twist_deg"]) < 0.05
    # The overlap model cannot see it (docs/physics.md C11): its minimum stays at 0.
    off = build_landscape(_scene(pad, chip_size=L, twist=(1.0, -2, 2), window=20, meniscus=False))
    assert off.global_minimum()[:3] == (0.0, 0.0, 0.0)


def test_height_from_volume_and_refusals():
    sq = box(-100, -100, 100, 100)
    sc = Scene.from_inputs(
        mask_from_geometry(sq, 2.0),
        chip_size_um=200,
        effects=Effects(meniscus=True),
        liquid=Liquid(volume_nl=0.9),
    )
    assert sc.meniscus_height_um == pytest.approx(22.5)
    with pytest.raises(InputError, match="larger than the chip"):
        Scene.from_inputs(
            mask_from_geometry(sq, 2.0),
            chip_size_um=200,
            effects=Effects(meniscus=True),
            liquid=Liquid(volume_nl=500),
        )
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(InputError, match="meniscus height"):
            Liquid(height_um=bad)
    assert regime_warning(60.0, 200.0) and regime_warning(40.0, 200.0) is None
    # Off, the height is not asked for (an impossible volume does not matter).
    assert (
        Scene.from_inputs(
            mask_from_geometry(sq, 2.0), chip_size_um=200, liquid=Liquid(volume_nl=500)
        ).meniscus_height_um
        is None
    )


def test_pinned_energy_scale_is_twice_the_surface_tension():
    sq = box(-50, -50, 50, 50)
    pinned = _scene(sq, chip_size=100, h=1e-9)
    free = _scene(sq, chip_size=100, h=1e-9, pinned=False)
    assert pinned.delta_gamma_N_m == pytest.approx(-2 * GAMMA)
    assert free.delta_gamma_N_m == pytest.approx(free.materials.delta_gamma_N_m)


def test_cli_evaluate_meniscus_reports_stiffness_and_offset(tmp_path, capsys):
    from simulator.cli import main

    out = tmp_path / "ev"
    code = main(
        [
            "evaluate",
            "--pattern",
            "patterns/library/defect_A_inward.png",
            "--chip-size",
            "200",
            "--meniscus",
            "--volume",
            "0.9",
            "--pinned",
            "--resolution",
            "4",
            "--twist-step",
            "2",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    d = json.loads((out / "summary.json").read_text())
    assert d["meniscus_height_um"] == pytest.approx(22.5)
    k = d["stiffness"]
    # 200 um square, pinned water: 2 gamma L / h = 1.29 N/m, less the corner deficit and the defect.
    assert 0.9 < k["x_N_per_m"] < 1.3 and 0.9 < k["y_N_per_m"] < 1.3 and k["twist_Nm_per_rad"] > 0
    assert d["offset_from_centre"]["x_um"] < 0 and d["global_minimum"]["refined"] is True


def test_cli_evaluate_free_contact_lines_reports_the_floor_the_chip_floats_on(tmp_path, capsys):
    # 200 um chip on the 200 um square, 0.9 nl (h = 22.5 um), free lines on the 60 deg
    # substrate: d_s = h cot 60 = 13.0 um. The well's floor spans +-d_s (to a 2 um pixel),
    # its stiffness is zero, every start on it is aligned, and the bias counts beyond it.
    from simulator.cli import main

    out = tmp_path / "ev"
    code = main(
        [
            "evaluate",
            "--pattern",
            "patterns/library/square_200.png",
            "--chip-size",
            "200",
            "--meniscus",
            "--volume",
            "0.9",
            "--resolution",
            "2",
            "--twist-step",
            "2",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    d = json.loads((out / "summary.json").read_text())
    ds = 22.5 / math.tan(math.radians(60))
    assert d["contact_lines"] == "free" and d["contact_line_reach_um"][
        "substrate"
    ] == pytest.approx(ds, rel=1e-3)
    assert d["contact_line_reach_um"]["pad"] == pytest.approx(
        22.5 / math.tan(math.radians(30)), rel=1e-3
    )
    fl = d["floating_range"]
    for axis in ("x", "y"):
        assert fl[f"{axis}_from_um"] == pytest.approx(-ds, abs=2.0) and fl[
            f"{axis}_to_um"
        ] == pytest.approx(ds, abs=2.0)
    assert d["stiffness"]["x_N_per_m"] == 0.0 and d["stiffness"]["y_N_per_m"] == 0.0
    assert d["global_minimum"]["refined"] is False and (
        d["global_minimum"]["x_um"],
        d["global_minimum"]["y_um"],
    ) == (0.0, 0.0)
    assert (
        min(d["max_bias_um"].values()) > 100 + ds
    )  # beyond the floor, out to the pad's edge and the line's reach
    assert d["yield"]["fraction"] == 1.0 and d["yield"]["outcomes"]["plateau"] == 0
    assert "floats on the well's floor" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("flags", "needle"),
    [
        (["--meniscus-height", "0"], "meniscus height"),
        (["--meniscus-height", "nan"], "meniscus height"),
        (["--meniscus-height", "300"], "larger than the chip"),
        (["--meniscus", "--volume", "500"], "larger than the chip"),
    ],
)
def test_cli_refuses_bad_heights_in_one_line(flags, needle, capsys):
    from simulator.cli import main

    code = main(
        [
            "energy",
            "--pattern",
            "patterns/library/square_200.png",
            "--chip-size",
            "200",
            "--at",
            "0,0,0",
            *flags,
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1


def test_scene_file_means_what_the_flags_mean(tmp_path):
    from simulator.cli import build_parser
    from simulator.commands._request import SceneRequest
    from simulator.commands._scene import scene_from_args
    from simulator.commands.energy import register  # noqa: F401  (the energy parser has every scene flag)

    toml = tmp_path / "s.toml"
    pattern = Path("patterns/library/square_200.png").resolve()
    toml.write_text(
        f'pattern = "{pattern}"\nchip_size_um = 200\nresolution_um = 4\n[effects]\nmeniscus = true\nhysteresis = true\n'
        "[liquid]\nmeniscus_height_um = 12.5\npinned = true\n[materials]\npad_receding_deg = 31\npad_advancing_deg = 50\n"
    )
    a = Scene.from_toml(toml)
    args = build_parser().parse_args(
        [
            "energy",
            "--pattern",
            "patterns/library/square_200.png",
            "--chip-size",
            "200",
            "--resolution",
            "4",
            "--meniscus-height",
            "12.5",
            "--pinned",
            "--hysteresis",
            "31:50",
            "--at",
            "0,0,0",
        ]
    )
    b = scene_from_args(SceneRequest.from_args(args))
    for s in (a, b):
        assert (
            s.meniscus_height_um == 12.5
            and s.liquid.pinned
            and s.effects.meniscus
            and s.effects.hysteresis
        )
        assert (s.materials.pad_receding_deg, s.materials.pad_advancing_deg) == (31.0, 50.0)
    assert a.um_per_px == b.um_per_px and np.array_equal(a.pattern.data, b.pattern.data)


def test_boxes_of_a_run_share_the_chips_footprint(monkeypatch):
    """A trajectory builds a landscape per box: the free-contact-line footprint (a distance
    transform of the whole chip) is made once, and a box gets the same energies from it."""
    import simulator.landscape._rotation as rotation_module
    import simulator.physics as physics

    monkeypatch.setattr(
        rotation_module, "_SMOOTH", {}
    )  # an earlier test may have left this chip's footprint
    calls = []
    sdf = physics.signed_distance_px
    monkeypatch.setattr(
        physics, "signed_distance_px", lambda img: (calls.append(img.shape), sdf(img))[1]
    )
    sc = _scene(
        box(-50, -50, 50, 50), chip_size=100.0, h=8.0, pinned=False, twist=(1.0, -2, 2), window=20
    )
    full = build_landscape(sc)
    boxed = build_landscape(sc, center_px=(4, -3), half_px=6)
    assert len(calls) == 1
    x0 = int(np.searchsorted(full.x_um, boxed.x_um[0]))
    y0 = int(np.searchsorted(full.y_um, boxed.y_um[0]))
    t, ny, nx = boxed.energy.shape
    np.testing.assert_allclose(
        boxed.energy,
        full.energy[:, y0 : y0 + ny, x0 : x0 + nx],
        rtol=0,
        atol=1e-12 * np.abs(full.energy).max(),
    )
    # Another chip (even of the same shape) makes its own.
    build_landscape(
        _scene(
            box(-50, -50, 50, 50),
            chip_size=100.0,
            h=8.0,
            pinned=False,
            twist=(1.0, -2, 2),
            window=20,
        )
    )
    assert len(calls) == 2


@pytest.mark.parametrize(
    "geometry, um_per_px",
    [
        (box(-500, -300, 500, 300), 2.0),  # a rectangle
        (affinity.rotate(box(-60, -40, 60, 40), 17, origin=(0, 0)), 1.0),  # turned: ragged
        (box(-50, -50, 50, 50).difference(box(-10, -20, 15, 5)), 1.0),  # with a hole
    ],
)
def test_a_chips_distance_cut_from_a_wider_canvas_is_the_transform_there(geometry, um_per_px):
    # The footprint state's rotators and the stateless one differ in margin: the signed
    # distance made on the widest canvas is cut for the others, which is the transform made
    # there bit for bit; where it could not be (an odd difference of sizes, a canvas that
    # cuts the chip), no cut is offered and the transform is made.
    from patterns.geometry import rasterize
    from simulator.landscape._rotation import _cropped_distance
    from simulator.physics import signed_distance_px

    x0, y0, x1, y1 = geometry.bounds
    w = 2 * math.ceil(max(abs(x0), abs(x1)) / um_per_px) + 2
    h = 2 * math.ceil(max(abs(y0), abs(y1)) / um_per_px) + 2
    img = rasterize(geometry, um_per_px, shape=(h + 20, w + 30))
    big = signed_distance_px(rasterize(geometry, um_per_px, shape=(h + 120, w + 90)))
    cut = _cropped_distance(big, img)
    assert cut is not None
    np.testing.assert_array_equal(cut, signed_distance_px(img))
    odd = rasterize(geometry, um_per_px, shape=(h + 21, w + 30))
    assert _cropped_distance(big, odd) is None
    tight = rasterize(geometry, um_per_px, shape=(h - 6, w + 30))  # the chip cut by it
    assert _cropped_distance(big, tight) is None
