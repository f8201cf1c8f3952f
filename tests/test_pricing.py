"""Priced before the work, and seen while it runs.

Every refusal for memory comes before the expensive work: each oversize case runs the
command in a fresh process whose expensive functions (the chip's meniscus footprint and
its distance transform, the chip's rotations, the correlator, the stepper's compilation,
the global minimum's bound, the Monte Carlo chunks) raise if they are called, and whose
own peak memory is measured; the refusal is one line with the fix, exit code 2.

Every step that can take more than a few seconds says so on stderr (not with ``--quiet``):
tested on small cases with the threshold lowered to 0 s (``SELFALIGN_WAIT_S``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import one_line_error

from foundation import WAIT_ENV, WAIT_S, quiet_waits, shows_wait, wait_threshold_s
from simulator.physics import Liquid
from simulator.scene import Effects, Scene

LIB = Path(__file__).resolve().parents[1] / "patterns" / "library"

#: A refused command's own peak memory (RSS): Python, NumPy, SciPy, JAX and the inputs.
REFUSED_RSS_MB = 500

#: Runs ``selfalign ARGS`` with the expensive steps replaced by a RuntimeError, then prints
#: the process's peak RSS (MB, VmHWM) on stdout.
GUARDED = textwrap.dedent("""
    import sys

    def forbid(owner, name):
        def stop(*args, **kwargs):
            raise RuntimeError(f"work started before the refusal: {name}")
        setattr(owner, name, stop)

    import scipy.ndimage
    from simulator.batch import _lanes
    from simulator.landscape import _correlator, _overlap_bound, _rotation
    from simulator.motion import _trajectory

    forbid(scipy.ndimage, "distance_transform_edt")
    forbid(_rotation.ChipRotator, "_smooth_chip")
    forbid(_rotation.ChipRotator, "__call__")
    forbid(_correlator.Correlator, "__init__")
    forbid(_overlap_bound._Bounds, "__init__")
    forbid(_trajectory, "jitted")
    forbid(_lanes, "_run_chunk")
    from simulator.cli import main
    code = main(sys.argv[1:])
    # VmHWM: this process's own peak (ru_maxrss can carry the forking parent's over exec)
    hwm = [int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmHWM:")][0]
    print(f"peak_rss_mb={hwm / 1024:.0f}")
    sys.exit(code)
""")


@pytest.fixture(scope="module")
def fp1k(tmp_path_factory) -> Path:
    """A 1000 um four-pad (gap 50 um) at 1 um/px: small to read, large to simulate."""
    path = tmp_path_factory.mktemp("pricing") / "fp1k.png"
    from simulator.cli import main

    assert (
        main(
            [
                "pattern",
                "four-pad",
                "--size",
                "1000",
                "--gap",
                "50",
                "--um-per-px",
                "1",
                "-o",
                str(path),
            ]
        )
        == 0
    )
    return path


def guarded(args: list, cwd: Path) -> tuple[int, str, float]:
    """(exit code, stderr, peak RSS in MB) of ``selfalign ARGS`` with the work forbidden."""
    env = os.environ | {
        "PYTHONWARNINGS": "ignore",
        WAIT_ENV: "0",
    }  # every waiting line shown: none may come before the refusal
    out = subprocess.run(
        [sys.executable, "-c", GUARDED, *[str(a) for a in args]],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=cwd,
        env=env,
    )
    rss = [
        float(line.split("=")[1])
        for line in out.stdout.splitlines()
        if line.startswith("peak_rss_mb=")
    ]
    assert rss, out.stdout + out.stderr
    return out.returncode, out.stderr, rss[0]


def _chip(fp: Path) -> list:
    return ["--pattern", fp, "--chip-size", "1000"]


#: name: (arguments after the pattern and chip, the words the one-line refusal holds).
CASES = {
    "simulate greedy: the first box with its transforms": (
        ["simulate", "--start=300,-200,10", "--engine", "fft", "--memory-budget", "64"],
        [
            "the landscape needs about",
            "7 twists x",
            "work space",
            "memory budget is 64 MB",
            "--um-per-px",
            "--memory-budget",
        ],
    ),
    "simulate gradient, free contact lines: the footprint's distance transform": (
        [
            "simulate",
            "--start=300,-200,10",
            "--method",
            "gradient",
            "--meniscus-height",
            "31",
            "--memory-budget",
            "60",
        ],
        [
            "meniscus footprint of the 1,000 x 1,000 um chip",
            "distance transform",
            "memory budget is 60 MB",
            "--resolution",
            "--meniscus-height",
            "--memory-budget",
        ],
    ),
    "simulate gradient, pinned lines: the footprint's K_h blur": (
        [
            "simulate",
            "--start=300,-200,10",
            "--method",
            "gradient",
            "--meniscus-height",
            "31",
            "--pinned",
            "--memory-budget",
            "400",
        ],
        [
            "meniscus footprint of the 1,000 x 1,000 um chip",
            "K_h blur",
            "memory budget is 400 MB",
            "--memory-budget",
        ],
    ),
    "simulate greedy with the meniscus on FFT boxes: the first box and its footprint": (
        [
            "simulate",
            "--start=300,-200,10",
            "--meniscus-height",
            "31",
            "--engine",
            "fft",
            "--memory-budget",
            "200",
        ],
        [
            "the landscape needs about",
            "meniscus footprint",
            "memory budget is 200 MB",
            "--memory-budget",
        ],
    ),
    "simulate greedy, meniscus below a pixel: the proof's whole landscape, a twist at a time": (
        ["simulate", "--start=300,-200,10", "--meniscus-height", "0.5", "--memory-budget", "150"],
        ["the landscape needs about", "(1 twist x ", "memory budget is 150 MB", "--memory-budget"],
    ),
    "simulate overdamped: the whole landscape": (
        ["simulate", "--start=300,-200,10", "--method", "overdamped", "--memory-budget", "1000"],
        ["the landscape needs about", "memory budget is 1,000 MB", "--memory-budget"],
    ),
    "energy with the meniscus: the footprint": (
        ["energy", "--at", "0,0,0", "--meniscus-height", "31", "--dispense", "none"]
        + ["--memory-budget", "80"],
        ["meniscus footprint", "distance transform", "--memory-budget"],
    ),
    "energy with the meniscus: the default footprint state's planes": (
        ["energy", "--at", "0,0,0", "--meniscus-height", "31", "--memory-budget", "200"],
        ["--dispense pattern (the default)", "footprint state's planes", "--dispense none"],
    ),
    "simulate with a droplet below the critical volume: refused before the droplet's warning": (
        [
            "simulate",
            "--start=300,-200,10",
            "--meniscus",
            "--volume",
            "5",
            "--engine",
            "fft",
            "--memory-budget",
            "64",
        ],
        ["meniscus footprint", "memory budget is 64 MB", "--memory-budget"],
    ),
    "montecarlo with a droplet below the critical volume: refused before the droplet's warning": (
        [
            "montecarlo",
            "--random",
            "100",
            "--spread",
            "10,10,1",
            "--volume",
            "5",
            "--memory-budget",
            "1000",
        ],
        ["the landscape needs about", "memory budget is 1,000 MB", "--memory-budget"],
    ),
    "montecarlo: the landscape with its transforms": (
        ["montecarlo", "--random", "100", "--spread", "10,10,1", "--memory-budget", "1000"],
        ["the landscape needs about", "memory budget is 1,000 MB", "--memory-budget"],
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_oversize_run_is_refused_before_any_work(case, fp1k, tmp_path):
    args, needles = CASES[case]
    rc, err, rss = guarded([args[0], *_chip(fp1k), *args[1:]], tmp_path)
    one_line_error(rc, err, "error:", *needles)
    assert rss < REFUSED_RSS_MB, f"{rss:.0f} MB used before refusing"


def test_evaluate_oversize_is_refused_before_its_output_or_any_work(fp1k, tmp_path):
    # A pixel size given (no automatic coarsening): priced before the compile line and the output.
    out = tmp_path / "report"
    rc, err, rss = guarded(
        [
            "evaluate",
            fp1k,
            "--chip-size",
            "1000",
            "--resolution",
            "1",
            "--memory-budget",
            "1000",
            "--out",
            out,
        ],
        tmp_path,
    )
    one_line_error(rc, err, "the landscape needs about", "--memory-budget")
    assert rss < REFUSED_RSS_MB and not out.exists()


def test_sweep_point_over_budget_fails_before_any_work(tmp_path):
    # The point's refusal is its row; the sweep itself goes on (and ends with exit code 0).
    spec = tmp_path / "sweep.toml"
    spec.write_text(
        textwrap.dedent("""
        [scene]
        chip_size_um = 1000
        resolution_um = 1
        memory_budget_mb = 200
        [scene.effects]
        meniscus = true
        [scene.liquid]
        meniscus_height_um = 31
        [design]
        name = "four-pad"
        size = 1000
        gap = 50
        [axes]
        gap = [50]
    """)
    )
    rc, err, rss = guarded(
        ["sweep", spec, "--out", tmp_path / "out", "--workers", "0", "--quiet"], tmp_path
    )
    assert rc == 0, err
    (point,) = (tmp_path / "out" / "points").glob("*.json")
    row = json.loads(point.read_text())["row"]
    assert (
        row["status"] == "error"
        and "the landscape needs about" in row["error"]
        and "--memory-budget" in row["error"]
    ), row
    assert rss < REFUSED_RSS_MB


@pytest.mark.fft
def test_a_build_takes_smaller_chunks_of_twists_before_it_refuses():
    # The work space grows with the twists transformed together (their chip rasters, and one
    # transform pipeline per thread up to one per twist): a budget that holds one twist at a
    # time builds the landscape (the same energies), where eight at a time would not fit.
    from simulator.landscape import build_landscape
    from simulator.landscape._build import _build_bytes, _layout

    sc = Scene.from_inputs(
        LIB / "four_pad_730_50.png", chip_size_um=730, resolution_um=5, dtype="float64"
    )
    lay = _layout(sc, None, (0, 0), None, check_budget=True)
    one, eight = _build_bytes(sc, lay, 1), _build_bytes(sc, lay, 8)
    assert eight > one
    tight = sc.replace(memory_budget_mb=(one + 0.2 * (eight - one)) / 2**20)
    # The same energies up to round-off: a JAX transform of a smaller batch rounds otherwise
    # (bit for bit only on the CPU paths, one twist per transform), and each build is within
    # the noise floor (32 eps(float64) max|E|, the FFT round-off bound) of the exact value.
    a, b = build_landscape(tight), build_landscape(sc)
    np.testing.assert_allclose(a.energy, b.energy, rtol=0, atol=2 * b.noise_floor_J)


def test_the_bound_rotates_the_footprint_once_when_the_pattern_is_the_smaller(monkeypatch):
    # The absolute bound is min(|P|, the footprint's largest mass over the twists): once one
    # twist's mass reaches |P| the others are not rotated (each is a whole chip canvas).
    from simulator.landscape._overlap_bound import _Bounds

    sc = Scene.from_inputs(
        LIB / "four_pad_730_50.png",
        chip_size_um=730,
        resolution_um=5,
        effects=Effects(meniscus=True),
        liquid=Liquid(height_um=20.0),
        dtype="float64",
    )
    b = _Bounds(sc)
    assert b.footprint
    calls = []
    rotate = type(b.rot).__call__
    monkeypatch.setattr(type(b.rot), "__call__", lambda self, t: calls.append(t) or rotate(self, t))
    assert b.absolute_px() == pytest.approx(float(b.pat.sum()) * (1 + 1e-9), rel=1e-12)
    assert len(calls) == 1 and calls[0] == b.twists[np.argmin(np.abs(b.twists))]


def test_the_bounds_keep_the_rotations_that_fit_a_quarter_of_the_budget():
    from simulator.landscape._overlap_bound import _Bounds

    sc = Scene.from_inputs(
        LIB / "four_pad_730_50.png",
        chip_size_um=730,
        resolution_um=5,
        effects=Effects(meniscus=True),
        liquid=Liquid(height_um=20.0),
        dtype="float64",
        memory_budget_mb=40,
    )
    b = _Bounds(sc)
    assert 1 <= b._fine_keep <= 40 * 2**20 / 4 / b._fine_bytes < len(b.twists)
    for j in range(len(b.twists)):
        b.fine(j)
        assert len(b._fine) <= b._fine_keep


# ---------------------------------------------------------------- the waiting lines
def test_wait_threshold(monkeypatch):
    monkeypatch.delenv(WAIT_ENV, raising=False)
    assert wait_threshold_s() == WAIT_S and shows_wait(WAIT_S) and not shows_wait(WAIT_S / 2)
    for text, want in (
        ("0", 0.0),
        ("12.5", 12.5),
        ("soon", WAIT_S),
        ("-1", WAIT_S),
        ("nan", WAIT_S),
    ):
        monkeypatch.setenv(WAIT_ENV, text)
        assert wait_threshold_s() == want, text
    monkeypatch.setenv(WAIT_ENV, "0")
    with quiet_waits():
        assert not shows_wait(1e9)
    assert shows_wait(0.0)


MENISCUS_RUN = [
    "simulate",
    "--pattern",
    LIB / "four_pad_730_50.png",
    "--chip-size",
    "730",
    "--resolution",
    "5",
    "--meniscus-height",
    "20",
    "--dispense",
    "none",  # the stateless path engine's boxes (the footprint state's: tests/test_footprint_path.py)
    "--method",
    "gradient",
    "--start=60,-40,4",
    "--engine",
    "fft",
    "--max-steps",
    "200",
]


def test_simulate_says_what_it_waits_for(monkeypatch, run_cli):
    monkeypatch.setenv(WAIT_ENV, "0")
    rc, out, err = run_cli(MENISCUS_RUN)
    assert rc == 0, err
    lines = err.splitlines()
    assert any(
        line.startswith("meniscus footprint of the 730 x 730 um chip (distance transform of ")
        for line in lines
    ), err
    boxes = [line for line in lines if line.startswith("landscape box ")]
    assert (
        boxes
        and boxes[0].startswith("landscape box 1: 7 twists x ")
        and "poses (transforms of " in boxes[0]
    ), err
    assert all(line.endswith("...") for line in boxes)
    assert "gradient:" in out and "landscape box" not in out  # results on stdout, waits on stderr


def test_quiet_silences_the_waiting_lines(monkeypatch, run_cli):
    monkeypatch.setenv(WAIT_ENV, "0")
    rc, out, err = run_cli([*MENISCUS_RUN, "--quiet"])
    assert rc == 0, err
    assert err == "", err


def test_no_waiting_line_under_the_threshold(monkeypatch, run_cli):
    monkeypatch.setenv(WAIT_ENV, "1e9")
    rc, out, err = run_cli(MENISCUS_RUN)
    assert rc == 0, err
    assert (
        "landscape box" not in err
        and "meniscus footprint" not in err
        and "global minimum" not in err
    )


def test_the_global_minimums_proof_shows_its_progress(monkeypatch, capsys):
    # A scene whose minimum needs the cell bound: a bar over the twists of each level of cells,
    # and a line for each box computed exactly.
    from simulator.landscape import global_minimum

    monkeypatch.setenv(WAIT_ENV, "0")
    sc = Scene.from_inputs(
        LIB / "defect_C_inward.png",
        chip_size_um=200,
        resolution_um=2,
        effects=Effects(meniscus=True),
        liquid=Liquid(volume_nl=0.9, pinned=True),
        dtype="float64",
    )
    assert global_minimum(sc).how == "cell bound"
    err = capsys.readouterr().err
    assert "global minimum: nominal box: 5 twists x 33 x 33 poses" in err
    assert "global minimum: bound over " in err and "twist" in err
    assert "global minimum: cell-bound box: " in err
    with quiet_waits():
        global_minimum(sc)
    assert capsys.readouterr().err == ""


#: Modules a refused run has not imported: JAX (the steppers, 1.8 s), SciPy's FFT (the
#: transforms; pricing needs their sizes only) and scikit-image's outlines (the pattern's
#: smallest feature, measured for the accuracy warning once a run is priced).
NOT_BEFORE_REFUSAL = ("jax", "scipy.fft", "skimage.measure")

#: Refused runs of every command that prices one: (arguments after the pattern and chip,
#: a word of the refusal).
REFUSED_RUNS = {
    "simulate: the first box": (
        ["simulate", "--start=300,-200,10", "--engine", "fft", "--memory-budget", "64"],
        "the landscape needs about",
    ),
    "simulate: the footprint (path engine)": (
        ["simulate", "--start=300,-200,10", "--method", "gradient", "--meniscus-height", "31"]
        + ["--memory-budget", "60"],
        "meniscus footprint",
    ),
    "simulate overdamped: the whole landscape": (
        ["simulate", "--start=300,-200,10", "--method", "overdamped", "--memory-budget", "1000"],
        "the landscape needs about",
    ),
    "montecarlo: the landscape": (
        ["montecarlo", "--random", "100", "--spread", "10,10,1", "--memory-budget", "1000"],
        "the landscape needs about",
    ),
    "montecarlo overdamped: the solver states of its lanes": (
        ["montecarlo", "--random", "100000", "--spread", "10,10,1", "--method", "overdamped"]
        + ["--chunk", "100000", "--resolution", "8", "--memory-budget", "1000"],
        "the solver states of 100,000 dynamics runs at once would need about 1.53 GB but the "
        "memory budget is 1,000 MB; use a smaller --chunk",
    ),
}


@pytest.mark.parametrize("case", list(REFUSED_RUNS))
def test_a_refused_run_has_not_imported_the_engine(case, fp1k, tmp_path):
    """``simulate`` and ``montecarlo`` price their run before they import JAX or SciPy's FFT
    and before they outline the pattern: a refusal costs none of their time or memory."""
    args, needle = REFUSED_RUNS[case]
    script = (
        "import sys\nfrom simulator.cli import main\ncode = main(sys.argv[1:])\n"
        f"print([m for m in {NOT_BEFORE_REFUSAL!r} if m in sys.modules])\nsys.exit(code)\n"
    )
    argv = [args[0], *_chip(fp1k), *args[1:]]
    out = subprocess.run(
        [sys.executable, "-c", script, *[str(a) for a in argv]],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
        env=os.environ | {"PYTHONWARNINGS": "ignore"},
    )
    one_line_error(out.returncode, out.stderr, "error:", needle, "memory budget")
    assert out.stdout.strip() == "[]"


def test_the_transform_sizes_are_scipys_without_importing_it():
    """The correlator's transform lengths (:func:`next_fast_len`, which pricing reads without
    importing SciPy's FFT) are SciPy's: 11-smooth, 5-smooth for real transforms."""
    import scipy.fft

    from simulator.landscape._fftsize import next_fast_len

    for real in (False, True):
        assert [next_fast_len(n, real) for n in range(1, 20_001)] == [
            scipy.fft.next_fast_len(n, real=real) for n in range(1, 20_001)
        ]


def test_memory_figures_read_as_numbers():
    """A refusal's figures: three significant digits below 1,000 of a unit, whole units with
    thousands separators above (a 1,000 MB budget is not '1e+03 MB')."""
    from foundation import fmt_bytes

    mb = 2**20
    assert [fmt_bytes(v * mb) for v in (1000, 999.4, 340, 1023.9)] == [
        "1,000 MB",
        "999 MB",
        "340 MB",
        "1,024 MB",
    ]
    assert fmt_bytes(1.53 * 2**30) == "1.53 GB" and fmt_bytes(12 * 2**10) == "12 kB"
    assert fmt_bytes(float("inf")) == "an unbounded amount of memory"
