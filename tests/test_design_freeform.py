"""Free-form design by gradients (``selfalign design`` with a ``[freeform]`` table).

The differentiable landscape against the build and against finite differences, the masks
kept in every output, the minimum feature on the written GDSII, a toy problem with a known
optimum, the orientation refusal, the seed, and the command end to end. Small grids
(24-64 px), float64 where numbers are compared.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from foundation import InputError
from patterns.geometry import Mask

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("design_freeform")

jax = pytest.importorskip("jax")


def _scene(kw=None, pattern=None, chip=(20, 14)):
    from simulator.scene import Scene

    pattern = pattern if pattern is not None else Mask(np.ones((48, 64)), 1.0)
    return Scene.from_inputs(pattern, chip_size_um=chip, dtype="float64", **(kw or {}))


def _meniscus():
    from simulator.physics import Liquid, Materials
    from simulator.scene import Effects

    return {
        "effects": Effects(meniscus=True),
        "liquid": Liquid(height_um=3.0),
        "materials": Materials(pad_angle_deg=30, substrate_angle_deg=100),
    }


MODELS = {"overlap": None, "meniscus": _meniscus()}


@pytest.mark.parametrize("model", sorted(MODELS))
def test_planes_equal_the_landscape_build(model):
    """The differentiable planes are build_landscape's energies at the same poses (float64)."""
    import jax.numpy as jnp

    from simulator.design import chip_side, overlap_planes
    from simulator.landscape import build_landscape

    rng = np.random.default_rng(3)
    w = (rng.random((48, 64)) > 0.4) * rng.random((48, 64))
    scene = _scene(MODELS[model], Mask(w, 1.0))
    for t in (0.0, 90.0, 33.0):
        side = chip_side(scene, (48, 64), [t])
        spectra = side.spectra(
            "float64"
        )  # float64 in JAX from here (as a float64 problem makes it)
        pl = np.asarray(overlap_planes(jnp.asarray(w, "float64"), spectra, side.index(), side.fft))
        mine = pl[0] * side.energy_per_px2_J
        ls = build_landscape(scene, twists=np.array([t]), backend="scipy")
        ix = np.round(ls.x_um).astype(int) + side.rx
        iy = np.round(ls.y_um).astype(int) + side.ry
        okx, oky = (ix >= 0) & (ix < mine.shape[1]), (iy >= 0) & (iy < mine.shape[0])
        ref = ls.energy[0]
        tol = 1e-12 * np.abs(ref).max()
        # every pose of the build is in the planes, or the chip does not touch the canvas there
        assert (
            np.abs(ref[~oky]).max(initial=0) <= tol and np.abs(ref[:, ~okx]).max(initial=0) <= tol
        )
        err = np.abs(mine[np.ix_(iy[oky], ix[okx])] - ref[np.ix_(oky, okx)]).max()
        assert err <= tol, (model, t, err)


def _fd_check(f, x, idx, eps):
    g = np.asarray(jax.grad(f)(x))
    for i in idx:
        e = np.zeros(x.shape)
        e.flat[i] = eps
        fd = (float(f(x + e)) - float(f(x - e))) / (2 * eps)
        assert abs(g.flat[i] - fd) <= 1e-6 * max(1.0, abs(fd)), (i, g.flat[i], fd)
    return g


@pytest.mark.parametrize("model", sorted(MODELS))
def test_gradient_is_finite_differences(model):
    """d/dw of a weighted sum of the planes, and d/dz of the whole objective (filter, projection,
    soft minima, orientation), equal central differences in float64."""
    import jax.numpy as jnp

    from simulator.design import chip_side, density_map, make_objective, overlap_planes, pattern_of

    rng = np.random.default_rng(5)
    H, W = 32, 40
    scene = _scene(MODELS[model], Mask(np.ones((H, W)), 1.0), chip=(12, 8))
    side = chip_side(scene, (H, W), [0.0, 90.0])
    spec, index = side.spectra("float64"), side.index()  # float64 in JAX from here
    coef = jnp.asarray(rng.standard_normal((2,) + side.plane_shape))

    @jax.jit
    def linear(w):
        return jnp.sum(coef * overlap_planes(w, spec, index, side.fft))

    idx = rng.choice(H * W, 6, replace=False)
    g = _fd_check(linear, jnp.asarray(rng.random((H, W))), idx, 1e-3)
    # linear in w: the gradient is the same at any pattern
    g2 = np.asarray(jax.grad(linear)(jnp.asarray(rng.random((H, W)))))
    assert np.allclose(g, g2, rtol=1e-12, atol=1e-12 * np.abs(g).max())

    keep_in = np.zeros((H, W), bool)
    keep_in[14:18, 18:22] = True
    keep_out = np.zeros((H, W), bool)
    keep_out[:3] = True
    dm = density_map(keep_in, keep_out, 3.0)
    arrays = dm.arrays("float64")
    terms = {
        "capture": {"weight": 1.0, "radius_um": [3, 9]},
        "gap": {"weight": 1.0, "radius_um": 4},
        "orientation": {"weight": 1.0, "twists_deg": [90.0]},
        "stiffness": {"weight": 1.0, "step_um": 1.0},
        "depth": {"weight": 0.5},
        "area": {"weight": 0.1},
    }
    obj = make_objective(terms, side, scene)

    @jax.jit
    def full(z):
        w = pattern_of(z, 4.0, arrays, dm.shape, dm.fft)
        planes = overlap_planes(w, spec, index, side.fft)
        return obj.total(obj.terms(planes, w))

    free = np.flatnonzero((~keep_in & ~keep_out).ravel())
    _fd_check(
        full, jnp.asarray(rng.standard_normal((H, W))), rng.choice(free, 6, replace=False), 1e-5
    )


def _doc(tmp_path, **ff):
    """A tiny design file: a 12 x 8 um chip on a 40 x 32 um canvas at 1 um/px."""
    base = {
        "scene": {"chip_size_um": [12, 8], "dtype": "float64", "effects": {"twist": False}},
        "freeform": {
            "size_um": [40, 32],
            "um_per_px": 1.0,
            "min_feature_um": 3,
            "iterations": 4,
            "keep_in": {"design": "rectangle", "width": 4, "height": 4, "offset_um": [-4, 0]},
            "keep_out": {"design": "rectangle", "width": 40, "height": 4, "offset_um": [0, 14]},
            "objective": {
                "capture": {"weight": 1.0, "radius_um": [2, 8]},
                "depth": {"weight": 1.0},
            },
            "verify": {"yield_starts": 16, "capture_grid": 3},
        },
    }
    base["freeform"].update(ff)
    return base


def test_keep_in_wettable_and_keep_out_dry_in_every_output(tmp_path):
    from patterns import read_mask
    from patterns.geometry import rasterize
    from simulator.design import freeform, load_freeform, read_gds_polygons

    spec = load_freeform(_doc(tmp_path, iterations=25, learning_rate=0.5), base=tmp_path)
    assert spec.keep_in.sum() == 16 and spec.keep_out.sum() == 40 * 4
    r = freeform(spec, tmp_path / "out", verify=False)
    for w in (r.density, r.pattern.data):
        assert np.all(w[spec.keep_in] == 1.0) and np.all(w[spec.keep_out] == 0.0)
    png = read_mask(tmp_path / "out" / "pattern_mask.png")
    assert png.um_per_px == 1.0 and png.shape == spec.shape
    assert np.all(png.data[spec.keep_in] == 1.0) and np.all(png.data[spec.keep_out] == 0.0)
    back = rasterize(read_gds_polygons(tmp_path / "out" / "pattern.gds"), 1.0, shape=spec.shape)
    assert back[spec.keep_in].min() >= 0.999 and back[spec.keep_out].max() <= 0.25
    assert (
        np.abs(back - r.pattern.data).max() <= 0.5
    )  # the simplification moves no edge by half a pixel
    # every history column has its unit and one row per iteration
    head = (tmp_path / "out" / "history.csv").read_text().splitlines()
    assert head[0] == "iteration,beta,objective,capture_N,depth_J" and len(head) == 26


def test_the_written_gdsii_respects_the_minimum_feature(tmp_path):
    """The written polygons, read back by gdstk, survive the opening and closing by the
    minimum feature (within the check's pixels); a strip narrower than it does not."""
    import shapely

    from simulator.design import feature_check, freeform, load_freeform, read_gds_polygons

    doc = _doc(tmp_path, iterations=30, learning_rate=0.5, min_feature_um=4, init=0.6)
    doc["freeform"]["objective"] = {
        "capture": {"weight": 1.0, "radius_um": [2, 10]},
        "area": {"weight": 0.3},
    }
    spec = load_freeform(doc, base=tmp_path)
    r = freeform(spec, tmp_path / "out", verify=False)
    geom = read_gds_polygons(tmp_path / "out" / "pattern.gds")
    assert r.layout is not None
    assert not geom.is_empty and r.layout["ok"], r.layout
    keep_in = shapely.box(-6, -2, -2, 2)
    assert feature_check(geom, 4.0, 1.0, keep_in=keep_in)["ok"]
    assert json.loads((tmp_path / "out" / "result.json").read_text())["layout"]["ok"]
    # the check can fail: a 2 um strip (or a 2 um slot) under a 4 um minimum feature
    strip = shapely.union_all([shapely.box(0, 0, 10, 10), shapely.box(10, 4, 20, 6)])
    assert not feature_check(strip, 4.0, 1.0)["ok"]
    slot = shapely.box(0, 0, 20, 20).difference(shapely.box(5, 9.5, 15, 10.5))
    c = feature_check(slot, 4.0, 1.0)
    assert c["opening_moves_um"] <= 2 and c["closing_moves_um"] > 2 and not c["ok"]


def test_toy_stiffness_of_a_square_chip_finds_the_full_square(tmp_path):
    """A square chip of L = 24 px over a design region of its own size: the largest overlap
    stiffness (over one pixel, k_x + k_y = 4 L |Delta_gamma|) with a little depth is every
    pixel wettable, found from a half-grey start."""
    from simulator.design import freeform, load_freeform

    doc = {
        "scene": {"chip_size_um": 24, "dtype": "float64", "effects": {"twist": False}},
        "freeform": {
            "size_um": 24,
            "um_per_px": 1.0,
            "min_feature_um": 3,
            "iterations": 60,
            "learning_rate": 0.3,
            "beta": [1.0, 8.0],
            "objective": {"stiffness": {"weight": 1.0}, "depth": {"weight": 0.1}},
            "baseline": {"design": "square", "size": 12},
        },
    }
    spec = load_freeform(doc, base=tmp_path)
    r = freeform(spec, verify=False)
    assert r.density.min() >= 0.5  # every pixel wettable after projection
    dg = abs(spec.scene.delta_gamma_N_m)
    k = r.history["stiffness_N_per_m"][-1]
    assert k == pytest.approx(4 * 24 * dg, rel=0.01)
    assert r.history["objective"][-1] == pytest.approx(4 + 0.1, rel=0.01)  # the analytic optimum
    assert r.history["objective"][-1] > 1.5 * r.history["objective"][0]


def test_orientation_of_a_symmetric_chip_is_refused(tmp_path):
    from simulator.design import load_freeform

    doc = _doc(tmp_path)
    doc["scene"]["effects"] = {"twist": True}
    doc["freeform"]["objective"] = {"orientation": {"weight": 1.0, "twists_deg": [90, 180]}}
    # a 12 x 8 rectangle repeats under 180 degrees: 180 refused, 90 allowed
    with pytest.raises(InputError, match="symmetric under a 180-degree turn.*180 deg equals"):
        load_freeform(doc, base=tmp_path)
    doc["freeform"]["objective"]["orientation"]["twists_deg"] = [90]
    assert load_freeform(doc, base=tmp_path).twists_deg() == (0.0, 90.0)
    doc["scene"]["chip_size_um"] = 10  # a square repeats under 90 degrees
    with pytest.raises(InputError, match="symmetric under a 90-degree turn"):
        load_freeform(doc, base=tmp_path)


def test_the_seed_fixes_the_result(tmp_path):
    from simulator.design import freeform, load_freeform

    doc = _doc(tmp_path, iterations=6, perturbation={"samples": 2, "edge_um": 1.0, "length_um": 6})
    a = freeform(load_freeform(doc, base=tmp_path), verify=False)
    b = freeform(load_freeform(doc, base=tmp_path), verify=False)
    assert np.array_equal(a.density, b.density)
    assert np.array_equal(a.history["objective"], b.history["objective"])
    doc["freeform"]["seed"] = 1
    c = freeform(load_freeform(doc, base=tmp_path), verify=False)
    assert not np.array_equal(a.history["objective"], c.history["objective"])


def _write(tmp_path, doc) -> str:
    lines = []

    def table(name, t):
        simple = {k: v for k, v in t.items() if not isinstance(v, dict)}
        lines.append(f"[{name}]")
        for k, v in simple.items():
            lines.append(f"{k} = {_toml(v)}")
        for k, v in t.items():
            if isinstance(v, dict) and name == "freeform" and k in ("keep_in", "keep_out"):
                lines.insert(lines.index(f"[{name}]") + 1, f"{k} = {_toml(v)}")
            elif isinstance(v, dict):
                table(f"{name}.{k}", v)

    for name, t in doc.items():
        table(name, t)
    p = tmp_path / "design.toml"
    p.write_text("\n".join(lines) + "\n")
    return str(p)


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + " }"
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return repr(v)


def test_the_command_end_to_end(tmp_path, run_cli):
    doc = _doc(tmp_path)
    doc["freeform"]["objective"]["depth"] = {"weight": 1.0}
    path = _write(tmp_path, doc)
    out = tmp_path / "out"
    rc, so, se = run_cli(["design", path, "--out", out, "--trials", "3", "--quiet"])
    assert rc == 0, se
    assert "capture fraction" in so and "wrote" in so and se == ""
    for name in (
        "pattern.png",
        "pattern_mask.png",
        "pattern.gds",
        "history.csv",
        "history.png",
        "capture_before_after.png",
        "before/capture.png",
        "after/capture.png",
        "result.json",
        "report.html",
    ):
        assert (out / name).is_file(), name
    res = json.loads((out / "result.json").read_text())
    assert res["iterations"] == 3 and res["canvas_px"] == [32, 40]
    ev = res["evaluation"]
    for side in ("baseline", "optimised"):
        assert 0 <= ev[side]["capture_fraction"] <= 1 and 0 <= ev[side]["yield_fraction"] <= 1
    # a rerun replaces its own previous output; a directory holding anything else is refused
    from simulator.design import freeform, load_freeform

    freeform(load_freeform(path), out, iterations=2, verify=False)
    assert json.loads((out / "result.json").read_text())["iterations"] == 2
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    rc, so, se = run_cli(["design", path, "--out", other, "--trials", "2", "--quiet"])
    assert (
        rc == 2
        and len(se.strip().splitlines()) == 1
        and (other / "notes.txt").read_text() == "mine"
    )


def _bad(tmp_path, change):
    doc = _doc(tmp_path)
    change(doc)
    return doc


BAD = {
    "unknown key": (lambda d: d["freeform"].update(colour=1), "colour: unknown key"),
    "missing keep-in file": (
        lambda d: d["freeform"].update(keep_in="nope.png"),
        "keep_in = '.*nope.png': the file does not exist",
    ),
    "mask of the wrong size": (
        lambda d: d["freeform"].update(keep_out="small.png"),
        "10 x 10 px but the design canvas is 40 x 32 px",
    ),
    "min feature below two pixels": (
        lambda d: d["freeform"].update(min_feature_um=1.5),
        "at least 2 px",
    ),
    "no iterations": (lambda d: d["freeform"].update(iterations=0), "iterations = 0"),
    "memory": (
        lambda d: d["scene"].update(memory_budget_mb=0.1),
        "one gradient iteration needs about",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_design_files_are_one_line(case, tmp_path, run_cli):
    from patterns import write_mask

    write_mask(tmp_path / "small.png", Mask(np.zeros((10, 10)), 1.0))
    change, needle = BAD[case]
    path = _write(tmp_path, _bad(tmp_path, change))
    out = tmp_path / "out"
    rc, so, se = run_cli(["design", path, "--out", out, "--quiet"])
    assert rc == 2 and len(se.strip().splitlines()) == 1, se
    import re

    assert re.search(needle, se), se
    assert not out.exists()


def test_trials_and_workers_flags(tmp_path, run_cli):
    path = _write(tmp_path, _doc(tmp_path))
    rc, _, se = run_cli(["design", path, "--out", tmp_path / "o", "--trials", "0"])
    assert rc == 2 and "--trials = 0" in se
    rc, _, se = run_cli(["design", path, "--out", tmp_path / "o", "--workers", "2"])
    assert rc == 2 and "--workers" in se and len(se.strip().splitlines()) == 1
