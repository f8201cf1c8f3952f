"""Monte Carlo batches: batch == single runs bit for bit, determinism, chunking, yields,
symmetric capture maps, maximum bias, pattern realizations, the CLI end to end."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from patterns import write_mask
from patterns.geometry import four_pad, mask_from_geometry, square
from simulator.batch import (
    BatchResult,
    StartGrid,
    capture_map,
    max_bias,
    random_starts,
    run_batch,
    run_realizations,
    summarize,
    twist_error,
)
from simulator.cli import main
from simulator.core import OUTCOMES
from simulator.landscape import build_landscape
from simulator.motion import (
    field_and_grid,
    gradient_descent,
    greedy,
    radius_of_gyration_px,
    simulate,
)
from simulator.scene import Scene, TwistGrid

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("montecarlo")


def make_scene(L, g, um_per_px, step_deg, **kw):
    pat = four_pad(L, g) if g else square(L)
    return Scene(
        pattern=mask_from_geometry(pat, um_per_px, margin_um=10),
        chip=mask_from_geometry(square(L), um_per_px),
        twist=TwistGrid(step_deg=step_deg),
        **kw,
    )


@pytest.fixture(scope="module")
def fp():
    """200 um four-pad (gap 20 um) at 2 um/px, twist step 10 degrees (9 twists, periodic)."""
    s = make_scene(200, 20, 2.0, 10.0)
    return s, build_landscape(s)


@pytest.fixture(scope="module")
def starts():
    """Grid starts (aligned, plateau, no-contact, diagonal ties) and random placements."""
    g = StartGrid.from_ranges((-240, 240, 40), (-120, 200, 40), (-20, 20, 20)).poses()
    r = random_starts(60, (80, 80, 15), seed=11)
    return np.concatenate([g, r, [[100, 0, 0], [92, 0, 0], [60, 60, 0], [60, -60, 0]]])


# ------------------------------------------------------------------ batch == single
@pytest.mark.xla_exact  # two compiled programs, bit for bit: the same optimisation only
@pytest.mark.parametrize("method", ["greedy", "gradient"])
def test_batch_equals_single_runs_bit_for_bit(fp, starts, method):
    scene, ls = fp
    r = run_batch(scene, starts, method, landscape=ls, chunk=64, progress=False)
    fld, grid = field_and_grid(ls, radius_of_gyration_px(scene))
    fn = greedy if method == "greedy" else gradient_descent
    single = jax.jit(fn, static_argnames=("grid", "max_steps", "record"))
    pick = np.random.default_rng(0).choice(len(starts), 24, replace=False)
    for n, i in enumerate(pick):
        q = grid.to_index(starts[i])
        q = jnp.asarray(np.round(q), jnp.int32) if method == "greedy" else jnp.asarray(q)
        state = single(fld, grid, q, 5000, record=False)
        end = np.asarray(state.idx if method == "greedy" else state.q)
        assert grid.to_pose(end).tobytes() == r.final[i].tobytes()
        assert int(state.step) == r.steps[i]
        if n >= 10:  # simulate() classifies on the host: slower, so fewer starts
            continue
        traj = simulate(scene, tuple(starts[i]), method=method, landscape=ls)
        assert np.asarray(traj.final).tobytes() == r.final[i].tobytes()
        assert traj.steps == r.steps[i] and traj.outcome == r.outcome_names()[i]
    assert set(r.outcome_names()) >= {"aligned", "plateau", "no_contact"}


def test_same_seed_same_bits_and_chunk_and_workers_change_nothing(fp):
    scene, ls = fp
    a = random_starts(300, (60, 60, 20), seed=5, around=(20, -10, 0))
    b = random_starts(300, (60, 60, 20), seed=5, around=(20, -10, 0))
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, random_starts(300, (60, 60, 20), seed=6, around=(20, -10, 0)))
    ref = run_batch(scene, a, landscape=ls, chunk=300, progress=False, workers=1)
    for chunk, workers in [(7, 2), (64, 1), (1000, 2)]:
        r = run_batch(scene, b, landscape=ls, chunk=chunk, progress=False, workers=workers)
        for k in ("final", "outcome", "steps", "energy_J"):
            assert getattr(r, k).tobytes() == getattr(ref, k).tobytes(), (k, chunk)
    assert summarize(ref) == summarize(r)


# ------------------------------------------------------------------ starts
def test_random_starts_distributions():
    u = random_starts(20000, (10, 20, 5), seed=1, around=(100, -50, 3), distribution="uniform")
    assert np.all(np.abs(u - [100, -50, 3]) <= [10, 20, 5])
    assert np.abs(u.mean(axis=0) - [100, -50, 3]).max() < 0.5
    n = random_starts(20000, (10, 20, 0), seed=1)
    np.testing.assert_allclose(n.std(axis=0), [10, 20, 0], rtol=0.03, atol=1e-12)
    assert np.all(n[:, 2] == 0)  # zero spread: exactly the nominal value
    for bad in [dict(n=0), dict(spread=(-1, 0, 0)), dict(seed=-1), dict(distribution="cauchy")]:
        kw = dict(n=10, spread=(1, 1, 1), seed=0) | bad
        with pytest.raises(ValueError, match="must|one of"):
            random_starts(**kw)


def test_start_grid_order_and_errors():
    g = StartGrid.from_ranges((0, 4, 2), 5.0, (-10, 10, 10))
    assert g.shape == (3, 1, 3) and g.x_um == (0.0, 2.0, 4.0)
    p = g.poses()
    assert p[:3].tolist() == [[0, 5, -10], [2, 5, -10], [4, 5, -10]]  # x fastest, twist slowest
    with pytest.raises(ValueError, match="step must be > 0"):
        StartGrid.from_ranges((0, 4, 0), 0)
    with pytest.raises(ValueError, match="stop"):
        StartGrid.from_ranges((4, 0, 1), 0)


def test_twist_error_modulo_period():
    np.testing.assert_array_equal(twist_error([-90, 45, -45, 44, 100], 90), [0, -45, -45, 44, 10])


# ------------------------------------------------------------------ physics
def test_square_yield_is_one_inside_capture_region():
    s = make_scene(200, 0, 4.0, 10.0)
    g = StartGrid.from_ranges((-120, 120, 8), (-120, 120, 8), (-20, 20, 10))
    r = run_batch(s, g, progress=False)
    summ = summarize(r, g)
    assert summ["yield"] == 1.0 and summ["outcomes"]["aligned"] == g.size
    assert (
        summ["aligned_error_um"]["x"]["max_abs"] == 0
        and summ["aligned_error_deg"]["twist"]["max_abs"] == 0
    )
    assert all(
        summ["max_bias_limited_by_grid"].values()
    )  # every start aligned, up to the grid edge


def test_placement_noise_yield(fp):
    scene, ls = fp
    exact = run_batch(
        scene,
        random_starts(50, (0, 0, 0), seed=0, around=(40, 20, 0)),
        landscape=ls,
        progress=False,
    )
    assert summarize(exact)["yield"] == 1.0
    wide = run_batch(
        scene,
        random_starts(400, (60, 60, 10), seed=0, around=(80, 0, 0)),
        landscape=ls,
        progress=False,
    )
    assert 0.2 < summarize(wide)["yield"] < 1.0


@pytest.mark.parametrize("method", ["greedy", "gradient"])
def test_four_pad_capture_map_is_mirror_symmetric(method):
    # float64: in float32, real energy differences below the float32 noise floor count as
    # ties, and the tie order (docs/physics.md §5) is not mirror-invariant, so a few starts on
    # basin boundaries (88 of 2601 here) end differently from their mirror images.
    scene = make_scene(200, 20, 2.0, 10.0, dtype="float64")
    g = StartGrid.from_ranges((-200, 200, 8), (-200, 200, 8), 0.0)
    r = run_batch(scene, g, method, progress=False)
    cmap = capture_map(r, g)[0]
    assert 0 < np.mean(cmap == 0) < 1
    np.testing.assert_array_equal(cmap, cmap[:, ::-1])  # mirror x (twist 0 maps to itself)
    np.testing.assert_array_equal(cmap, cmap[::-1, :])  # mirror y
    np.testing.assert_array_equal(cmap, cmap.T)  # 4-fold: swap x and y
    if method == "greedy":
        bias, limited = max_bias(r, g)
        # docs/physics.md §6.3 / C9: about one pad (p = 90 um); the plateau from p to p + g stops the chip.
        assert (
            set(bias.values()) == {bias["+x"]}
            and 88 <= bias["+x"] <= 96
            and not any(limited.values())
        )


def test_max_bias_walks_out_from_the_origin():
    g = StartGrid.from_ranges((-6, 6, 2), 0.0)  # x = -6 .. 6 at y = 0
    out = np.array([1, 0, 0, 0, 0, 1, 0], np.int8)  # aligned except x = -6 and x = 4
    r = BatchResult(
        "greedy", g.poses(), g.poses(), out, np.zeros(7, np.int32), np.zeros(7), 90.0, (0, 0, 0)
    )
    bias, limited = max_bias(r, g)
    assert bias == {"+x": 2.0, "-x": 4.0, "+y": None, "-y": None}
    assert limited == {"+x": False, "-x": False, "+y": None, "-y": None}


def test_starts_outside_the_twist_range_or_window_are_refused():
    s = make_scene(200, 20, 4.0, 10.0).replace(
        twist=TwistGrid(step_deg=10, min_deg=-20, max_deg=20)
    )
    with pytest.raises(ValueError, match="twist range"):
        run_batch(s, [[0, 0, 40]], progress=False)
    with pytest.raises(ValueError, match="every start twist must be 0"):
        run_batch(s.replace(effects=s.effects.__class__(twist=False)), [[0, 0, 10]], progress=False)
    with pytest.raises(ValueError, match="translation window"):
        run_batch(s.replace(window_um=100), [[150, 0, 0]], progress=False)


def test_realizations_per_sigma():
    chip = mask_from_geometry(square(200), 4.0)
    starts = StartGrid.from_ranges((-40, 40, 40), (-40, 40, 40), 0.0)
    out = run_realizations(
        [2.0, 8.0], [0, 1], chip, starts, scene_options={"twist": TwistGrid(step_deg=10)}
    )
    assert [o["sigma_um"] for o in out] == [2.0, 8.0]
    for o in out:
        assert o["n"] == 2 * starts.size and o["seeds"] == [0, 1] and len(o["optima"]) == 2
        assert set(o) >= {"yield", "outcomes", "error_um", "error_deg", "aligned_error_um"}
    again = run_realizations(
        [8.0], [1], chip, starts, scene_options={"twist": TwistGrid(step_deg=10)}
    )
    assert again[0]["optima"][0] == out[1]["optima"][1]


# ------------------------------------------------------------------ CLI
@pytest.fixture(scope="module")
def fp_png(tmp_path_factory):
    path = tmp_path_factory.mktemp("pat") / "fourpad.png"
    write_mask(path, mask_from_geometry(four_pad(200, 20), 4.0, margin_um=8))
    return path


BASE = ["montecarlo", "--chip-size", "200", "--twist-step", "10", "--quiet"]


def test_cli_grid_json_csv_map(fp_png, tmp_path, capsys):
    j, c, m = tmp_path / "mc.json", tmp_path / "mc.csv", tmp_path / "map.png"
    rc = main(
        BASE
        + [
            "--pattern",
            str(fp_png),
            "--grid=-160:160:16,-160:160:16,-10:10:10",
            "--json",
            str(j),
            "--csv",
            str(c),
            "--map",
            str(m),
        ]
    )
    assert rc == 0
    doc = json.loads(j.read_text())
    assert {"n", "yield", "outcomes", "error_um", "error_deg", "seed", "max_bias_um"} <= set(doc)
    assert doc["n"] == 21 * 21 * 3 and doc["seed"] is None and set(doc["outcomes"]) == set(OUTCOMES)
    assert set(doc["error_um"]) == {"x", "y"} and set(doc["error_deg"]["twist"]) == {
        "mean",
        "mean_abs",
        "std",
        "max_abs",
    }
    lines = c.read_text().splitlines()
    assert (
        lines[0]
        == "start_x_um,start_y_um,start_twist_deg,final_x_um,final_y_um,final_twist_deg,outcome,steps"
    )
    assert len(lines) == doc["n"] + 1
    from PIL import Image

    with Image.open(m) as im:
        assert im.size[0] > 600 and im.size[1] > 200
    out = capsys.readouterr().out
    assert "% aligned" in out and "plateau" in out and "um" in out


def test_cli_random_placement(fp_png, tmp_path):
    j = tmp_path / "r.json"
    args = BASE + [
        "--pattern",
        str(fp_png),
        "--random",
        "200",
        "--spread",
        "30,30,5",
        "--around",
        "40,0,0",
        "--seed",
        "4",
        "--json",
        str(j),
    ]
    assert main(args) == 0
    doc = json.loads(j.read_text())
    assert doc["n"] == 200 and doc["seed"] == 4 and doc["starts"]["distribution"] == "normal"
    assert main(args[:-1] + [str(tmp_path / "r2.json")]) == 0
    again = json.loads((tmp_path / "r2.json").read_text())
    assert again["outcomes"] == doc["outcomes"] and again["error_um"] == doc["error_um"]


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--grid", "0:10,0"], "START:STOP:STEP"),
        (["--grid", "0:10:0,0"], "step must be > 0"),
        (["--grid", "0:a:2,0"], "not a finite number"),
        (["--grid", "0,0,0,0"], "X0:X1:DX"),
        (["--random", "0", "--spread", "1,1,1"], "from 1 to"),
        (["--random", "2.5", "--spread", "1,1,1"], "whole number"),
        (["--random", "10", "--spread=-1,1,1"], "spread must be >= 0"),
        (["--random", "10"], "needs --spread"),
        (["--grid", "0,0", "--random", "10", "--spread", "1,1,1"], "exactly one"),
        ([], "exactly one"),
        (["--grid", "0,0", "--seed", "3"], "applies to --random"),
        (["--random", "10", "--spread", "1,1,1", "--map", "OUT/m.png"], "needs --grid"),
        (["--grid", "0,0", "--map", "OUT/m.jpg"], "must end in"),
        (["--grid", "0,0", "--json", "OUT/missing/x.json"], "does not exist"),
        (["--grid", "0,0", "--chunk", "0"], "chunk must be"),
        (["--grid", "0,0", "--json", "OUT/a.json", "--csv", "OUT/a.json"], "same file"),
    ],
)
def test_cli_bad_input_one_line_exit_2_no_files(fp_png, tmp_path, capsys, extra, match):
    out = tmp_path / "out"
    out.mkdir()
    extra = [e.replace("OUT", str(out)) for e in extra]
    rc = main(
        BASE
        + ["--pattern", str(fp_png), "--json", str(out / "s.json"), "--csv", str(out / "s.csv")]
        + extra
    )
    err = capsys.readouterr().err
    assert rc == 2 and match in err and len(err.strip().splitlines()) == 1
    assert list(out.iterdir()) == []


def test_cli_failure_while_writing_leaves_no_files(fp_png, tmp_path, monkeypatch, capsys):
    from foundation import InputError
    from simulator.commands import montecarlo as cmd

    def broken(*a, **k):
        raise InputError("cannot draw")

    monkeypatch.setattr(cmd, "plot_capture_map", broken)
    rc = main(
        BASE
        + [
            "--pattern",
            str(fp_png),
            "--grid",
            "0:40:20,0",
            "--json",
            str(tmp_path / "a.json"),
            "--csv",
            str(tmp_path / "a.csv"),
            "--map",
            str(tmp_path / "a.png"),
        ]
    )
    assert rc == 2 and "cannot draw" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == []
