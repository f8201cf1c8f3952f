"""Issue 14: the command line as users type it, and answers that mean what they say.

One test (or a few) per point of the issue:

1. the global minimum is the scene's, wherever the pads lie: an off-centre square pad and
   an L-shaped pad whose optimum is turned by 45 degrees align in ``simulate``,
   ``montecarlo`` and ``evaluate``, and :func:`simulator.landscape.global_minimum` (which a
   single run uses, without the full landscape) names the full landscape's pose;
2. a file's stored scale wins, ``--pattern-um-per-px`` / ``--chip-um-per-px`` set what a
   file lacks, a contradicting flag is refused unless ``--override-scale``;
3. words: the equivalent twist of a turned chip, the capture fraction's title, errors
   measured from the target the run reports;
4. negative values after a space parse for every pose, range and list flag;
5. ``selfalign --help`` and ``selfalign pattern`` import neither JAX nor matplotlib;
6. the package configuration lists every package and the library's data files;
7. ``--csv`` of ``simulate`` and ``energy`` parse, with units in the header;
8. docs and help agree with the code: every default a help text quotes, no "%%", an
   ``--invert`` flag, ``--grid`` replacing a scene's ``random``, the files the README names.
"""

from __future__ import annotations

import argparse
import csv
import inspect
import json
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from shapely import affinity
from shapely.geometry import box

from patterns import write_mask
from patterns.geometry import (
    DESIGNS,
    REQUIRED,
    Mask,
    four_pad,
    mask_from_geometry,
    random_jagged,
    square,
)
from patterns.library import library_path
from simulator.cli import build_parser, main
from simulator.physics import Materials
from simulator.scene import Effects, Scene, TwistGrid

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("cli_usage")

ROOT = Path(__file__).resolve().parents[1]
SQUARE = str(library_path("square_200"))  # 200 um square pad at 1 um/px


def one_line_error(rc: int, err: str, *needles: str) -> None:
    assert rc == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for n in needles:
        assert n in err, err


# ============================================================ 1. the global minimum
def l_shape():
    """A 200 um square less a 100 um corner, turned by 45 degrees: a 200 um chip covers it
    whole only at twist 45 = -45 degrees (square symmetry), centred on the origin."""
    return affinity.rotate(
        box(-100, -100, 100, 100).difference(box(0, 0, 100, 100)), 45, origin=(0, 0)
    )


@pytest.fixture(scope="module")
def pads(tmp_path_factory):
    """PNGs at 2 um/px: the L-shaped pad, and a 200 um square pad centred at (150, 100) um
    of a 700 x 500 um image."""
    d = tmp_path_factory.mktemp("pads")
    write_mask(d / "L.png", Mask(mask_from_geometry(l_shape(), 2.0, margin_um=20).data, 2.0))
    write_mask(
        d / "off.png",
        Mask(mask_from_geometry(box(50, 0, 250, 200), 2.0, shape=(250, 350)).data, 2.0),
    )
    return d


#: (png, start, the global minimum (x, y, twist), twists of the same pose)
CASES = {
    "L": ("L.png", "60,-40,10", (0.0, 0.0, -45.0), (45.0, -45.0)),
    "off": ("off.png", "100,60,5", (150.0, 100.0, 0.0), (0.0,)),
}
FAST = ["--chip-size", "200", "--twist-step", "5"]


@pytest.mark.parametrize("case", sorted(CASES))
def test_simulate_aligns_at_the_scenes_global_minimum(case, pads, tmp_path, run_cli):
    png, start, opt, twists = CASES[case]
    out = tmp_path / "t.json"
    rc, stdout, err = run_cli(
        ["simulate", "--pattern", pads / png, *FAST, "--start", start, "--json", out, "--quiet"]
    )
    assert rc == 0, err
    doc = json.loads(out.read_text())
    assert doc["outcome"] == "aligned" and stdout.startswith("greedy: aligned at"), stdout
    f = doc["final"]
    assert (f["x_um"], f["y_um"]) == opt[:2] and f["twist_deg"] in twists
    assert (doc["optimum"]["x_um"], doc["optimum"]["y_um"], doc["optimum"]["twist_deg"]) == opt


@pytest.mark.parametrize("case", sorted(CASES))
def test_montecarlo_aligns_and_measures_errors_from_the_minimum(case, pads, tmp_path, run_cli):
    png, _, opt, _ = CASES[case]
    out = tmp_path / "mc.json"
    around = f"{opt[0] - 10:g},{opt[1] + 10:g},{opt[2] + 5:g}"
    rc, stdout, err = run_cli(
        [
            "montecarlo",
            "--pattern",
            pads / png,
            *FAST,
            "--random",
            "40",
            "--spread",
            "4,4,2",
            "--around",
            around,
            "--seed",
            "1",
            "--json",
            out,
            "--quiet",
        ]
    )
    assert rc == 0, err
    doc = json.loads(out.read_text())
    assert doc["yield"] >= 0.9, doc["outcomes"]
    g = doc["error_target"]
    assert g["kind"] == "global_minimum" and (g["x_um"], g["y_um"], g["twist_deg"]) == opt
    assert (doc["optimum"]["x_um"], doc["optimum"]["y_um"], doc["optimum"]["twist_deg"]) == opt
    # aligned means within one grid step (2 um, 5 deg) of the target the errors are measured from
    assert (
        doc["aligned_error_um"]["x"]["max_abs"] <= 2
        and doc["aligned_error_um"]["y"]["max_abs"] <= 2
    )
    assert doc["aligned_error_deg"]["twist"]["max_abs"] <= 5
    assert f"from the global minimum ({opt[0]:g} um, {opt[1]:g} um, {opt[2]:g} deg)" in stdout


@pytest.mark.parametrize("case", sorted(CASES))
def test_evaluate_reports_the_minimum_and_measures_around_it(
    case, pads, tmp_path, run_cli, monkeypatch
):
    import simulator.batch._evaluate as evaluating
    from simulator.render import plot_capture_map

    titles = []
    draw = plot_capture_map
    monkeypatch.setattr(
        evaluating,
        "plot_capture_map",
        lambda *a, **k: (titles.append(k.get("title", "")), draw(*a, **k)),
    )
    png, _, opt, _ = CASES[case]
    rep = tmp_path / "rep"
    rc, stdout, err = run_cli(["evaluate", pads / png, *FAST, "--out", rep, "--quiet"])
    assert rc == 0, err
    s = json.loads((rep / "summary.json").read_text())
    g = s["global_minimum"]
    assert (g["x_um"], g["y_um"], g["twist_deg"]) == opt
    assert (
        s["capture"]["center"] == {"x_um": opt[0], "y_um": opt[1]}
        and s["capture"]["twist_deg"] == opt[2]
    )
    assert s["capture"]["fraction"] > 0.3 and s["yield"]["fraction"] > 0.9
    assert (
        s["yield"]["error_um"]["x"]["max_abs"] <= 2 and s["yield"]["error_um"]["y"]["max_abs"] <= 2
    )
    assert f"global minimum at ({opt[0]:g} um, {opt[1]:g} um, {opt[2]:g} deg)" in stdout
    # 3. the capture map's title says what the report says: the capture fraction
    assert titles and "capture fraction" in titles[0] and "yield" not in titles[0]
    assert f"{100 * s['capture']['fraction']:.1f} %" in titles[0]


def _scenes():
    """Scenes whose global minimum lies anywhere: off-centre, turned, jagged, degenerate."""
    g2 = mask_from_geometry
    off = g2(box(50, 0, 250, 200), 2.0, shape=(250, 350))
    yield (
        "L",
        Scene(
            pattern=g2(l_shape(), 2.0, margin_um=20),
            chip=g2(square(200), 2.0),
            twist=TwistGrid(5.0),
        ),
    )
    yield "off-centre", Scene(pattern=off, chip=g2(square(200), 2.0), twist=TwistGrid(5.0))
    yield (
        "off-centre, no twist",
        Scene(pattern=off, chip=g2(square(200), 2.0), effects=Effects(twist=False)),
    )
    yield (
        "off-centre, bounded twist",
        Scene(pattern=off, chip=g2(square(200), 2.0), twist=TwistGrid(3.0, 6.0, 30.0)),
    )
    yield (
        "jagged",
        Scene(
            pattern=g2(random_jagged(120, sigma=3, seed=4), 1.0, margin_um=8),
            chip=g2(square(120), 1.0),
            twist=TwistGrid(3.0),
        ),
    )
    yield (
        "chip larger than pattern",
        Scene(
            pattern=g2(square(60), 1.0, margin_um=10),
            chip=g2(square(150), 1.0),
            twist=TwistGrid(3.0),
        ),
    )
    yield (
        "chip smaller than a pad",
        Scene(
            pattern=g2(four_pad(200, 20), 2.0, margin_um=10),
            chip=g2(square(8), 2.0),
            twist=TwistGrid(9.0),
        ),
    )
    yield (
        "chip larger than pattern, two periods of twist",
        Scene(
            pattern=g2(square(40), 2.0, margin_um=10),
            chip=g2(square(100), 2.0),
            twist=TwistGrid(15.0, -180.0, 180.0),
        ),
    )
    yield (
        "repulsive pad",
        Scene(
            pattern=g2(box(20, 0, 80, 60), 2.0, shape=(60, 100)),
            chip=g2(square(60), 2.0),
            twist=TwistGrid(15.0),
            materials=Materials(pad_angle_deg=70.0, substrate_angle_deg=40.0, allow_repulsive=True),
        ),
    )
    yield (
        "chip image",
        Scene(
            pattern=g2(four_pad(120, 12), 1.0, margin_um=6),
            chip=Mask(g2(box(-40, -30, 40, 30), 1.0).data, 1.0),
            twist=TwistGrid(6.0),
        ),
    )


@pytest.mark.parametrize("name, scene", list(_scenes()), ids=[n for n, _ in _scenes()])
def test_global_minimum_without_the_full_landscape_is_the_full_landscapes(name, scene):
    from simulator.landscape import build_landscape, global_minimum

    ls = build_landscape(scene)
    want = ls.global_minimum()
    got = global_minimum(scene)
    assert got.pose == want[:3], (name, got)
    assert abs(got.energy_J - want[3]) <= ls.noise_floor_J
    if (
        name == "repulsive pad"
    ):  # no bound applies (Delta_gamma > 0): the whole landscape, in chunks
        assert got.how == "full landscape"
    else:  # proved without computing the whole landscape
        assert got.how in ("absolute bound", "cell bound") and got.poses < ls.energy.size


def test_cell_bound_is_an_upper_bound_on_every_pose():
    # The proof's inequality, checked on every cell of two small scenes (exact chip, chip image)
    # against the float64 landscape: the bound never falls below the overlap it bounds.
    from simulator.landscape import build_landscape
    from simulator.landscape._overlap_bound import _Bounds

    scenes = [
        Scene(
            pattern=mask_from_geometry(four_pad(100, 10), 1.0, margin_um=5),
            chip=mask_from_geometry(square(70), 1.0),
            twist=TwistGrid(15.0),
            dtype="float64",
        ),
        Scene(
            pattern=mask_from_geometry(random_jagged(60, sigma=2, seed=1), 1.0, margin_um=4),
            chip=Mask(mask_from_geometry(square(31), 1.0).data, 1.0),
            twist=TwistGrid(20.0),
            dtype="float64",
        ),
    ]
    for s in scenes:
        ls, b = build_landscape(s), _Bounds(s)
        area = ls.energy / b.scale
        for k in (2, 3, 5):
            for j in range(len(ls.twist_deg)):
                m, n, lower = b.cells(j, k)
                x0, x1, y0, y1 = b.cell_px(m, n, k)
                for i in np.flatnonzero((x0 <= x1) & (y0 <= y1)):
                    a = area[
                        j, y0[i] + b.ry : y1[i] + b.ry + 1, x0[i] + b.rx : x1[i] + b.rx + 1
                    ].max()
                    assert lower[i] / b.scale >= a - 1e-9 * b.pat.sum(), (k, j, i)


def test_landscape_picture_stars_the_minimum_only_where_it_is(monkeypatch, tmp_path):
    # The global minimum of the L-shaped pad is at -45 deg: the 0 deg panel has no star.
    from simulator.landscape import build_landscape
    from simulator.render import _figures as render

    figs = []
    monkeypatch.setattr(render, "save_figure", lambda fig, path: figs.append(fig))
    s = Scene(
        pattern=mask_from_geometry(l_shape(), 4.0, margin_um=20),
        chip=mask_from_geometry(square(200), 4.0),
        twist=TwistGrid(15.0),
    )
    render.plot_landscape(build_landscape(s), tmp_path / "l.png", pattern=s.pattern)
    axes = [a for a in figs[0].axes if a.get_label() != "<colorbar>"][:2]
    stars = [[ln for ln in a.get_lines() if ln.get_marker() == "*"] for a in axes]
    assert not stars[0] and len(stars[1]) == 1
    assert "-45°" in stars[1][0].get_label() and "-45°" in axes[0].get_title()


# ============================================================ 2. scale precedence
@pytest.fixture(scope="module")
def scaled(tmp_path_factory):
    """A 180 um pad stored at 2 um/px, and a 180 x 180 px chip image with no scale."""
    d = tmp_path_factory.mktemp("scale")
    write_mask(d / "pat2.png", mask_from_geometry(square(180), 2.0, margin_um=20))
    Image.fromarray(np.pad(np.full((180, 180), 255, np.uint8), 10)).save(d / "chip.png")
    return d


@pytest.mark.parametrize(
    "flags, overlap",
    [
        (["--chip-um-per-px", "1"], 32400.0),  # the pattern keeps its 2 um/px; the chip is 180 um
        (
            ["--um-per-px", "2"],
            32400.0,
        ),  # agrees with the pattern, gives the chip its scale (360 um)
        (
            ["--um-per-px", "1", "--override-scale"],
            8100.0,
        ),  # the old behaviour, asked for: a 90 um pad
        (["--pattern-um-per-px", "2", "--chip-um-per-px", "1"], 32400.0),
    ],
)
def test_a_files_scale_wins_and_flags_set_what_files_lack(
    scaled, flags, overlap, tmp_path, run_cli
):
    out = tmp_path / "e.json"
    rc, _, err = run_cli(
        [
            "energy",
            "--pattern",
            scaled / "pat2.png",
            "--chip",
            scaled / "chip.png",
            "--no-twist",
            "--at",
            "0,0,0",
            "--json",
            out,
            *flags,
        ]
    )
    assert rc == 0, err
    # float32: within the landscape's noise floor, 32 eps(float32) of max|E| (the FFT
    # round-off bound); at (0, 0, 0) the overlap is max|E| (rel=1e-6, 8 eps, was one path's luck)
    assert json.loads(out.read_text())["poses"][0]["overlap_um2"] == pytest.approx(
        overlap, rel=32 * float(np.finfo(np.float32).eps)
    )


@pytest.mark.parametrize(
    "flags, needles",
    [
        (
            ["--um-per-px", "1"],
            [
                "pat2.png stores its scale, 2 um/px",
                "--um-per-px 1 contradicts it",
                "--override-scale",
            ],
        ),
        (
            ["--pattern-um-per-px", "1", "--chip-um-per-px", "1"],
            ["--pattern-um-per-px 1 contradicts it"],
        ),
        ([], ["chip.png has no scale", "--chip-um-per-px"]),
    ],
)
def test_a_contradicting_or_missing_scale_is_one_line(scaled, flags, needles, run_cli):
    rc, _, err = run_cli(
        [
            "energy",
            "--pattern",
            scaled / "pat2.png",
            "--chip",
            scaled / "chip.png",
            "--no-twist",
            "--at",
            "0,0,0",
            *flags,
        ]
    )
    one_line_error(rc, err, *needles)


def test_scene_keys_follow_the_same_rule(scaled, tmp_path):
    toml = tmp_path / "s.toml"
    toml.write_text(
        f'pattern = "{scaled / "pat2.png"}"\nchip = "{scaled / "chip.png"}"\num_per_px = 1\n[effects]\ntwist = false\n'
    )
    with pytest.raises(Exception, match="contradicts it"):
        Scene.from_toml(toml)
    toml.write_text(toml.read_text().replace("um_per_px = 1", "chip_um_per_px = 1"))
    s = Scene.from_toml(toml)
    assert s.um_per_px == 2.0 and s.chip.area_um2 == pytest.approx(180**2)


# ============================================================ 3. words
def _traj(final, outcome="aligned"):
    from simulator.motion import Trajectory

    path = np.array([[40.0, 0.0, 0.0], final])
    return Trajectory("greedy", outcome, path, np.zeros(2), 1, optimum=(0.0, 0.0, 0.0))


@pytest.mark.parametrize(
    "chip, final, words",
    [
        (
            square(200),
            (0.0, 0.0, 90.0),
            "aligned at (0.00 um, 0.00 um, 90.00 deg) (twist 90 deg = 0 deg for a square chip) after 1 steps",
        ),
        (square(200), (0.0, 0.0, -90.0), "(twist -90 deg = 0 deg for a square chip)"),
        (
            box(-100, -50, 100, 50),
            (0.0, 0.0, 180.0),
            "(twist 180 deg = 0 deg for a rectangular chip)",
        ),
        (square(200), (0.0, 0.0, 3.0), "aligned at (0.00 um, 0.00 um, 3.00 deg) after 1 steps"),
    ],
)
def test_a_turned_chip_is_reported_with_its_equivalent_twist(chip, final, words):
    from simulator.commands.simulate import end_line

    s = Scene(
        pattern=mask_from_geometry(square(200), 4.0, margin_um=8),
        chip=mask_from_geometry(chip, 4.0),
    )
    line = end_line(s, _traj(final))
    assert words in line and "global minimum" not in line


def test_a_run_that_does_not_align_names_the_minimum():
    from simulator.commands.simulate import end_line

    s = Scene(
        pattern=mask_from_geometry(square(200), 4.0, margin_um=8),
        chip=mask_from_geometry(square(200), 4.0),
    )
    assert end_line(s, _traj((100.0, 0.0, 0.0), "plateau")).endswith(
        "; the global minimum is at (0 um, 0 um, 0 deg)"
    )


@pytest.mark.parametrize(
    "time_s, words",
    [
        (6.88e-3, "after 1 steps, 6.88 ms"),
        (0.9996, "after 1 steps, 1 s"),
        (2.5, "after 1 steps, 2.5 s"),
    ],
)
def test_a_dynamic_run_s_time_reads_in_ms_or_s(time_s, words):
    # a run of 1 s of simulated time read "1e+03 ms"
    from simulator.commands.simulate import end_line
    from simulator.motion import Trajectory

    s = Scene(
        pattern=mask_from_geometry(square(200), 4.0, margin_um=8),
        chip=mask_from_geometry(square(200), 4.0),
    )
    path = np.array([[40.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    t = Trajectory("overdamped", "aligned", path, np.zeros(2), 1, time_s, optimum=(0.0, 0.0, 0.0))
    assert end_line(s, t).endswith(words)


# ============================================================ 4. negative values after a space
NEGATIVE_FORMS = [
    (["simulate", "--pattern", "p.png", "--start", "-300,200,10"], "start", "-300,200,10"),
    (["energy", "--pattern", "p.png", "--at", "-40,25,0"], "at", ["-40,25,0"]),
    (["energy", "--pattern", "p.png", "--at", "-1e-3,-2.5,-0.5"], "at", ["-1e-3,-2.5,-0.5"]),
    (
        ["energy", "--pattern", "p.png", "--curve", "x", "--from", "-60", "--to", "-10"],
        "start",
        -60.0,
    ),
    (
        ["energy", "--pattern", "p.png", "--curve", "x", "--from", "-60", "--to", "-10"],
        "stop",
        -10.0,
    ),
    (
        ["montecarlo", "--pattern", "p.png", "--grid", "-100:100:50,-100:100:50"],
        "grid",
        "-100:100:50,-100:100:50",
    ),
    (
        ["montecarlo", "--pattern", "p.png", "--grid", "-100:100:50,0,-10:10:10"],
        "grid",
        "-100:100:50,0,-10:10:10",
    ),
    (
        ["montecarlo", "--pattern", "p.png", "--random", "5", "--around", "-60,0,0"],
        "around",
        "-60,0,0",
    ),
    (
        ["pattern", "polygon", "--points", "-100,-100;100,-100;0,100", "-o", "p.png"],
        "p_points",
        "-100,-100;100,-100;0,100",
    ),
    (
        ["pattern", "polygon", "--points", "-100,-100; 100,-100; 0,100", "-o", "p.png"],
        "p_points",
        "-100,-100; 100,-100; 0,100",
    ),
    (["simulate", "--pattern", "p.png", "--start", "-3,2,1", "--window", "-5"], "window", -5.0),
]


@pytest.mark.parametrize("argv, dest, value", NEGATIVE_FORMS)
def test_every_negative_value_form_parses(argv, dest, value):
    assert getattr(build_parser().parse_args(argv), dest) == value


def test_negative_values_after_a_space_run(tmp_path, capsys, run_cli):
    out = tmp_path / "e.json"
    rc, _, err = run_cli(
        [
            "energy",
            "--pattern",
            SQUARE,
            "--chip-size",
            "200",
            "--resolution",
            "4",
            "--at",
            "-40,25,0",
            "--curve",
            "x",
            "--from",
            "-60",
            "--to",
            "-12",
            "--json",
            out,
        ]
    )
    assert rc == 0, err
    doc = json.loads(out.read_text())
    assert doc["poses"][0]["x_um"] == -40 and doc["curve"]["values_um"][0] == -60
    rc, _, err = run_cli(
        ["pattern", "polygon", "--points", "-100,-100;100,-100;0,100", "-o", tmp_path / "tri.png"]
    )
    assert rc == 0, err
    # a word that is not a number still reads as an option
    with pytest.raises(SystemExit) as exit_:
        main(["energy", "--pattern", SQUARE, "--at", "-x"])
    assert exit_.value.code == 2 and "expected one argument" in capsys.readouterr().err


# ============================================================ 5. start-up
HEAVY = (
    "jax",
    "jaxlib",
    "matplotlib",
    "diffrax",
    "scipy.signal",
    "simulator.landscape._build",
    "simulator.landscape._landscape",
    "simulator.motion._trajectory",
)
PROBE = """
import contextlib, io, json, sys
from simulator.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    try:
        main(json.loads(sys.argv[1]))
    except SystemExit:
        pass
print(json.dumps(sorted(m for m in sys.modules if m in json.loads(sys.argv[2]) or m.split(".")[0] in ("jax", "matplotlib"))))
"""


def test_a_command_registers_its_own_parser_only():
    """``selfalign simulate ...`` imports and registers the simulate command alone (the others'
    modules cost 0.1 s at every start); no command, or a misspelt one, gets them all (the
    listing of ``--help`` and of argparse's "invalid choice")."""
    from simulator.cli import COMMANDS

    def commands(parser):
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        return list(sub.choices)

    assert commands(build_parser()) == list(COMMANDS) == commands(build_parser("simulat"))
    assert all(commands(build_parser(name)) == [name] for name in COMMANDS)
    with pytest.raises(SystemExit):
        build_parser("simulat").parse_args(["simulat"])


@pytest.mark.parametrize(
    "argv",
    [
        ["--help"],
        ["pattern", "--list"],
        ["pattern", "--help"],
        ["simulate", "--help"],
        ["pattern", "square", "--size", "50", "-o", "{d}/sq.png"],
    ],
)
def test_help_and_pattern_do_not_import_jax_or_matplotlib(argv, tmp_path):
    argv = [a.replace("{d}", str(tmp_path)) for a in argv]
    out = subprocess.run(
        [sys.executable, "-c", PROBE, json.dumps(argv), json.dumps(HEAVY)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


HUGEPAGE_PROBE = """
import json, os, sys
from simulator.cli import main
main(["pattern", "--list"])
from numpy._core.multiarray import _get_madvise_hugepage
print(json.dumps([os.environ.get("NUMPY_MADVISE_HUGEPAGE"), bool(_get_madvise_hugepage())]))
"""


@pytest.mark.skipif(sys.platform != "linux", reason="NumPy advises hugepages on Linux only")
@pytest.mark.parametrize("user", [None, "1", "0"])
def test_the_command_asks_numpy_for_no_hugepages_unless_the_user_says(user):
    # simulator.cli.HUGEPAGE_ADVICE: the command's process sets NUMPY_MADVISE_HUGEPAGE=0 before
    # NumPy is imported, and keeps a value the user set (1 turns the advice back on)
    import os

    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    if user is not None:
        env["NUMPY_MADVISE_HUGEPAGE"] = user
    out = subprocess.run(
        [sys.executable, "-c", HUGEPAGE_PROBE],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
        env=env,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    value, advised = json.loads(out.stdout.strip().splitlines()[-1])
    assert value == (user or "0")
    assert advised == (value == "1")


# ============================================================ 6. install
def test_pyproject_lists_every_package_and_the_library_files():
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    packages = set(conf["packages"])
    for top in ("simulator", "patterns"):
        for init in (ROOT / top).rglob("__init__.py"):
            assert ".".join(init.parent.relative_to(ROOT).parts) in packages, init
    data = conf["package-data"]["patterns.library"]
    assert "patterns.library" in packages
    for f in (ROOT / "patterns" / "library").iterdir():
        assert any(f.match(pat) for pat in data), f


# ============================================================ 7. CSV outputs
def test_simulate_csv_is_the_path_with_units(tmp_path, run_cli):
    j, c = tmp_path / "t.json", tmp_path / "t.csv"
    rc, out, err = run_cli(
        [
            "simulate",
            "--pattern",
            SQUARE,
            "--chip-size",
            "200",
            "--resolution",
            "4",
            "--twist-step",
            "5",
            "--start",
            "-40,24,5",
            "--json",
            j,
            "--csv",
            c,
            "--quiet",
        ]
    )
    assert rc == 0, err
    assert f"wrote {c}" in out
    rows = list(csv.DictReader(c.read_text().splitlines()))
    assert list(rows[0]) == ["step", "x_um", "y_um", "twist_deg", "energy_J"]
    path = json.loads(j.read_text())["path"]
    assert len(rows) == len(path) and [int(r["step"]) for r in rows] == list(range(len(path)))
    for r, p in zip(rows, path, strict=True):
        assert [float(r[k]) for k in ("x_um", "y_um", "twist_deg")] == [
            p["x_um"],
            p["y_um"],
            p["twist_deg"],
        ]
        assert float(r["energy_J"]) == pytest.approx(p["energy_J"], rel=1e-9)


def test_simulate_engine_flag_picks_the_engine_and_keeps_the_path(tmp_path, run_cli):
    paths = {}
    for engine in ("fft", "path", "auto"):
        j = tmp_path / f"{engine}.json"
        rc, out, err = run_cli(
            [
                "simulate",
                "--pattern",
                SQUARE,
                "--chip-size",
                "200",
                "--resolution",
                "4",
                "--twist-step",
                "5",
                "--start",
                "-40,24,5",
                "--engine",
                engine,
                "--json",
                j,
                "--quiet",
            ]
        )
        assert rc == 0, err
        doc = json.loads(j.read_text())
        assert doc["cost"]["engine"] == (
            "fft" if engine == "auto" else engine
        )  # auto: a small chip stays on FFT
        assert ("(path engine)" in out) == (engine == "path")
        paths[engine] = [
            (p["x_um"], p["y_um"], p["twist_deg"]) for p in doc["path"]
        ]  # energies: each engine's round-off
    assert paths["fft"] == paths["path"] == paths["auto"]
    rc, _, err = run_cli(
        [
            "simulate",
            "--pattern",
            SQUARE,
            "--chip-size",
            "200",
            "--resolution",
            "4",
            "--start",
            "-40,24,0",
            "--method",
            "overdamped",
            "--engine",
            "path",
        ]
    )
    assert rc != 0 and "--engine path" in err


def test_energy_csv_holds_poses_and_curve_with_units(tmp_path, run_cli):
    j, c = tmp_path / "e.json", tmp_path / "e.csv"
    rc, _, err = run_cli(
        [
            "energy",
            "--pattern",
            SQUARE,
            "--chip-size",
            "200",
            "--resolution",
            "4",
            "--at",
            "-40,24,0",
            "--at",
            "0,0,0",
            "--curve",
            "x",
            "--from",
            "-60",
            "--to",
            "60",
            "--json",
            j,
            "--csv",
            c,
        ]
    )
    assert rc == 0, err
    rows = list(csv.DictReader(c.read_text().splitlines()))
    assert list(rows[0]) == [
        "kind",
        "x_um",
        "y_um",
        "twist_deg",
        "overlap_um2",
        "energy_J",
        "force_x_N",
        "force_y_N",
        "torque_Nm",
    ]
    doc = json.loads(j.read_text())
    poses, curve = (
        [r for r in rows if r["kind"] == "pose"],
        [r for r in rows if r["kind"] == "curve"],
    )
    assert len(poses) == 2 and len(curve) == len(doc["curve"]["values_um"])
    for r, p in zip(poses, doc["poses"], strict=True):
        assert float(r["overlap_um2"]) == pytest.approx(p["overlap_um2"], rel=1e-9)
        assert float(r["force_x_N"]) == pytest.approx(p["force_N"][0], rel=1e-9, abs=1e-30)
    assert [float(r["x_um"]) for r in curve] == doc["curve"]["values_um"]
    assert {float(r["y_um"]) for r in curve} == {24.0}
    assert [float(r["energy_J"]) for r in curve] == pytest.approx(
        doc["curve"]["energy_J"], rel=1e-9
    )
    assert [float(r["force_x_N"]) for r in curve] == pytest.approx(
        doc["curve"]["force_N"], rel=1e-9, abs=1e-30
    )


# ============================================================ 8. docs and help
def _parsers():
    """(command path, parser) of every parser of the command line."""

    def walk(parser, path):
        yield path, parser
        for a in parser._actions:
            if isinstance(a, argparse._SubParsersAction):
                for name, sub in a.choices.items():
                    yield from walk(sub, path + [name])

    yield from walk(build_parser(), [])


def _code_defaults() -> dict[str, object]:
    """The code's default for each flag whose argparse default is None (resolved downstream)."""
    from foundation import DEFAULT_BUDGET_CAP_MB, DEFAULT_MAX_IMAGE_MPX
    from patterns.layout import DEFAULT_MAX_POLYGONS, DEFAULT_UM_PER_PX
    from simulator.batch import StartGrid, random_starts
    from simulator.core import DEFAULT_CHUNK, DEFAULT_MAX_STEPS, METHODS
    from simulator.design import DRAWS, PROFILE, TIME_SIGMA, TRIALS
    from simulator.physics import Liquid, Materials
    from simulator.scene import DEFAULT_PRESET

    scene_fields = Scene.__dataclass_fields__
    m, liq = Materials(), Liquid()
    return {
        "--surface-tension": m.surface_tension_N_m * 1e3,
        "--pad-angle": m.pad_angle_deg,
        "--substrate-angle": m.substrate_angle_deg,
        "--twist-step": TwistGrid().step_deg,
        "--dtype": scene_fields["dtype"].default,
        "--max-image-mpx": DEFAULT_MAX_IMAGE_MPX,
        "--accuracy": DEFAULT_PRESET,
        "--volume": liq.volume_nl,
        "--viscosity": liq.viscosity_Pa_s * 1e3,
        "--chip-thickness": scene_fields["chip_thickness_um"].default,
        "--chip-density": scene_fields["chip_density_kg_m3"].default,
        "--damping-calibration": scene_fields["damping_calibration"].default,
        "--line-friction": scene_fields["line_friction_Pa_s"].default,
        "--max-steps": DEFAULT_MAX_STEPS,
        "--chunk": DEFAULT_CHUNK,
        "--method": METHODS[0],
        "--seed": 0,
        "--distribution": inspect.signature(random_starts).parameters["distribution"].default,
        "--around": ",".join(
            f"{v:g}" for v in inspect.signature(random_starts).parameters["around"].default
        ),
        "--grid": inspect.signature(StartGrid.from_ranges).parameters["twist_deg"].default,
        "--memory-budget": DEFAULT_BUDGET_CAP_MB,
        "--density": liq.density_kg_m3,
        "--um-per-px": DEFAULT_UM_PER_PX,
        "--max-polygons": DEFAULT_MAX_POLYGONS,
        # calibrate
        "--trials": TRIALS,
        "--draws": DRAWS,
        "--time-sigma": TIME_SIGMA,
        "--profile": PROFILE,
    }


def _same(quoted: str, value) -> bool:
    try:
        return float(quoted) == float(value)
    except (TypeError, ValueError):
        return quoted == str(value)


def test_every_default_a_help_text_quotes_is_the_codes():
    code = _code_defaults()
    checked = 0
    for path, parser in _parsers():
        for a in parser._actions:
            if not a.help or not a.option_strings:
                continue
            flag = a.option_strings[-1]
            text = " ".join(a.help.split())
            for q in re.findall(
                r"\(default:? ([-+0-9.e,]+|[a-z][a-z0-9_]*)[),;]", text
            ) + re.findall(r"at most (\d+);", text):
                if q in ("off", "none", "unknown"):  # not set: nothing is assumed
                    assert a.default in (None, False), (
                        f"{' '.join(path)} {flag}: help says default {q}, argparse has {a.default!r}"
                    )
                    checked += 1
                    continue
                if (
                    path[:1] == ["pattern"]
                    and len(path) == 2
                    and f"p_{flag[2:].replace('-', '_')}" == a.dest
                ):
                    p = next(p for p in DESIGNS[path[1]].params if p.flag == flag)
                    want = (
                        p.default
                        if p.default not in (None, REQUIRED)
                        else inspect.signature(DESIGNS[path[1]].builder).parameters[p.name].default
                    )
                elif a.default is not None and not isinstance(a.default, bool):
                    want = a.default
                else:
                    assert flag in code, (
                        f"{' '.join(path)} {flag} quotes a default ({q}): add the code's default to _code_defaults"
                    )
                    want = code[flag]
                assert _same(q, want), (
                    f"{' '.join(path)} {flag}: help says default {q}, the code uses {want}"
                )
                checked += 1
    assert checked >= 30


def test_help_texts_print_no_doubled_percent():
    for path, parser in _parsers():
        assert "%%" not in parser.format_help(), " ".join(path)


@pytest.mark.fft
def test_all_black_masks_name_the_invert_flags_and_invert_works(tmp_path, run_cli):
    ink = np.full((120, 120), 255, np.uint8)
    ink[10:110, 10:110] = 0  # a black 100 um pad on white
    Image.fromarray(ink).save(tmp_path / "ink.png", dpi=(25400, 25400))
    Image.fromarray(np.zeros((50, 50), np.uint8)).save(tmp_path / "black.png", dpi=(25400, 25400))
    out = tmp_path / "e.json"
    rc, _, err = run_cli(
        [
            "energy",
            "--pattern",
            tmp_path / "ink.png",
            "--invert",
            "--chip-size",
            "100",
            "--no-twist",
            "--at",
            "0,0,0",
            "--json",
            out,
        ]
    )
    assert rc == 0, err
    doc = json.loads(out.read_text())
    # float32: within the noise floor, 32 eps(float32) max|E| (the FFT round-off bound),
    # 0.04 um^2 at max|E| = 100^2 um^2 (the default rel=1e-6, 0.01 um^2, was below it)
    floor_um2 = doc["noise_floor_J"] / (abs(doc["delta_gamma_N_m"]) * 1e-12)
    assert doc["poses"][0]["overlap_um2"] == pytest.approx(100 * 100, abs=floor_um2)
    rc, _, err = run_cli(
        ["energy", "--pattern", tmp_path / "black.png", "--chip-size", "10", "--at", "0,0,0"]
    )
    one_line_error(rc, err, "all black", "--invert")
    rc, _, err = run_cli(
        ["energy", "--pattern", SQUARE, "--chip", tmp_path / "black.png", "--at", "0,0,0"]
    )
    one_line_error(rc, err, "all black", "--invert-chip")
    rc, _, err = run_cli(
        [
            "energy",
            "--pattern",
            SQUARE,
            "--chip",
            tmp_path / "ink.png",
            "--invert-chip",
            "--no-twist",
            "--at",
            "0,0,0",
            "--json",
            out,
            "--force",  # replaces the first run's JSON, as asked
        ]
    )
    assert rc == 0, err


def test_a_grid_flag_replaces_the_scenes_random_starts(tmp_path, run_cli):
    toml = tmp_path / "mc.toml"
    toml.write_text(
        f'pattern = "{SQUARE}"\nchip_size_um = 200\nresolution_um = 4\n[twist]\nstep_deg = 10\n'
        "[montecarlo]\nrandom = 20\nspread = [10, 10, 1]\naround = [20, 0, 0]\nseed = 3\n"
    )
    out = tmp_path / "mc.json"
    rc, _, err = run_cli(
        ["montecarlo", toml, "--grid", "-40:40:20,-40:40:20", "--json", out, "--quiet"]
    )
    assert rc == 0, err
    doc = json.loads(out.read_text())
    assert doc["starts"]["kind"] == "grid" and doc["n"] == 25 and doc["seed"] is None
    rc, _, err = run_cli(
        ["montecarlo", toml, "--json", out, "--quiet", "--force"]
    )  # the scene's own random starts (replacing the first run's JSON, as asked)
    assert rc == 0, err
    assert json.loads(out.read_text())["starts"]["kind"] == "random"


def test_the_files_the_readme_names_exist():
    # the README and the manual's pages it links (docs/): the user guide moved there
    readme = "\n".join(
        p.read_text() for p in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    )
    assert "PHYSICS.md" not in readme
    named = set(
        re.findall(
            r"(?<![\w/.])((?:notebooks|examples|docs|benchmarks|tests)/[\w./-]+\.(?:ipynb|toml|md|py|png|gif|gds))",
            readme,
        )
    )
    assert "notebooks/d_accuracy_cost.ipynb" in named
    missing = sorted(p for p in named if not (ROOT / p).exists())
    assert not missing, missing


def test_threads_come_from_selfalign_threads(run_cli, monkeypatch):
    from simulator.core import threads
    from simulator.landscape import Correlator, Window

    monkeypatch.setenv("SELFALIGN_THREADS", "1")
    assert threads() == 1
    assert Correlator(np.ones((8, 8)), (3, 3), Window(2, 2, 3, 3), "float32", "scipy").workers == 1
    monkeypatch.setenv("SELFALIGN_THREADS", "two")
    rc, _, err = run_cli(
        [
            "simulate",
            "--pattern",
            str(library_path("square_200")),
            "--chip-size",
            "200",
            "--start",
            "10,5,0",
            "--quiet",
        ]
    )
    one_line_error(rc, err, "SELFALIGN_THREADS='two'", "whole number")
    monkeypatch.delenv("SELFALIGN_THREADS")
    import os

    assert threads() == (os.cpu_count() or 1)
