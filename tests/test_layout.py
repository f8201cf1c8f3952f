"""Issue 16: mask layouts (GDSII, OASIS, DXF) as patterns, and designs written as layouts.

Known answers on exact geometry: every design survives generator -> layout -> geometry to
the 1 nm database unit; hierarchies flatten to the area they must have; units, layers,
cells and the chip layer select what they say; every bad input is one line, exit code 2,
nothing written. Layouts are small and rasters coarse, so the file runs in well under a
minute.
"""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path
from typing import Any

import gdstk
import numpy as np
import pytest
import shapely
from ezdxf import filemanagement
from shapely.geometry import Polygon, box

from foundation import InputError
from patterns.geometry import DESIGNS, build
from patterns.layout import (
    DXF_UNITS,
    LayoutSelection,
    layout_format,
    layout_geometry,
    read_layout,
    snap,
    write_layout,
)
from patterns.library import library_path
from simulator.cli import main
from simulator.scene import LAYOUT_KEYS, Scene

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("layout")

ROOT = Path(__file__).resolve().parents[1]
SITE = ROOT / "examples" / "site.gds"

#: Parameters for every registered design (the round trip must cover them all).
DESIGN_PARAMS = {
    "square": {"size": 200},
    "rectangle": {"width": 300, "height": 120.5},
    "circle": {"diameter": 150},
    "four-pad": {"size": 730, "gap": 50},
    "defect": {"kind": "outward", "position": "corner", "height": 30, "width": 60},
    "constant-jagged": {"amplitude": 5},
    "random-jagged": {"sigma": 4, "seed": 1},
    "polygon": {"points": [(0, 0), (100.0004, 0), (50.3, 80.77)]},
}


def one_line_error(rc, err, *needles):
    assert rc == 2, err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert "Traceback" not in err and "internal error" not in err and "[GDSTK]" not in err, err
    for n in needles:
        assert n in err, err


def gds(path: Path, cells: dict[str, list[Any]], unit=1e-6, precision=1e-9) -> Path:
    """Write a library of ``{name: [elements]}`` (cells created first, then filled)."""
    lib = gdstk.Library(unit=unit, precision=precision)
    made = {name: lib.new_cell(name) for name in cells}
    for name, elements in cells.items():
        for e in elements:
            element: Any = e(made) if callable(e) else e  # an element, or one made of the cells
            made[name].add(element)
    lib.write_gds(str(path))
    return path


def dxf(path: Path, entities, insunits: int | None = 13, layers=()) -> Path:
    doc = filemanagement.new("R2010")
    for name in layers:
        doc.layers.add(name)
    msp = doc.modelspace()
    for points, layer, closed in entities:
        msp.add_lwpolyline(points, close=closed, dxfattribs={"layer": layer})
    if insunits is None:
        del doc.header["$INSUNITS"]
    else:
        doc.units = insunits
    doc.saveas(path)
    return path


def coords_nm(geometry) -> np.ndarray:
    """Every vertex in whole nanometres; each must sit on the 1 nm grid (to float round-off)."""
    c = shapely.get_coordinates(shapely.normalize(geometry)) * 1000
    n = np.round(c)
    assert np.all(np.abs(c - n) < 1e-6), "a vertex is off the 1 nm grid"
    return n.astype(np.int64)


# ------------------------------------------------------------------ round trips
def test_every_design_has_round_trip_parameters():
    assert set(DESIGN_PARAMS) == set(DESIGNS)


@pytest.mark.parametrize("suffix", [".gds", ".oas", ".dxf"])
@pytest.mark.parametrize("name", list(DESIGN_PARAMS))
def test_round_trip_design_to_the_database_unit(tmp_path, name, suffix):
    design = build(name, **DESIGN_PARAMS[name])
    path = write_layout(tmp_path / f"d{suffix}", design, cell=name)
    lay = read_layout(path)
    back = lay.geometry(next(iter(k for k, v in lay.rings.items() if v)))
    assert lay.dbu_um == 1e-3
    # The same polygon to the database unit: the design's vertices rounded to 1 nm, exactly.
    assert np.array_equal(coords_nm(back), coords_nm(snap(design)))
    assert shapely.hausdorff_distance(back, design) <= 0.5e-3 * math.sqrt(2) + 1e-12
    assert (
        abs(back.area - design.area) <= 0.5e-3 * design.length
    )  # each vertex moved by at most half a database unit
    assert back.is_valid and len(shapely.get_parts(back)) == len(shapely.get_parts(design))


def test_pattern_command_writes_gds_and_dxf(tmp_path, run_cli):
    for suffix, layer in ((".gds", "layer 1/0"), (".dxf", "layer PATTERN")):
        out = tmp_path / f"fourpad{suffix}"
        rc, text, err = run_cli(["pattern", "four-pad", "--size", "730", "--gap", "50", "-o", out])
        assert rc == 0, err
        assert (
            layer in text
            and "4 polygons" in text
            and "database unit 1 nm" in text
            and "area 462400 um^2" in text
        )
        g, chip, record = layout_geometry(out)
        assert g.area == 462400 and g.bounds == (-365, -365, 365, 365) and chip is None
    lib = gdstk.read_gds(str(tmp_path / "fourpad.gds"))
    assert (lib.unit, lib.precision) == (1e-6, 1e-9) and [c.name for c in lib.top_level()] == [
        "four_pad"
    ]
    (cell,) = lib.cells
    assert isinstance(cell, gdstk.Cell)
    assert {(p.layer, p.datatype) for p in cell.polygons} == {(1, 0)}
    assert (
        filemanagement.readfile(tmp_path / "fourpad.dxf").header["$INSUNITS"] == 13
    )  # micrometres
    rc, _, err = run_cli(["pattern", "square", "--size", "10", "-o", tmp_path / "x.txt"])
    one_line_error(rc, err, ".gds, .oas or .dxf")
    assert not (tmp_path / "x.txt").exists()


def test_polygon_with_a_hole_survives_as_a_keyhole_and_as_nested_dxf(tmp_path):
    ring = box(-100, -100, 100, 100).difference(box(-40, -30, 40, 30))
    for suffix in (".gds", ".dxf"):
        back = read_layout(write_layout(tmp_path / f"r{suffix}", ring)).geometry(
            (1, 0) if suffix == ".gds" else "PATTERN"
        )
        assert isinstance(back, Polygon)
        assert back.geom_type == "Polygon" and len(back.interiors) == 1
        assert back.area == 200 * 200 - 80 * 60 and back.symmetric_difference(ring).area == 0


# ------------------------------------------------------------------ hierarchy, layers, units
def test_hierarchical_gds_flattens_references_arrays_rotations_magnification(tmp_path):
    pad = gdstk.rectangle((0, 0), (10, 10), layer=1)  # 100 um^2
    path = gds(
        tmp_path / "h.gds",
        {
            "PAD": [pad],
            "PAIR": [
                lambda c: gdstk.Reference(c["PAD"], (0, 0)),
                lambda c: gdstk.Reference(c["PAD"], (20, 0)),
            ],  # 200
            "TOP": [
                lambda c: gdstk.Reference(
                    c["PAD"], (-500, 0), rotation=math.radians(30)
                ),  # rotated: 100
                lambda c: gdstk.Reference(c["PAD"], (-300, 0), magnification=2.5),  # 625
                lambda c: gdstk.Reference(
                    c["PAD"], (-200, 0), rotation=math.pi / 2, magnification=1.5, x_reflection=True
                ),  # 225
                lambda c: gdstk.Reference(
                    c["PAIR"], (0, 100), columns=3, rows=2, spacing=(100, 50)
                ),  # array of a reference: 6 x 200
                lambda c: gdstk.Reference(
                    c["PAIR"], (0, -200), rotation=math.pi, magnification=2
                ),  # 2 x 400
                gdstk.FlexPath([(0, -400), (100, -400)], 4, layer=1),  # a path: 400
                gdstk.rectangle((300, 300), (320, 310), layer=1),  # 200, overlapped by the next one
                gdstk.rectangle(
                    (310, 300), (330, 310), layer=1
                ),  # 200, 100 of it shared: the union adds 100
            ],
        },
    )
    g = read_layout(path).geometry((1, 0))
    # Exact but for the 30-degree pad, whose vertices are snapped to the 1 nm grid (area error < perimeter x 0.5 nm).
    assert g.area == pytest.approx(100 + 625 + 225 + 1200 + 800 + 400 + 300, abs=40 * 0.5e-3)
    assert len(shapely.get_parts(g)) == 1 + 1 + 1 + 12 + 2 + 1 + 1
    rotated = [p for p in shapely.get_parts(g) if p.bounds[0] < -400][0]
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    expected = (
        np.round(
            np.array(
                [(0, 0), (10 * c, 10 * s), (10 * c - 10 * s, 10 * s + 10 * c), (-10 * s, 10 * c)]
            )
            * 1000
        )
        / 1000
    )
    assert sorted(map(tuple, rotated.exterior.coords[:-1])) == sorted(
        map(tuple, expected + (-500, 0))
    )  # snapped to 1 nm
    mirrored = [p for p in shapely.get_parts(g) if -250 < p.bounds[0] < -100][0]
    assert mirrored.bounds == pytest.approx(
        (-200, 0, -185, 15)
    )  # x_reflection, then 90 deg: stays in the first quadrant


def test_hand_written_gds_with_a_box_record(tmp_path):
    """A GDSII file written byte by byte (no layout library): BOUNDARY and BOX elements, 1 nm in 1 um."""

    def rec(rt, dt, data=b""):
        return struct.pack(">HBB", 4 + len(data), rt, dt) + data

    def real8(x):  # GDSII excess-64 base-16 real
        e = 64
        while x >= 1:
            x, e = x / 16, e + 1
        while x < 1 / 16:
            x, e = x * 16, e - 1
        return bytes([e]) + int(round(x * 2**56)).to_bytes(7, "big")

    def xy(*v):
        return struct.pack(f">{len(v)}i", *v)

    body = (
        rec(0, 2, struct.pack(">h", 600))
        + rec(1, 2, bytes(24))
        + rec(2, 6, b"HAND")
        + rec(3, 5, real8(1e-3) + real8(1e-9))
    )
    body += rec(5, 2, bytes(24)) + rec(6, 6, b"TOP\0")
    body += (
        rec(8, 0)
        + rec(13, 2, b"\0\1")
        + rec(14, 2, b"\0\0")
        + rec(16, 3, xy(0, 0, 20000, 0, 20000, 10000, 0, 10000, 0, 0))
        + rec(17, 0)
    )
    body += (
        rec(45, 0)
        + rec(13, 2, b"\0\1")
        + rec(46, 2, b"\0\0")
        + rec(16, 3, xy(20000, 0, 30500, 0, 30500, 10000, 20000, 10000, 20000, 0))
        + rec(17, 0)
    )
    body += rec(7, 0) + rec(4, 0)
    path = tmp_path / "hand.layout"  # no known extension: recognized by its content
    path.write_bytes(body)
    assert layout_format(path) == "gds"
    g = read_layout(path).geometry((1, 0))
    assert (
        g.geom_type == "Polygon" and g.area == 30.5 * 10 and g.bounds == (0, 0, 30.5, 10)
    )  # box and boundary merged


def test_layer_and_datatype_selection(tmp_path, capsys):
    path = gds(
        tmp_path / "l.gds",
        {
            "TOP": [
                gdstk.rectangle((0, 0), (10, 10), layer=1, datatype=0),
                gdstk.rectangle((0, 0), (20, 10), layer=1, datatype=1),
                gdstk.rectangle((0, 0), (30, 10), layer=2, datatype=0),
                gdstk.rectangle((50, 0), (60, 10), layer=2, datatype=0),
            ]
        },
    )
    for text, area in (("1/0", 100), ("1", 100), ("1/1", 200), (" 2 / 0 ", 400)):
        assert layout_geometry(path, LayoutSelection(layer=text))[0].area == area
    with pytest.raises(
        InputError,
        match=r"several layers \(1/0 \(1 polygon\), 1/1 \(1 polygon\), 2/0 \(2 polygons\)\); choose the pattern with --layer",
    ):
        layout_geometry(path)
    with pytest.raises(InputError, match="give a layer and datatype as L/D"):
        layout_geometry(path, LayoutSelection(layer="one"))
    # A layout with one layer needs no --layer; with a chip layer, the other layer is the pattern.
    two = gds(
        tmp_path / "two.gds",
        {
            "TOP": [
                gdstk.rectangle((0, 0), (10, 10), layer=5),
                gdstk.rectangle((-5, -5), (15, 15), layer=6),
            ]
        },
    )
    assert layout_geometry(two, LayoutSelection(chip_layer="6/0"))[0].area == 100


@pytest.mark.parametrize(
    ("unit", "precision", "side"), [(1e-3, 1e-6, 0.2), (1e-9, 1e-9, 200_000), (1e-6, 1e-10, 200)]
)
def test_gds_units_mm_nm_and_a_fine_database_unit(tmp_path, unit, precision, side):
    """A 200 um square drawn in mm, in nm, and in um with a 0.1 nm database unit."""
    path = gds(
        tmp_path / "u.gds",
        {"TOP": [gdstk.rectangle((0, 0), (side, side / 2))]},
        unit=unit,
        precision=precision,
    )
    lay = read_layout(path)
    g = lay.geometry((0, 0))
    assert g.bounds == (0, 0, 200, 100) and g.area == 20000
    assert lay.dbu_um == pytest.approx(precision * 1e6)


def test_dxf_units_from_the_header_or_the_flag(tmp_path, capsys):
    square = [(0, 0), (0.2, 0), (0.2, 0.1), (0, 0.1)]
    mm = dxf(tmp_path / "mm.dxf", [(square, "PADS", True)], insunits=4)
    assert read_layout(mm).geometry("PADS").bounds == (0, 0, 200, 100)
    assert read_layout(mm).key("pads") == "PADS"  # DXF layer names ignore case, as in AutoCAD
    nm = dxf(
        tmp_path / "nm.dxf", [([(x * 1e6, y * 1e6) for x, y in square], "PADS", True)], insunits=12
    )
    assert read_layout(nm).geometry("PADS").area == 20000
    bare = dxf(tmp_path / "bare.dxf", [(square, "PADS", True)], insunits=None)
    assert read_layout(bare, dxf_units="mm").geometry("PADS").area == 20000
    with pytest.raises(
        InputError, match=r"states no units \(\$INSUNITS\); pass --dxf-units um, mm or nm"
    ):
        read_layout(bare)
    with pytest.raises(InputError, match="drop --dxf-units"):
        read_layout(mm, dxf_units="um")


def test_dxf_blocks_inherit_the_insert_layer_and_arrays_flatten(tmp_path):
    doc = filemanagement.new("R2010")
    doc.units = 13
    pad = doc.blocks.new("PAD")
    pad.add_lwpolyline([(0, 0), (10, 0), (10, 10), (0, 10)], close=True, dxfattribs={"layer": "0"})
    msp = doc.modelspace()
    msp.add_blockref(
        "PAD", (0, 0), dxfattribs={"layer": "PADS", "rotation": 45, "xscale": 2, "yscale": 2}
    )  # 400
    msp.add_blockref("PAD", (100, 0), dxfattribs={"layer": "PADS"}).grid(
        size=(2, 3), spacing=(20, 30)
    )  # 6 x 100
    msp.add_circle(
        (0, -100), 10, dxfattribs={"layer": "PADS"}
    )  # sampled within 1 nm of the true circle
    msp.add_lwpolyline(
        [(-200, 0, 1), (-190, 0, 1)], format="xyb", close=True, dxfattribs={"layer": "PADS"}
    )  # two bulges: a circle, r 5
    msp.add_lwpolyline(
        [(-50, -50), (50, -50), (50, 50), (-50, 50)], close=True, dxfattribs={"layer": "OUTLINE"}
    )
    msp.add_lwpolyline(
        [(-10, -10), (10, -10), (10, 10), (-10, 10)], close=True, dxfattribs={"layer": "OUTLINE"}
    )  # a hole
    msp.add_text("label", dxfattribs={"layer": "PADS"})
    doc.saveas(tmp_path / "b.dxf")
    lay = read_layout(tmp_path / "b.dxf")
    pads = lay.geometry("PADS")
    exact = 400 + 600 + math.pi * 100 + math.pi * 25
    # Chords 1 nm inside the circles lose 2/3 x sagitta x perimeter; the 45-degree pad's vertices snap to 1 nm.
    lost = 2 / 3 * 1e-3 * 2 * math.pi * (10 + 5) + 0.5e-3 * 80
    assert exact - lost <= pads.area < exact + 0.5e-3 * 80 and len(shapely.get_parts(pads)) == 9
    circle = [p for p in shapely.get_parts(pads) if p.bounds[0] < -150][0]
    assert circle.bounds == pytest.approx(
        (-200, -5, -190, 5), abs=1.5e-3
    )  # chords within 1 nm, then snapped to 1 nm
    outline = lay.geometry("OUTLINE")
    assert isinstance(outline, Polygon)
    assert outline.area == 100 * 100 - 20 * 20 and len(outline.interiors) == 1
    with pytest.raises(InputError, match=r"no block named 'X'; blocks present: PAD \(1 entity\)"):
        read_layout(tmp_path / "b.dxf", cell="X")
    assert read_layout(tmp_path / "b.dxf", cell="PAD").geometry("0").area == 100


# ------------------------------------------------------------------ the chip layer and the frame
def offset_site(tmp_path: Path) -> Path:
    """Chip outline 200 x 200 um on 2/0 at layout (1000, 500); the pad 30 um right of and 20 um below it."""
    return gds(
        tmp_path / "offset.gds",
        {
            "TOP": [
                gdstk.rectangle((900, 400), (1100, 600), layer=2),
                gdstk.rectangle((930, 380), (1130, 580), layer=1),
            ]
        },
    )


def test_chip_layer_keeps_the_pattern_placement_relative_to_the_chip(tmp_path):
    path = offset_site(tmp_path)
    pattern, chip, record = layout_geometry(path, LayoutSelection(layer="1/0", chip_layer="2/0"))
    assert chip is not None
    assert chip.bounds == (-100, -100, 100, 100) and pattern.bounds == (-70, -120, 130, 80)
    assert record["origin_um"] == [1000, 500] and "chip outline on layer 2/0" in record["origin"]
    pattern, chip, record = layout_geometry(path, LayoutSelection(layer="1/0"))
    assert (
        chip is None
        and pattern.bounds == (-100, -100, 100, 100)
        and record["origin_um"] == [1030, 480]
    )
    assert "bounding box" in record["origin"]


@pytest.mark.fft
def test_chip_layer_reproduces_the_known_offset_in_energy_and_toml(tmp_path, run_cli):
    path = offset_site(tmp_path)
    out = tmp_path / "e.json"
    rc, _, err = run_cli(
        [
            "energy",
            "--pattern",
            path,
            "--layer",
            "1/0",
            "--chip-layer",
            "2/0",
            "--resolution",
            "2",
            "--at",
            "30,-20,0",
            "--at",
            "0,0,0",
            "--json",
            out,
        ]
    )
    assert rc == 0, err
    assert (
        "poses are relative to the centre of the chip outline on layer 2/0, at layout (1000, 500) um"
        in err
    )
    doc = json.loads(out.read_text())
    poses = doc["poses"]
    # float32: within the noise floor, 32 eps(float32) max|E| (the FFT round-off bound),
    # 0.15 um^2 at max|E| = 200^2 um^2 (the default rel=1e-6, 0.04 um^2, was below it)
    floor_um2 = doc["noise_floor_J"] / (abs(doc["delta_gamma_N_m"]) * 1e-12)
    assert poses[0]["overlap_um2"] == pytest.approx(200 * 200, abs=floor_um2) and poses[1][
        "overlap_um2"
    ] == pytest.approx(170 * 180, abs=floor_um2)
    # The same scene from a TOML file: the flags are scene keys.
    scene = tmp_path / "s.toml"
    scene.write_text(
        'pattern = "offset.gds"\nlayer = "1/0"\nchip_layer = "2/0"\nresolution_um = 2\n'
    )
    s = Scene.from_toml(scene)
    assert s.chip.geometry.bounds == (-100, -100, 100, 100) and s.pattern.params["layout"][
        "origin_um"
    ] == [1000, 500]
    scene.write_text('pattern = "offset.gds"\nlayer = "1/0"\ndxf_units = "cm"\n')
    rc, _, err = run_cli(["energy", scene, "--chip-size", "200", "--at", "0,0,0"])
    one_line_error(rc, err, 'dxf_units = "cm"', '"um", "mm", "nm"')


def test_evaluate_gds_written_by_gdstk_finds_the_offset(tmp_path, run_cli):
    path = offset_site(tmp_path)
    rep = tmp_path / "rep"
    rc, out, err = run_cli(
        [
            "evaluate",
            path,
            "--layer",
            "1/0",
            "--chip-layer",
            "2/0",
            "--out",
            rep,
            "--quiet",
            "--resolution",
            "5",
            "--twist-step",
            "3",
        ]
    )
    assert rc == 0, err
    assert out.startswith(
        "frame: offset.gds cell TOP layer 1/0 (1 polygon, user unit 1 um, database unit 1 nm)"
    )
    s = json.loads((rep / "summary.json").read_text())
    g = s["global_minimum"]
    assert (g["x_um"], g["y_um"], g["twist_deg"]) == (30.0, -20.0, 0.0)
    assert s["layout"]["origin_um"] == [1000, 500] and s["settings"]["chip_um"] == [200, 200]
    assert "chip outline on layer 2/0" in (rep / "report.html").read_text()


def test_evaluate_the_example_site(tmp_path, run_cli):
    rep = tmp_path / "rep"
    rc, out, err = run_cli(
        [
            "evaluate",
            SITE,
            "--layer",
            "1/0",
            "--chip-layer",
            "2/0",
            "--out",
            rep,
            "--quiet",
            "--resolution",
            "4",
            "--twist-step",
            "2",
        ]
    )
    assert rc == 0, err
    assert (
        "poses are relative to the centre of the chip outline on layer 2/0, at layout (1500, 800) um"
        in out
    )
    s = json.loads((rep / "summary.json").read_text())
    g = s["global_minimum"]
    assert (g["x_um"], g["y_um"], g["twist_deg"]) == (0.0, 0.0, 0.0)
    assert s["layout"]["area_um2"] == 4 * 180 * 180 and s["layout"]["polygons"] == 4
    # Without a chip layer the target is the pads' bounding-box centre, and the output says so.
    rc, out, err = run_cli(
        [
            "evaluate",
            SITE,
            "--layer",
            "1/0",
            "--out",
            tmp_path / "rep2",
            "--quiet",
            "--resolution",
            "8",
            "--no-twist",
        ]
    )
    assert rc == 0, err
    assert (
        "the centre of the pattern's bounding box (no chip layer), at layout (1500, 800) um" in out
    )


def test_example_site_is_what_its_script_writes(tmp_path):
    import runpy

    mod = runpy.run_path(str(ROOT / "examples" / "make_site_gds.py"))
    mod["main"](str(tmp_path / "site.gds"))
    assert (tmp_path / "site.gds").read_bytes() == SITE.read_bytes()
    cells = {c.name: c for c in gdstk.read_gds(str(SITE)).cells}
    assert isinstance(cells["SITE"], gdstk.Cell)
    assert len(cells["SITE"].references) == 4 and {
        r.cell.name for r in cells["SITE"].references
    } == {"PAD"}


def test_layout_chip_file_and_content_sniffing(tmp_path, capsys):
    pad = write_layout(tmp_path / "pad.dxf", box(0, 0, 100, 100))
    chip = write_layout(tmp_path / "chip.oas", box(500, 500, 600, 600))
    s = Scene.from_inputs(pad, chip=chip, resolution_um=5)
    assert s.chip.geometry.bounds == (-50, -50, 50, 50) and s.pattern.geometry.area == 10000
    assert layout_format(library_path("square_200")) is None  # a PNG stays a PNG
    renamed = tmp_path / "pad.png"
    renamed.write_bytes(pad.read_bytes())  # a DXF named .png: its content decides
    assert layout_format(renamed) == "dxf"


def test_schema_and_scene_agree_on_the_layout_keys():
    from simulator.scene import DXF_UNITS as SCHEMA_UNITS, SCHEMA

    assert set(LAYOUT_KEYS) <= set(SCHEMA[None]) and tuple(DXF_UNITS) == SCHEMA_UNITS


# ------------------------------------------------------------------ bad input: one line, exit 2, nothing written
def bowtie(tmp_path):
    return gds(
        tmp_path / "bow.gds",
        {"TOP": [gdstk.Polygon([(0, 0), (100, 100), (100, 0), (0, 100)], layer=1)]},
    )


BAD = {
    "missing_layer": (
        lambda t: [SITE, "--layer", "7/0"],
        [
            "cell SITE has nothing on layer 7/0",
            "layers present: 1/0 (4 polygons), 2/0 (1 polygon), 3/0 (4 polygons)",
        ],
    ),
    "missing_cell": (
        lambda t: [SITE, "--layer", "1/0", "--cell", "PADS"],
        ["no cell named 'PADS'", "cells present: PAD (1 polygon), SITE (9 polygons)"],
    ),
    "several_top_cells": (
        lambda t: [
            gds(
                t / "tops.gds",
                {"A": [gdstk.rectangle((0, 0), (1, 1))], "B": [gdstk.rectangle((0, 0), (2, 1))]},
            )
        ],
        ["2 top cells (A (1 polygon), B (1 polygon)); choose one with --cell NAME"],
    ),
    "empty_dxf_layer": (
        lambda t: [
            dxf(t / "e.dxf", [([(0, 0), (9, 0), (9, 9)], "PADS", True)], layers=["EMPTY"]),
            "--layer",
            "EMPTY",
        ],
        ["layer 'EMPTY': the layer is empty", "'PADS' (1 polygon)"],
    ),
    "zero_area_gds_layer": (
        lambda t: [gds(t / "z.gds", {"TOP": [gdstk.Polygon([(0, 0), (10, 0), (20, 0)], layer=1)]})],
        ["the layer is empty"],
    ),
    "open_dxf_polyline": (
        lambda t: [dxf(t / "o.dxf", [([(0, 0), (50, 0), (50, 40)], "PADS", False)])],
        ["LWPOLYLINE", "is open: it ends at (50, 40) um, not at its start (0, 0) um"],
    ),
    "self_intersecting": (
        lambda t: [bowtie(t)],
        ["polygon 1 of 1 crosses itself near (50, 50) um"],
    ),
    "dxf_without_units": (
        lambda t: [dxf(t / "n.dxf", [([(0, 0), (9, 0), (9, 9)], "PADS", True)], insunits=None)],
        ["states no units", "pass --dxf-units um, mm or nm"],
    ),
    "corrupt_gds": (
        lambda t: [_truncated(t)],
        ["not a readable GDSII file", "End of file reached unexpectedly"],
    ),
    "corrupt_dxf": (
        lambda t: [
            _written(t / "bad.dxf", "0\nSECTION\n2\nENTITIES\n0\nLWPOLYLINE\n10\nnot-a-number\n")
        ],
        ["not a readable DXF file"],
    ),
    "missing_referenced_cell": (
        lambda t: [
            gds(
                t / "ghost.gds",
                {
                    "TOP": [
                        gdstk.Reference("GHOST", (0, 0)),  # pyright: ignore[reportArgumentType] - a cell's name, as gdstk takes
                        gdstk.rectangle((0, 0), (9, 9)),
                    ]
                },
            )
        ],
        ["cell TOP references cell GHOST, which the file does not hold"],
    ),
    "raster_over_budget": (
        lambda t: [
            SITE,
            "--layer",
            "1/0",
            "--chip-layer",
            "2/0",
            "--resolution",
            "0.01",
            "--memory-budget",
            "64",
        ],
        [
            "the pattern raster of site.gds at 0.01 um/px would be 40,000 x 40,000 px",
            "--resolution 0.5 (um/px) or coarser would fit",
        ],
    ),
    "layer_flag_on_a_png": (
        lambda t: [library_path("square_200"), "--layer", "1/0", "--chip-size", "200"],
        ["--layer apply to layout patterns"],
    ),
    "two_chips": (
        lambda t: [SITE, "--layer", "1/0", "--chip-layer", "2/0", "--chip-size", "400"],
        ["give one chip"],
    ),
    "same_layer_twice": (
        lambda t: [SITE, "--layer", "2/0", "--chip-layer", "2/0"],
        ["name the same layer 2/0"],
    ),
}


def _written(p: Path, text: str) -> Path:
    p.write_text(text)
    return p


def _truncated(t: Path) -> Path:
    p = t / "cut.gds"
    p.write_bytes(SITE.read_bytes()[:300])
    return p


@pytest.mark.parametrize("case", list(BAD))
def test_bad_layout_input_is_one_line_and_writes_nothing(tmp_path, capfd, case):
    make, needles = BAD[case]
    inputs = make(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    rc = main(["evaluate", *map(str, inputs), "--out", str(tmp_path / "rep"), "--quiet"])
    out, err = capfd.readouterr()  # file descriptors too: no stray lines from the C readers
    one_line_error(rc, err, *needles)
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no --out, no temporaries


def test_the_suggested_scale_fits(tmp_path, run_cli):
    # The raster at the suggested scale fits the 64 MB it was suggested for; the landscape at
    # that scale is priced on its own (with its transforms' work space it needs about 89 MB).
    args = [
        "energy",
        "--pattern",
        SITE,
        "--layer",
        "1/0",
        "--chip-layer",
        "2/0",
        "--resolution",
        "0.5",
        "--no-twist",
        "--at",
        "0,0,0",
    ]
    rc, _, err = run_cli([*args, "--memory-budget", "64"])
    assert rc == 2 and "the landscape needs about" in err and "raster" not in err, err
    rc, _, err = run_cli([*args, "--memory-budget", "128"])
    assert rc == 0, err
