"""`selfalign pattern`: every design writes a scaled PNG; bad input is one line, exit 2, no file."""

import re
import struct

import pytest
from PIL import Image

from patterns import read_mask
from patterns.geometry import DESIGNS, build

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("pattern_cli")

DESIGN_ARGS = {
    "square": (["--size", "200"], {"size": 200}),
    "rectangle": (["--width", "120", "--height", "50.5"], {"width": 120, "height": 50.5}),
    "circle": (["--diameter", "90"], {"diameter": 90}),
    "four-pad": (["--size", "200", "--gap", "20"], {"size": 200, "gap": 20}),
    "defect": (
        [
            "--size",
            "200",
            "--kind",
            "inward",
            "--position",
            "corner",
            "--edge",
            "top",
            "--height",
            "30",
            "--width",
            "60",
        ],
        {
            "size": 200,
            "kind": "inward",
            "position": "corner",
            "edge": "top",
            "height": 30,
            "width": 60,
        },
    ),
    "constant-jagged": (["--size", "200", "--amplitude", "3.2"], {"size": 200, "amplitude": 3.2}),
    "random-jagged": (
        ["--size", "200", "--sigma", "4", "--seed", "5"],
        {"size": 200, "sigma": 4, "seed": 5},
    ),
    "polygon": (["--points", "0,0;60,0;60,40;-20,50"], {"points": "0,0;60,0;60,40;-20,50"}),
}


def test_every_design_is_covered():
    assert set(DESIGN_ARGS) == set(DESIGNS)


@pytest.mark.parametrize("design", list(DESIGN_ARGS))
@pytest.mark.parametrize("um_per_px", ["1", "0.5"])
def test_each_design_writes_a_scaled_png(tmp_path, run_cli, design, um_per_px):
    flags, params = DESIGN_ARGS[design]
    out = tmp_path / f"{design}.png"
    rc, stdout, err = run_cli(["pattern", design, *flags, "--um-per-px", um_per_px, "-o", str(out)])
    assert (rc, err) == (0, "")
    mask = read_mask(out)
    assert mask.um_per_px == float(um_per_px)
    exact = build(design, **params).area
    assert mask.area_um2 == pytest.approx(exact, rel=1e-5)
    assert mask.params["design"] == design and mask.params["area_um2"] == pytest.approx(exact)
    assert f"wrote {out}" in stdout and f"at {um_per_px} um/px" in stdout and "um^2" in stdout
    assert [p.name for p in tmp_path.iterdir()] == [out.name]  # no temporary left behind


def test_four_pad_example(tmp_path, run_cli, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, stdout, err = run_cli(
        [
            "pattern",
            "four-pad",
            "--size",
            "730",
            "--gap",
            "50",
            "--um-per-px",
            "1",
            "-o",
            "fourpad.png",
        ]
    )
    assert rc == 0 and err == ""
    with Image.open("fourpad.png") as im:
        assert im.mode == "I;16"
        assert round(im.info["dpi"][0] / 0.0254) == 1_000_000  # pHYs: 1e6 px/m = 1 um/px
    data = (tmp_path / "fourpad.png").read_bytes()
    i = data.index(b"pHYs")
    assert struct.unpack(">IIB", data[i + 4 : i + 13]) == (1_000_000, 1_000_000, 1)
    mask = read_mask("fourpad.png")
    assert mask.area_um2 == pytest.approx(4 * 340**2, rel=1e-3)
    assert mask.area_um2 == 4 * 340**2  # pixel-aligned edges: exact
    assert mask.shape == (750, 750)  # 730 um + the default 10 um margin on each side
    assert "750 x 750 px" in stdout and "462400 um^2" in stdout


def test_margin_sets_the_canvas(tmp_path, run_cli):
    out = tmp_path / "sq.png"
    rc, _, _ = run_cli(["pattern", "square", "--size", "100", "--margin", "0", "-o", str(out)])
    assert rc == 0 and read_mask(out).shape == (100, 100)


def test_defaults_and_provenance(tmp_path, run_cli):
    out = tmp_path / "cj.png"
    assert run_cli(["pattern", "constant-jagged", "--amplitude", "5", "-o", str(out)])[0] == 0
    params = read_mask(out).params
    assert params["parameters"]["size"] == {"value": 200.0, "unit": "um"}
    assert params["parameters"]["pitch"] == {"value": 10.0, "unit": "um"}
    assert params["um_per_px"] == 1.0 and params["margin_um"] == 10.0


def test_list_describes_every_design_with_units(run_cli):
    rc, out, err = run_cli(["pattern", "--list"])
    assert rc == 0 and err == ""
    for name, design in DESIGNS.items():
        assert f"{name}: " in out
        for p in design.params:
            assert p.flag in out
    assert "--gap [um]" in out and "--kind [" not in out and "(inward|outward)" in out


BAD = [
    (["four-pad", "--size", "730"], r"four-pad needs --gap"),
    (["random-jagged", "--sigma", "2"], r"random-jagged needs --seed"),
    (["square", "--size", "-5"], r"--size must be a finite number > 0 um, got '-5'"),
    (["square", "--size", "0"], r"--size must be a finite number > 0"),
    (["square", "--size", "big"], r"--size must be a number, got 'big'"),
    (["four-pad", "--size", "730", "--gap", "730"], r"gap=730 um must be smaller than size=730 um"),
    (["four-pad", "--size", "730", "--gap", "900"], r"gap=900 um must be smaller"),
    (["square", "--size", "200", "--um-per-px", "0"], r"--um-per-px must be a finite number > 0"),
    (["square", "--size", "200", "--um-per-px", "-1"], r"--um-per-px must be a finite number > 0"),
    (["square", "--size", "200", "--margin", "-1"], r"--margin must be a finite number >= 0"),
    (
        ["defect", "--kind", "sideways", "--height", "10", "--width", "20"],
        r"--kind must be one of inward, outward",
    ),
    (
        ["defect", "--kind", "inward", "--height", "150", "--width", "20"],
        r"height=150 um: an inward defect",
    ),
    (["constant-jagged", "--amplitude", "60"], r"amplitude=60 um is too large"),
    (["polygon", "--points", "0,0;10,0;0,10;10,10"], r"the polygon is not simple"),
    (["polygon", "--points", "0,0;10"], r"--points: cannot read point '10'"),
    (["square", "--size", "200", "--bogus", "1"], r"unrecognized arguments: --bogus 1"),
    (["square", "--size", "200", "--seed", "1"], r"unrecognized arguments"),
]


@pytest.mark.parametrize("args,match", BAD)
def test_bad_input_is_one_line_exit_2_and_no_file(tmp_path, run_cli, args, match):
    out = tmp_path / "out.png"
    rc, stdout, err = run_cli(["pattern", *args, "-o", str(out)])
    assert rc == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert re.search(match, err), err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "target,match",
    [
        ("missing/out.png", r"directory .*missing does not exist"),
        ("afile/out.png", r"directory .*afile does not exist"),
        ("adir", r"adir: is a directory"),
        ("out.jpg", r"must end in \.png"),
    ],
)
def test_bad_output_path(tmp_path, run_cli, target, match):
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    rc, _, err = run_cli(["pattern", "square", "--size", "20", "-o", str(tmp_path / target)])
    assert rc == 2 and err.count("\n") == 1
    assert re.search(match, err), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir", "afile"]
    assert list((tmp_path / "adir").iterdir()) == []


def test_missing_output_and_missing_design(run_cli):
    rc, _, err = run_cli(["pattern", "square", "--size", "20"])
    assert rc == 2 and "-o OUT.png is required" in err and err.count("\n") == 1
    rc, _, err = run_cli(["pattern"])
    assert rc == 2 and "name a design (square, rectangle" in err and "--list" in err
