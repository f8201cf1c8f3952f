"""Issue 36, round 4: inputs that crashed or were refused without naming themselves, the Python
API's argument checks, messages in the command line's own spelling, all-or-nothing outputs on a
full disk, and outputs that never replace a file the user did not ask to replace."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import listing, one_line_error  # tests/cli_helpers.py
from ezdxf import filemanagement

from foundation import InputError

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("reliability_round4")

ROOT = Path(__file__).resolve().parents[1]
SEARCH_EXAMPLE = ROOT / "examples" / "design_fourpad_gap.toml"


# ------------------------------------------------------------------ item 2: crashes
def _search_file(tmp_path: Path, objective: str) -> Path:
    text = SEARCH_EXAMPLE.read_text()
    assert 'maximize = "gap_um"' in text
    p = tmp_path / "search.toml"
    p.write_text(text.replace('maximize = "gap_um"', f'maximize = "{objective}"'))
    return p


@pytest.mark.parametrize(
    "objective, needle",
    [
        ("gap_um + " + "9" * 400, "is not a finite number"),  # OverflowError in math.isfinite
        ("-" * 490 + "gap_um", "nests more than 100 levels deep"),  # named neither file nor key
    ],
)
def test_search_objective_refusals_name_the_file_and_the_key(tmp_path, run_cli, objective, needle):
    spec = _search_file(tmp_path, objective)
    out = tmp_path / "out"
    rc, _, err = run_cli(["design", spec, "--out", out])
    one_line_error(rc, err, f"{spec}: [search] maximize", needle)
    assert not out.exists()


def test_search_objective_nesting_counts_the_tree_not_the_parentheses(tmp_path):
    from simulator.design import load_search

    spec = _search_file(tmp_path, "(" * 120 + "gap_um" + ")" * 120 + " + " + "-" * 90 + "1")
    assert load_search(spec).objectives[0].expression.columns == ("gap_um",)


def test_search_constraint_with_a_huge_integer_names_its_index(tmp_path):
    from simulator.design import load_search

    text = SEARCH_EXAMPLE.read_text().replace(
        '"volume_nl >= critical_volume_nl"', '"volume_nl >= ' + "1" * 400 + '"'
    )
    spec = tmp_path / "s.toml"
    spec.write_text(text)
    with pytest.raises(InputError, match=r"\[search\] constraints\[1\]: .*not a finite number"):
        load_search(spec)


def _dxf_with_scaled_insert(tmp_path: Path, xscale: str) -> Path:
    """A DXF whose model space inserts block PAD (a 10 um square) with the x-scale ``xscale``
    as written in the file (ezdxf itself would never write a zero scale)."""
    doc = filemanagement.new("R2010")
    doc.header["$INSUNITS"] = 13
    pad = doc.blocks.new("PAD")
    pad.add_lwpolyline([(0, 0), (10, 0), (10, 10), (0, 10)], close=True, dxfattribs={"layer": "0"})
    doc.layers.add("PADS")
    doc.modelspace().add_blockref("PAD", (0, 0), dxfattribs={"layer": "PADS", "xscale": 2})
    good = tmp_path / "good.dxf"
    doc.saveas(good)
    text = good.read_text()
    assert text.count(" 41\n2.0\n") == 1
    p = tmp_path / f"scale_{xscale}.dxf"
    p.write_text(text.replace(" 41\n2.0\n", f" 41\n{xscale}\n"))
    return p


@pytest.mark.parametrize("xscale", ["0.0", "1e-320", "nan"])
def test_dxf_insert_with_a_degenerate_scale_is_one_line(tmp_path, run_cli, xscale):
    p = _dxf_with_scaled_insert(tmp_path, xscale)
    rc, out, err = run_cli(
        ["energy", "--pattern", p, "--chip-size", "10", "--resolution", "1", "--at", "0,0,0"]
    )
    one_line_error(rc, err, f"{p}: modelspace", "block PAD", "non-zero scale")
    assert out == ""


def test_dxf_insert_with_a_normal_scale_still_reads(tmp_path):
    from patterns.layout import read_layout

    p = _dxf_with_scaled_insert(tmp_path, "3.0")
    assert read_layout(p).geometry("PADS").area == pytest.approx(300)


# ------------------------------------------------------------------ item 3: the Python API's checks
@pytest.fixture(scope="module")
def small_scene():
    from patterns.geometry import mask_from_geometry, square
    from simulator.scene import Scene

    return Scene(
        pattern=mask_from_geometry(square(100), 5), chip=mask_from_geometry(square(100), 5)
    )


@pytest.mark.parametrize(
    "kwargs, needle",
    [
        ({"twists": [math.nan]}, "twists must be a non-empty list of finite twists"),
        ({"twists": [math.inf, 0.0]}, "twists must be a non-empty list of finite twists"),
        ({"twists": [[1.0, 2.0]]}, "twists must be a non-empty list of finite twists"),
        ({"half_px": -5}, "half_px must be a whole number of pixels >= 0"),
        ({"half_px": 2.5}, "half_px must be a whole number of pixels >= 0"),
        ({"center_px": (math.nan, 0)}, "center_px must be two finite numbers"),
        ({"center_px": (1, 2, 3)}, "center_px must be two finite numbers"),
    ],
)
def test_build_landscape_refuses_bad_arguments_with_input_error(small_scene, kwargs, needle):
    from simulator.landscape import build_landscape

    with pytest.raises(InputError, match=needle):
        build_landscape(small_scene, **kwargs)


def test_build_landscape_still_takes_whole_numbers_of_any_type(small_scene):
    from simulator.landscape import build_landscape

    ls = build_landscape(
        small_scene,
        twists=[0.0],
        center_px=(np.int64(1), 2.0),  # pyright: ignore[reportArgumentType] - the test's point
        half_px=np.int64(3),  # pyright: ignore[reportArgumentType] - the test's point
    )
    assert ls.energy.shape == (1, 7, 7)
    one = build_landscape(small_scene, twists=[0.0], half_px=0)
    assert one.energy.shape == (1, 1, 1)


@pytest.mark.parametrize("size", [(1, 2, 3), (100,), [[1, 2]], True, "100x50", (100, None)])
def test_scene_chip_size_of_the_wrong_shape_is_an_input_error(size):
    from patterns.geometry import mask_from_geometry, square
    from simulator.scene import Scene

    with pytest.raises(InputError, match="chip"):
        Scene.from_inputs(pattern=mask_from_geometry(square(100), 5), chip_size_um=size)


def test_scene_chip_size_of_one_or_two_numbers_still_makes_the_chip():
    from patterns.geometry import mask_from_geometry, square
    from simulator.scene import Scene

    pattern = mask_from_geometry(square(100), 5)
    assert Scene.from_inputs(pattern=pattern, chip_size_um=50).chip.area_um2 == pytest.approx(2500)
    # an array where the annotation says numbers: the test's point
    rect = Scene.from_inputs(pattern=pattern, chip_size_um=np.array([100, 50.0])).chip
    assert rect.area_um2 == pytest.approx(5000)


@pytest.mark.parametrize("data", [np.full((4, 4), 0.5 + 0.5j), [[0.5 + 0j, 1.0]]])
def test_mask_refuses_complex_values(data, recwarn):
    from patterns.geometry import Mask

    with pytest.raises(InputError, match="real-valued image, got complex values"):
        Mask(data, 1.0)
    assert not [w for w in recwarn if "ComplexWarning" in str(w.category)]


def test_mask_refuses_text_and_takes_real_numbers():
    from patterns.geometry import Mask

    with pytest.raises(InputError, match="image of numbers"):
        Mask(np.array([["a", "b"]]), 1.0)
    assert Mask(np.array([[0, 1]], dtype=np.uint8), 2.0).area_um2 == 4.0


# ------------------------------------------------------------------ item 4: messages
SQUARE_ARGS = ["--chip-size", "100", "--resolution", "5", "--at", "0,0,0"]


def _square_png(tmp_path: Path) -> Path:
    from patterns import write_mask
    from patterns.geometry import mask_from_geometry, square

    return write_mask(tmp_path / "square.png", mask_from_geometry(square(100), 5))


def test_repulsive_refusal_names_the_command_line_flag(tmp_path, run_cli):
    png = _square_png(tmp_path)
    rc, _, err = run_cli(
        ["energy", "--pattern", png, *SQUARE_ARGS, "--pad-angle", "70", "--substrate-angle", "40"]
    )
    one_line_error(rc, err, "Delta_gamma", "pass --allow-repulsive to study")
    assert "allow_repulsive" not in err


def test_repulsive_refusal_from_a_scene_file_names_its_key_too(tmp_path, run_cli):
    png = _square_png(tmp_path)
    scene = tmp_path / "scene.toml"
    scene.write_text("[materials]\npad_angle_deg = 70\nsubstrate_angle_deg = 40\n")
    rc, _, err = run_cli(["energy", scene, "--pattern", png, *SQUARE_ARGS])
    one_line_error(rc, err, "pass --allow-repulsive", "allow_repulsive = true under [materials]")
    assert "allow_repulsive=True" not in err
    rc, out, err = run_cli(["energy", scene, "--pattern", png, *SQUARE_ARGS, "--allow-repulsive"])
    assert rc == 0, err


def test_simulate_help_says_the_path_engine_covers_free_contact_lines(tmp_path, run_cli):
    rc, out, _ = run_cli(["simulate", "--help"])
    assert rc == 0
    text = " ".join(out.split())
    assert "no free contact lines" not in text
    assert "free contact lines' footprint" in text and "not the K_h-blurred meniscus" in text
    # ... as the engine itself says: a free-contact-line scene is covered, the K_h one is not.
    from simulator.landscape import path_engine_supported
    from simulator.scene import Scene

    base = {"pattern": str(_square_png(tmp_path)), "chip_size_um": 100, "resolution_um": 5}
    wet = {"effects": {"meniscus": True}, "liquid": {"volume_nl": 0.2}}  # 20 um high: 4 px
    free = Scene.from_dict(base | wet)
    assert free.wall_profile is not None and path_engine_supported(free) == (True, "")
    pinned = Scene.from_dict(base | wet | {"liquid": {"volume_nl": 0.2, "pinned": True}})
    assert not path_engine_supported(pinned)[0]  # the K_h-blurred chip


# ------------------------------------------------------------------ item 5: all or nothing on a full disk
SQUARE_200 = str(ROOT / "patterns" / "library" / "square_200.png")  # 200 um square at 1 um/px
#: A file-size limit the small outputs fit under and the GIF (about 90 kB) does not: every
#: write past it fails in the kernel (EFBIG), as on a full disk (ENOSPC), as in
#: tests/test_bad_input_and_safe_outputs.py::test_full_disk_during_output.
LIMITED = (
    "import resource, signal, sys; signal.signal(signal.SIGXFSZ, signal.SIG_IGN); "
    "resource.setrlimit(resource.RLIMIT_FSIZE, (65536, 65536)); "
    "from simulator.cli import main; sys.exit(main(sys.argv[1:]))"
)


def test_simulate_outputs_are_all_or_nothing_on_a_full_disk(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            "-c",
            LIMITED,
            "simulate",
            "--pattern",
            SQUARE_200,
            "--chip-size",
            "200",
            "--start",
            "20,10,0",
            "--json",
            "a.json",
            "--csv",
            "a.csv",
            "--plot",
            "a.png",
            "--gif",
            "a.gif",
            "--quiet",
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=300,
    )
    one_line_error(proc.returncode, proc.stderr, "cannot write a.gif", "no partial output was kept")
    assert "wrote" not in proc.stdout  # nothing announced ...
    assert listing(tmp_path) == []  # ... and nothing kept: not the JSON, CSV or plot written before


def test_energy_outputs_are_all_or_nothing(tmp_path, run_cli, monkeypatch):
    import errno

    import simulator.commands.energy as energy

    def full(path, *args):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(energy, "_write_csv", full)  # the CSV, written after the JSON, fails
    monkeypatch.chdir(tmp_path)
    rc, out, err = run_cli(
        ["energy", "--pattern", SQUARE_200, "--chip-size", "200", "--at", "0,0,0"]
        + ["--json", "e.json", "--csv", "e.csv"]
    )
    one_line_error(rc, err, "cannot write e.csv", "no partial output was kept")
    assert "wrote" not in out and listing(tmp_path) == []


# ------------------------------------------------------------------ item 6: no silent overwrites
def test_pattern_refuses_an_existing_output_unless_forced(tmp_path, run_cli):
    for name in ("s.png", "s.gds"):
        out = tmp_path / name
        out.write_bytes(b"the user's file")
        args = ["pattern", "square", "--size", "20", "-o", out]
        rc, _, err = run_cli(args)
        one_line_error(rc, err, f"-o {out}: exists", "pass --force to replace it")
        assert out.read_bytes() == b"the user's file"
        rc, stdout, err = run_cli([*args, "--force"])
        assert rc == 0 and stdout.startswith(f"wrote {out}"), err
        assert out.read_bytes() != b"the user's file"
    assert listing(tmp_path) == ["s.gds", "s.png"]


def test_simulate_refuses_an_existing_gif_before_any_work(tmp_path, run_cli, monkeypatch):
    import simulator.motion

    def no_run(*args, **kwargs):
        raise AssertionError("the run started before the output was checked")

    monkeypatch.setattr(simulator.motion, "simulate", no_run)
    gif = tmp_path / "a.gif"
    gif.write_bytes(b"GIF89a mine")
    args = ["simulate", "--pattern", SQUARE_200, "--chip-size", "200", "--start", "20,10,0"]
    rc, out, err = run_cli([*args, "--json", tmp_path / "a.json", "--gif", gif])
    one_line_error(rc, err, f"--gif {gif}: exists", "--force")
    assert out == "" and gif.read_bytes() == b"GIF89a mine" and listing(tmp_path) == ["a.gif"]


@pytest.mark.parametrize(
    "args",
    [
        ["energy", "--pattern", SQUARE_200, "--chip-size", "200", "--at", "0,0,0", "--csv"],
        ["montecarlo", "--pattern", SQUARE_200, "--chip-size", "200", "--grid", "0,0", "--json"],
        ["liquid", "height", "--volume", "1", "--chip-size", "200", "--json"],
    ],
)
def test_every_file_output_refuses_an_existing_file_unless_forced(tmp_path, run_cli, args):
    out = tmp_path / "old.txt"
    out.write_text("mine")
    rc, _, err = run_cli([*args, out])
    one_line_error(rc, err, f"{out}: exists", "--force")
    assert out.read_text() == "mine"
    rc, _, err = run_cli([*args, out, "--force", *(["--quiet"] if args[0] == "montecarlo" else [])])
    assert rc == 0, err
    assert out.read_text() != "mine"


def test_force_never_replaces_an_input_or_a_link(tmp_path, run_cli):
    pat = tmp_path / "pad.png"
    pat.write_bytes(Path(SQUARE_200).read_bytes())
    args = ["energy", "--pattern", pat, "--chip-size", "200", "--at", "0,0,0", "--force"]
    rc, _, err = run_cli([*args, "--json", pat])
    one_line_error(rc, err, "is an input")
    (tmp_path / "l.json").symlink_to(tmp_path / "t.json")
    rc, _, err = run_cli([*args, "--json", tmp_path / "l.json"])
    one_line_error(rc, err, "symbolic link")
    assert pat.read_bytes() == Path(SQUARE_200).read_bytes()


def test_a_local_cluster_starts_while_port_8787_is_taken():
    # The scheduler's HTTP server took port 8787 unless told otherwise: a second cluster on the
    # machine (two sweeps, the suite's parallel workers) then warned that the port was taken,
    # and the suite turns warnings into errors. It binds a free loopback port now.
    import socket

    from simulator.sweep._cluster import dask_client

    holder = socket.socket()
    try:
        holder.bind(("127.0.0.1", 8787))
        holder.listen()
    except OSError:  # taken already: the case under test all the same
        pass
    try:
        with dask_client(1, None) as client:
            assert list(client.run(lambda: 1).values()) == [1]
    finally:
        holder.close()
