"""Bad input and safe outputs (issue 15), one regression test per reproduction: nothing
lost, nothing crashes.

Every bad input gives exit code 2 and exactly one line on stderr with no traceback,
writes nothing, and is refused before memory is allocated. The memory cases run in
one subprocess whose peak resident memory is measured (they must stay near the cost
of importing the package, far below what the requests would take).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import listing, one_line_error, python_m  # noqa: F401  (tests/cli_helpers.py)
from PIL import Image

from foundation import MARKER
from patterns.library import library_path
from simulator.cli import main

SQUARE = str(library_path("square_200"))  # 200 um square pad at 1 um/px
FOUR_PAD = str(library_path("four_pad_730_50"))
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def small_png(tmp_path) -> Path:
    """A 40 um square pad at 2 um/px, copied into the test's directory."""
    p = tmp_path / "pad.png"
    assert main(["pattern", "square", "--size", "40", "--um-per-px", "2", "-o", str(p)]) == 0
    return p


# ======================================================= 1. evaluate --out deletes data
def evaluate_args(pattern, out, *extra):
    return ["evaluate", pattern, "--chip-size", "40", "--out", out, "--quiet", *extra]


def test_evaluate_out_existing_directory_with_user_files_is_kept(small_png, tmp_path, run_cli):
    keep = tmp_path / "results"
    keep.mkdir()
    (keep / "notes.txt").write_text("mine")
    rc, _, err = run_cli(evaluate_args(small_png, keep))
    one_line_error(rc, err, "not empty", "--force")
    rc, _, err = run_cli(evaluate_args(small_png, keep, "--force"))
    one_line_error(rc, err, "did not write")
    assert listing(keep) == ["notes.txt"] and (keep / "notes.txt").read_text() == "mine"
    assert listing(tmp_path) == ["pad.png", "results", "results/notes.txt"]  # no temporaries


def test_evaluate_out_dot_keeps_the_working_directory(small_png, tmp_path, run_cli, monkeypatch):
    monkeypatch.chdir(tmp_path)
    before = listing(tmp_path)
    for out in (".", "..", "./", str(tmp_path)):
        rc, _, err = run_cli(evaluate_args("pad.png", out))
        one_line_error(rc, err, "working directory")
    assert listing(tmp_path) == before


def test_evaluate_out_dotdot_keeps_the_parent_tree(small_png, tmp_path, run_cli, monkeypatch):
    sub = tmp_path / "sub"
    sub.mkdir()
    monkeypatch.chdir(sub)
    rc, _, err = run_cli(evaluate_args(small_png, ".."))
    one_line_error(rc, err, "working directory")
    assert (tmp_path / "pad.png").exists() and sub.is_dir()


def test_evaluate_out_symlink_is_refused(small_png, tmp_path, run_cli):
    target = tmp_path / "real"
    target.mkdir()
    (tmp_path / "link").symlink_to(target)
    rc, _, err = run_cli(evaluate_args(small_png, tmp_path / "link"))
    one_line_error(rc, err, "symbolic link")
    assert (tmp_path / "link").is_symlink() and listing(target) == []


def test_evaluate_out_the_inputs_directory_is_refused(small_png, tmp_path, run_cli):
    rc, _, err = run_cli(evaluate_args(small_png, tmp_path))
    one_line_error(rc, err)
    assert small_png.exists()


def test_evaluate_out_new_directory_then_force_replaces_only_its_own_output(
    small_png, tmp_path, run_cli
):
    out = tmp_path / "ev"
    assert run_cli(evaluate_args(small_png, out))[0] == 0
    marker = json.loads((out / MARKER).read_text())
    assert set(marker["files"]) == {
        "summary.json",
        "report.html",
        "landscape.png",
        "force.png",
        "capture.png",
        "pattern.png",
    }
    first = (out / "summary.json").stat().st_mtime_ns
    rc, _, err = run_cli(evaluate_args(small_png, out))  # exists: refused without --force
    one_line_error(rc, err, "--force")
    assert run_cli(evaluate_args(small_png, out, "--force"))[0] == 0
    assert (out / "summary.json").stat().st_mtime_ns >= first
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "ev",
        "pad.png",
    ]  # the old copy is gone, nothing hidden left
    (out / "extra.txt").write_text("a user's file")
    rc, _, err = run_cli(evaluate_args(small_png, out, "--force"))
    one_line_error(rc, err, "did not write")
    assert (out / "extra.txt").exists()


def test_evaluate_out_existing_empty_directory_is_filled_keeping_its_mode(
    small_png, tmp_path, run_cli
):
    out = tmp_path / "empty"
    out.mkdir()
    out.chmod(0o750)
    assert run_cli(evaluate_args(small_png, out))[0] == 0
    assert (out / "report.html").exists() and (out.stat().st_mode & 0o777) == 0o750


def test_evaluate_out_read_only_empty_directory_is_not_replaced(small_png, tmp_path, run_cli):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        rc, _, err = run_cli(evaluate_args(small_png, ro))
        one_line_error(rc, err, "read-only")
        assert (ro.stat().st_mode & 0o777) == 0o555 and listing(ro) == []
    finally:
        ro.chmod(0o755)


def test_demo_out_refuses_a_directory_of_user_files(tmp_path, run_cli):
    out = tmp_path / "out"
    out.mkdir()
    (out / "thesis.tex").write_text("x")
    rc, _, err = run_cli(["demo", "--out", out, "--force", "--quiet"])
    one_line_error(rc, err, "did not write")
    assert listing(out) == ["thesis.tex"]


# ======================================================= 2. priced before allocation
MEMORY_CASES = {
    "energy_chip_size_1e9": [
        "energy",
        "--pattern",
        FOUR_PAD,
        "--chip-size",
        "1e9",
        "--at",
        "0,0,0",
    ],
    # The library PNG stores 1 um/px: a contradicting --um-per-px needs --override-scale (issue 14).
    "um_per_px_1e-6": [
        "energy",
        "--pattern",
        FOUR_PAD,
        "--chip-size",
        "730",
        "--at",
        "0,0,0",
        "--um-per-px",
        "1e-6",
        "--override-scale",
    ],
    "pattern_square_size_1e9": ["pattern", "square", "--size", "1e9", "-o", "{d}/big.png"],
    "max_steps_1e9_path_buffers": [
        "simulate",
        "--pattern",
        SQUARE,
        "--chip-size",
        "200",
        "--start",
        "10,10,0",
        "--max-steps",
        "1000000000",
    ],
    "montecarlo_random_1e8": [
        "montecarlo",
        "--pattern",
        SQUARE,
        "--chip-size",
        "200",
        "--random",
        "100000000",
        "--spread",
        "10,10,1",
        "--memory-budget",
        "4096",
    ],
    "curve_from_-1e9_to_1e9": [
        "energy",
        "--pattern",
        SQUARE,
        "--chip-size",
        "200",
        "--curve",
        "x",
        "--from=-1e9",
        "--to=1e9",
    ],
    "png_13000_px_rgba": [
        "energy",
        "--pattern",
        "{d}/bomb.png",
        "--um-per-px",
        "1",
        "--chip-size",
        "200",
        "--at",
        "0,0,0",
    ],
    "memory_budget_above_machine": [
        "energy",
        "--pattern",
        SQUARE,
        "--chip-size",
        "200",
        "--at",
        "0,0,0",
        "--memory-budget",
        "1e9",
    ],
    "phys_2_31_px_per_m": [
        "energy",
        "--pattern",
        "{d}/phys.png",
        "--chip-size",
        "200",
        "--at",
        "0,0,0",
    ],
    "chip_size_1e5": ["energy", "--pattern", SQUARE, "--chip-size", "1e5", "--at", "0,0,0"],
    "chip_size_1e300": ["energy", "--pattern", SQUARE, "--chip-size", "1e300", "--at", "0,0,0"],
    "twist_step_1e-300": [
        "energy",
        "--pattern",
        SQUARE,
        "--chip-size",
        "200",
        "--at",
        "0,0,0",
        "--twist-step",
        "1e-300",
    ],
    "max_steps_1e12": [
        "simulate",
        "--pattern",
        SQUARE,
        "--chip-size",
        "200",
        "--start",
        "10,10,0",
        "--max-steps",
        "1000000000000",
    ],
    "resolution_1e-6": [
        "energy",
        "--pattern",
        SQUARE,
        "--chip-size",
        "200",
        "--at",
        "0,0,0",
        "--resolution",
        "1e-6",
    ],
    "montecarlo_twist_step_1e-6": [
        "montecarlo",
        "--pattern",
        SQUARE,
        "--chip-size",
        "200",
        "--twist-step",
        "1e-6",
        "--random",
        "10",
        "--spread",
        "1,1,1",
    ],
    "overdamped_max_steps_1e12": [
        "simulate",
        "--pattern",
        SQUARE,
        "--chip-size",
        "200",
        "--start",
        "10,10,0",
        "--method",
        "overdamped",
        "--max-steps",
        "1000000000000",
    ],
}
#: Knob words each refusal must name (what shrinks the request).
MEMORY_KNOBS = {
    "energy_chip_size_1e9": "coarser scale",
    "um_per_px_1e-6": "coarser scale",
    "pattern_square_size_1e9": "coarser scale",
    "max_steps_1e9_path_buffers": "--max-steps",
    "montecarlo_random_1e8": "fewer starts",
    "curve_from_-1e9_to_1e9": "--from/--to",
    "png_13000_px_rgba": "--max-image-mpx",
    "memory_budget_above_machine": "machine's memory",
    "phys_2_31_px_per_m": "coarser scale",
    # 100 mm on a 200 um pad: 500 times the pattern, refused as a unit slip before it is priced
    "chip_size_1e5": "a chip size in nm? --chip-size takes um: give --chip-size 100",
    "chip_size_1e300": "coarser scale",
    "twist_step_1e-300": "--twist-step",
    "max_steps_1e12": "32-bit",
    "resolution_1e-6": "coarser scale",
    "montecarlo_twist_step_1e-6": "--twist-step",
    "overdamped_max_steps_1e12": "32-bit",
}
RUNNER = textwrap.dedent("""
    import contextlib, io, json, sys, time
    from simulator.cli import main

    def peak_kb():  # VmHWM: this process's peak RSS (ru_maxrss would include the parent's at fork)
        for line in open("/proc/self/status"):
            if line.startswith("VmHWM:"):
                return int(line.split()[1])

    cases, out = json.loads(sys.argv[1]), {}
    for name, args in cases.items():
        err = io.StringIO()
        t0 = time.perf_counter()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            rc = main(args)
        out[name] = {"rc": rc, "err": err.getvalue(), "s": time.perf_counter() - t0,
                     "peak_kb": peak_kb()}
    print(json.dumps(out))
""")


@pytest.fixture(scope="module")
def memory_runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("mem")
    Image.new("RGBA", (13000, 13000), (0, 0, 0, 255)).save(
        d / "bomb.png"
    )  # 0.7 MB on disk, 7.9 GB decoded
    Image.fromarray(np.full((50, 50), 255, np.uint8)).save(
        d / "phys.png", dpi=((2**31 - 1) * 0.0254,) * 2
    )
    cases = {k: [a.replace("{d}", str(d)) for a in v] for k, v in MEMORY_CASES.items()}
    proc = subprocess.run(
        [sys.executable, "-c", RUNNER, json.dumps(cases)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=d,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.splitlines()[-1]), d


# the tests that read memory_runs (one subprocess of every case) run on one xdist worker, which
# runs it once (make test: --dist loadgroup)
@pytest.mark.xdist_group("memory_runs")
@pytest.mark.parametrize("name", list(MEMORY_CASES))
def test_memory_is_priced_before_allocation(memory_runs, name):
    runs, d = memory_runs
    r = runs[name]
    one_line_error(r["rc"], r["err"], MEMORY_KNOBS[name])
    assert listing(d) == ["bomb.png", "phys.png"]  # nothing written


@pytest.mark.xdist_group("memory_runs")
def test_memory_peak_of_all_refusals_stays_small(memory_runs):
    # VmHWM is the peak over the whole process: every refusal above came before any
    # large allocation (the requests range from 8 GB to 1e+290 TB).
    runs, _ = memory_runs
    assert (
        max(r["peak_kb"] for r in runs.values()) < 2**20
    )  # 1 GiB; importing jax etc. is ~0.25 GiB


# ======================================================= 3. one line instead of a traceback
def test_png_selfalign_chunk_nested_json(tmp_path, run_cli):
    from PIL import PngImagePlugin

    info = PngImagePlugin.PngInfo()
    info.add_text("selfalign", "[" * 50000 + "]" * 50000)
    p = tmp_path / "nested.png"
    Image.fromarray(np.full((20, 20), 255, np.uint8)).save(p, pnginfo=info, dpi=(0.0254 * 1e6,) * 2)
    rc, _, err = run_cli(["energy", "--pattern", p, "--chip-size", "10", "--at", "0,0,0"])
    one_line_error(rc, err, "nested too deeply")


def scene_file(tmp_path: Path, body: str) -> Path:
    p = tmp_path / "scene.toml"
    p.write_text(f'pattern = "{SQUARE}"\nchip_size_um = 200\n' + body)
    return p


@pytest.mark.parametrize(
    "name,body,needle",
    [
        ("toml_5000_deep_arrays", "x = " + "[" * 5000 + "]" * 5000 + "\n", "nested too deeply"),
        ("toml_10000_digit_integer", "window_um = " + "9" * 10000 + "\n", "more than 4300 digits"),
        (
            "toml_surface_tension_water",
            '[materials]\nsurface_tension_mN_m = "water"\n',
            "surface_tension_mN_m",
        ),
        ("toml_chip_size_three_numbers", "", "chip_size_um"),
        ("toml_pattern_42", "", "pattern"),
        (
            "toml_allow_repulsive_string_false",
            '[materials]\nallow_repulsive = "false"\n',
            "allow_repulsive",
        ),
        ("toml_effects_twist_no", '[effects]\ntwist = "no"\n', "twist"),
        ("toml_simulate_metod", '[simulate]\nmetod = "gradient"\nstart = [1, 2, 3]\n', "metod"),
        (
            "toml_max_steps_1e12",
            "[simulate]\nmax_steps = 1000000000000\nstart = [1, 2, 3]\n",
            "max_steps",
        ),
    ],
)
def test_toml_scene_errors_are_one_line(tmp_path, run_cli, name, body, needle):
    p = scene_file(tmp_path, body)
    if name == "toml_chip_size_three_numbers":
        p.write_text(f'pattern = "{SQUARE}"\nchip_size_um = [1, 2, 3]\n')
    if name == "toml_pattern_42":
        p.write_text("pattern = 42\nchip_size_um = 200\n")
    rc, _, err = run_cli(["simulate", p, "--start", "1,2,3"])
    one_line_error(rc, err, needle)
    assert listing(tmp_path) == ["scene.toml"]


def test_toml_file_with_25_million_element_array_is_refused_fast(tmp_path, run_cli):
    p = tmp_path / "scene.toml"
    with open(p, "w") as f:
        f.write(f'pattern = "{SQUARE}"\nchip_size_um = 200\nx = [')
        f.write("0," * 25_000_000)
        f.write("]\n")
    rc, _, err = run_cli(["energy", p, "--at", "0,0,0"])
    one_line_error(rc, err, "at most 1,048,576 bytes")  # refused on its size, before parsing


def in_thread(fn):
    """fn() in a thread; a call that blocks (on a FIFO) fails the test instead of hanging it."""
    import threading

    box = []
    t = threading.Thread(target=lambda: box.append(fn()), daemon=True)
    t.start()
    t.join(timeout=120)
    if t.is_alive():
        pytest.fail("blocked reading a FIFO")
    return box[0]


def test_fifo_as_scene_file_does_not_hang(tmp_path, run_cli):
    fifo = tmp_path / "scene.toml"
    os.mkfifo(fifo)
    rc, _, err = in_thread(lambda: run_cli(["energy", fifo, "--at", "0,0,0"]))
    one_line_error(rc, err, "FIFO")


def test_fifo_as_pattern_does_not_hang(tmp_path, run_cli):
    fifo = tmp_path / "p.png"
    os.mkfifo(fifo)
    rc, _, err = in_thread(
        lambda: run_cli(["energy", "--pattern", fifo, "--chip-size", "10", "--at", "0,0,0"])
    )
    one_line_error(rc, err, "FIFO")


@pytest.mark.fft
def test_evaluate_1x1_px_pattern(tmp_path, run_cli):
    p = tmp_path / "one.png"
    Image.fromarray(np.array([[255]], np.uint8)).save(p, dpi=(0.0254 * 1e6,) * 2)  # 1 um/px
    rc, out, err = run_cli(["evaluate", p, "--out", tmp_path / "ev", "--quiet"])
    # the default chip (the pattern's bounding box) is 1 px: refused as a chip under 3 px
    # (issue 39), not a crash; at a third of a micrometre per pixel it runs
    one_line_error(rc, err, "spans 1 px at 1 um/px", "--resolution")
    assert not (tmp_path / "ev").exists()
    rc, out, err = run_cli(
        ["evaluate", p, "--out", tmp_path / "ev", "--quiet", "--resolution", "0.25"]
    )
    assert rc == 0, err
    summary = json.loads((tmp_path / "ev" / "summary.json").read_text())
    # float32: within the noise floor, 32 eps(float32) max|E| (the FFT round-off bound), and
    # max|E| is this overlap's energy (abs=1e-6 um^2, 8 eps of 1 um^2, was one path's luck)
    assert summary["global_minimum"]["overlap_um2"] == pytest.approx(
        1.0, rel=32 * float(np.finfo(np.float32).eps)
    )
    assert summary["settings"]["chip_um"] == [1.0, 1.0]


# ---------------------------------------------------------------- full disk
FULL_DISK = {
    "evaluate": [
        "evaluate",
        SQUARE,
        "--chip-size",
        "200",
        "--out",
        "ev",
        "--quiet",
        "--resolution",
        "4",
    ],
    "gif": [
        "simulate",
        "--pattern",
        SQUARE,
        "--chip-size",
        "200",
        "--start",
        "20,10,0",
        "--gif",
        "t.gif",
        "--quiet",
    ],
    "plot": [
        "simulate",
        "--pattern",
        SQUARE,
        "--chip-size",
        "200",
        "--start",
        "20,10,0",
        "--plot",
        "t.png",
        "--quiet",
    ],
    "csv": [
        "montecarlo",
        "--pattern",
        SQUARE,
        "--chip-size",
        "200",
        "--grid=-40:40:2,-40:40:2",
        "--csv",
        "m.csv",
        "--quiet",
    ],
}


@pytest.mark.parametrize("name", list(FULL_DISK))
def test_full_disk_during_output(tmp_path, name):
    # A file-size limit of 4 kB makes every write past it fail in the kernel (EFBIG), as a
    # full disk does (ENOSPC): same path through the code, no special filesystem needed.
    code = (
        "import resource, signal, sys; signal.signal(signal.SIGXFSZ, signal.SIG_IGN); "
        "resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096)); "
        "from simulator.cli import main; sys.exit(main(sys.argv[1:]))"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, *FULL_DISK[name]],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=300,
    )
    one_line_error(proc.returncode, proc.stderr, "cannot write", "no partial output")
    assert listing(tmp_path) == []  # no partial file, no temporary


def test_stdout_to_a_full_device():
    for args in (
        ["pattern", "--list"],
        ["energy", "--pattern", SQUARE, "--chip-size", "200", "--at", "0,0,0"],
    ):
        with open("/dev/full", "w") as full:
            proc = subprocess.run(
                [sys.executable, "-m", "simulator.cli", *args],
                stdout=full,
                stderr=subprocess.PIPE,
                text=True,
                timeout=120,
            )
        one_line_error(proc.returncode, proc.stderr, "standard output", "No space left")


def test_unexpected_failure_is_one_line_with_the_traceback_saved(monkeypatch, capsys):
    import simulator.commands.energy as energy

    def boom(args):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(energy, "run", boom)
    monkeypatch.delenv("SELFALIGN_DEBUG", raising=False)
    rc = main(["energy", "--pattern", SQUARE, "--chip-size", "200", "--at", "0,0,0"])
    err = capsys.readouterr().err
    assert (
        rc == 1
        and err.count("\n") == 1
        and "internal error: ZeroDivisionError: a bug" in err
        and "SELFALIGN_DEBUG=1" in err
    )
    saved = Path(err.split("traceback in ")[1].split(",")[0])
    assert "Traceback" in saved.read_text() and "boom" in saved.read_text()
    saved.unlink()
    monkeypatch.setenv("SELFALIGN_DEBUG", "1")
    with pytest.raises(ZeroDivisionError):
        main(["energy", "--pattern", SQUARE, "--chip-size", "200", "--at", "0,0,0"])


def test_library_warning_is_one_line(monkeypatch, capsys):
    import warnings

    import simulator.commands.energy as energy

    def warn(args):
        warnings.warn("something\nover two lines", UserWarning, stacklevel=1)
        return 0

    monkeypatch.setattr(energy, "run", warn)
    assert main(["energy", "--at", "0,0,0"]) == 0
    assert capsys.readouterr().err == "selfalign: warning: something over two lines\n"


# ======================================================= 4. strict scenes (in Python too)
def test_scene_from_toml_in_python_refuses_string_booleans(tmp_path):
    from foundation import InputError
    from simulator.scene import Scene

    with pytest.raises(InputError, match="allow_repulsive"):
        Scene.from_toml(scene_file(tmp_path, '[materials]\nallow_repulsive = "false"\n'))
    with pytest.raises(InputError, match="twist"):
        Scene.from_toml(scene_file(tmp_path, '[effects]\ntwist = "no"\n'))


def test_python_api_refuses_string_booleans():
    from foundation import InputError
    from simulator.physics import Materials
    from simulator.scene import Effects

    with pytest.raises(InputError, match="true or false"):
        Materials(allow_repulsive="false")  # pyright: ignore[reportArgumentType] - the test's point
    with pytest.raises(InputError, match="true or false"):
        Effects(twist="no")  # pyright: ignore[reportArgumentType] - the test's point


# ======================================================= 5. finite outputs
def test_overdamped_volume_1e300_writes_no_nan(tmp_path, run_cli):
    out = tmp_path / "v.json"
    rc, _, err = run_cli(
        [
            "simulate",
            "--pattern",
            SQUARE,
            "--chip-size",
            "200",
            "--start",
            "10,10,0",
            "--method",
            "overdamped",
            "--volume",
            "1e-300",
            "--json",
            out,
            "--quiet",
        ]
    )
    one_line_error(rc, err, "--volume", "thinner than")
    assert not out.exists()


def test_equal_angles_with_allow_repulsive_print_no_nan(tmp_path, run_cli):
    args = [
        "--chip-size",
        "200",
        "--pad-angle",
        "50",
        "--substrate-angle",
        "50",
        "--allow-repulsive",
    ]
    rc, out, err = run_cli(["energy", "--pattern", SQUARE, "--at", "0,0,0", *args])
    one_line_error(rc, err, "no wettability contrast")
    assert "nan" not in out
    rc, _, err = run_cli(["evaluate", SQUARE, "--out", tmp_path / "ev", "--quiet", *args])
    one_line_error(rc, err, "no wettability contrast")
    assert listing(tmp_path) == []


def test_non_finite_result_is_refused_before_writing(tmp_path):
    from foundation import InputError
    from simulator.commands._outputs import write_json

    with pytest.raises(InputError, match=r"a\.b\[1\] is nan"):
        write_json(tmp_path / "x.json", {"a": {"b": [1.0, float("nan")]}})
    assert listing(tmp_path) == []


# ======================================================= 7. unsafe output targets
def test_json_onto_a_device_node_keeps_the_node(run_cli):
    rc, _, err = run_cli(
        [
            "energy",
            "--pattern",
            SQUARE,
            "--chip-size",
            "200",
            "--at",
            "0,0,0",
            "--json",
            "/dev/null",
        ]
    )
    one_line_error(rc, err, "not a regular file")
    assert Path("/dev/null").is_char_device()


def test_json_and_csv_onto_the_input_pattern(tmp_path, run_cli):
    pat = tmp_path / "pad.png"
    pat.write_bytes(Path(SQUARE).read_bytes())
    before = pat.read_bytes()
    for args in (
        ["energy", "--pattern", pat, "--chip-size", "200", "--at", "0,0,0", "--json", pat],
        ["montecarlo", "--pattern", pat, "--chip-size", "200", "--grid", "0,0", "--csv", pat],
        ["simulate", "--pattern", pat, "--chip-size", "200", "--start", "1,1,0", "--plot", pat],
    ):
        rc, _, err = run_cli(args)
        one_line_error(rc, err, "is an input")
    scene = tmp_path / "s.toml"
    scene.write_text('pattern = "pad.png"\nchip_size_um = 200\n')
    rc, _, err = run_cli(["energy", scene, "--at", "0,0,0", "--json", tmp_path / "pad.png"])
    one_line_error(rc, err, "is an input")
    assert pat.read_bytes() == before and listing(tmp_path) == ["pad.png", "s.toml"]


def test_json_onto_a_symlink_keeps_the_link(tmp_path, run_cli):
    target = tmp_path / "t.json"
    target.write_text("{}")
    (tmp_path / "l.json").symlink_to(target)
    rc, _, err = run_cli(
        [
            "energy",
            "--pattern",
            SQUARE,
            "--chip-size",
            "200",
            "--at",
            "0,0,0",
            "--json",
            tmp_path / "l.json",
        ]
    )
    one_line_error(rc, err, "symbolic link")
    assert (tmp_path / "l.json").is_symlink() and target.read_text() == "{}"


def held_run(args: list[str], point: str, cwd: Path, env: dict | None = None) -> subprocess.Popen:
    """Start the CLI with ``SELFALIGN_HOLD_AT=point`` and return once it holds there.

    The process announces the hold on stderr and waits for a signal (foundation/_hold.py),
    so the test signals at a known stage of the run, however fast the machine is.
    """
    env = (env or os.environ) | {"SELFALIGN_HOLD_AT": point}
    proc = subprocess.Popen(
        python_m("simulator.cli", *args),
        cwd=cwd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert proc.stderr is not None
    seen = []
    for (
        line
    ) in proc.stderr:  # blocks until the hold line (or the end of a run that never got there)
        seen.append(line)
        if f"selfalign: holding at {point}" in line:  # after a progress bar's carriage returns
            return proc
    proc.wait(timeout=60)
    pytest.fail(
        f"the run ended (exit {proc.returncode}) before holding at {point}: {''.join(seen)[-2000:]}"
    )


@pytest.mark.parametrize(
    "name,args,point,sig",
    [
        (
            "evaluate",
            ["evaluate", FOUR_PAD, "--chip-size", "730", "--out", "ev", "--resolution", "2"],
            "output",
            signal.SIGTERM,
        ),
        (
            "evaluate",
            ["evaluate", FOUR_PAD, "--chip-size", "730", "--out", "ev", "--resolution", "2"],
            "output",
            signal.SIGINT,
        ),
        (
            "montecarlo",
            [
                "montecarlo",
                "--pattern",
                FOUR_PAD,
                "--chip-size",
                "730",
                "--resolution",
                "4",
                "--random",
                "20000",
                "--spread",
                "200,200,5",
                "--json",
                "mc.json",
                "--csv",
                "mc.csv",
            ],
            "batch",
            signal.SIGTERM,
        ),
        (
            "montecarlo",
            [
                "montecarlo",
                "--pattern",
                FOUR_PAD,
                "--chip-size",
                "730",
                "--resolution",
                "4",
                "--random",
                "20000",
                "--spread",
                "200,200,5",
                "--json",
                "mc.json",
                "--csv",
                "mc.csv",
            ],
            "batch",
            signal.SIGINT,
        ),
    ],
)
def test_sigterm_leaves_no_temporaries(tmp_path, name, args, point, sig):
    # The run holds where its work is under way (evaluate: its temporary output directory
    # exists; montecarlo: the batch has run its first chunk); the signal arrives there.
    # SIGTERM removes the temporaries and ends at once; Ctrl-C unwinds through them.
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    proc = held_run(args, point, run_dir)
    if point == "output":
        assert any(p.name.startswith(".ev.") for p in run_dir.iterdir())  # the temporary exists now
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == (143 if sig == signal.SIGTERM else 130), err[-2000:]
    lines = [
        x for x in err.replace("\r", "\n").splitlines() if x.strip()
    ]  # a progress bar may close first
    assert lines[-1] == (
        "selfalign: terminated (no partial output was kept)"
        if sig == signal.SIGTERM
        else "selfalign: interrupted (no partial output was kept)"
    ), err[-2000:]
    assert "Traceback" not in err and "Error" not in err
    assert listing(run_dir) == []


def test_sigterm_while_starting_up_is_one_line(tmp_path):
    # A signal that arrives before the command's modules are imported: the handler is
    # already installed, so the exit is 143 with one line and nothing written.
    proc = held_run(
        ["energy", "--pattern", SQUARE, "--chip-size", "200", "--at", "0,0,0"], "startup", tmp_path
    )
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert err.strip().splitlines() == ["selfalign: terminated (no partial output was kept)"]
    assert listing(tmp_path) == []
