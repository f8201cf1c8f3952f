"""Property-based fuzzing of the boundary: CLI flags, TOML scenes and the PNG reader.

For any input: exit code 0 or 2, on failure exactly one line on stderr with no
traceback and no "internal error", no file left behind but the outputs asked for,
and bounded memory (the peak of Python and numpy allocations, traced per example,
stays under 1 GiB while the requests range up to 1e300 um and 1e8 starts). The
number of examples is fixed so the suite stays within CI's time.
"""

from __future__ import annotations

import contextlib
import io
import os
import struct
import tempfile
import tracemalloc
import zlib
from pathlib import Path
from typing import cast

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st
from PIL import Image, PngImagePlugin

from foundation import InputError
from patterns import read_mask
from simulator.cli import main

MEMORY_LIMIT = 2**30
SETTINGS = {"deadline": None, "derandomize": True, "suppress_health_check": [HealthCheck.too_slow]}

NUMBERS = [
    "0",
    "-0",
    "1",
    "2",
    "-3",
    "7.5",
    "40",
    "200",
    "1e-300",
    "1e-6",
    "1e6",
    "1e9",
    "1e300",
    "-1e9",
    "nan",
    "inf",
    "-inf",
    "",
    "abc",
    "0x10",
    "1_0",
]
POSES = [
    "0,0,0",
    "1,2,3",
    "-40,25,0",
    "1e9,0,0",
    "nan,0,0",
    "1,2",
    "1,2,3,4",
    "a,b,c",
    "",
    "0,0,1e300",
    "5,5,-720",
]
RANGES = [
    "-10:10:5,-10:10:5",
    "0,0",
    "0:0:0,0",
    "-1e9:1e9:1e-3,0",
    "1:0:1,0",
    "a:b:c,0",
    "0,0,0:90:1e-6",
    "-4:4:2,-4:4:2,0",
]


def run_traced(args: list[str], workdir: Path) -> tuple[int, str, int]:
    """main(args) in ``workdir``: (exit code, stderr, peak traced bytes)."""
    err = io.StringIO()
    cwd = os.getcwd()
    os.chdir(workdir)
    tracemalloc.start()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                rc = main(args)
            except SystemExit as e:  # argparse usage errors
                rc = cast(int, e.code)  # argparse exits with a status number
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
        os.chdir(cwd)
    return rc, err.getvalue(), peak


def check_run(rc, err: str, peak: int, workdir: Path, inputs: set[str], outputs: set[str]) -> None:
    assert rc in (0, 2), (rc, err)
    assert "Traceback" not in err and "internal error" not in err, err
    assert peak < MEMORY_LIMIT, f"{peak / 2**20:.0f} MB traced"
    if rc == 2:
        lines = [
            ln
            for ln in err.splitlines()
            if not ln.startswith(("compiling", "selfalign: warning", "warning:"))
        ]
        assert len(lines) == 1 and "error" in lines[0], err
    left = {p.name for p in workdir.iterdir()}
    allowed = inputs | (outputs if rc == 0 else set())
    assert left <= allowed, f"left behind: {sorted(left - allowed)} ({err})"


def small_pattern(d: Path) -> str:
    assert (
        main(["pattern", "square", "--size", "40", "--um-per-px", "2", "-o", str(d / "pad.png")])
        == 0
    )
    return "pad.png"


# ------------------------------------------------------------------ CLI flags
def pool(valid: list[str], hostile: list[str] = NUMBERS) -> st.SearchStrategy[str]:
    """Valid values about half of the time, hostile ones otherwise."""
    return st.sampled_from(valid) | st.sampled_from(hostile)


SCENE_FLAGS = {
    "--chip-size": pool(["20", "30x10", "6"], NUMBERS + ["1e300x1", "0x5"]),
    "--um-per-px": pool(["2", "1", "4"]),
    "--resolution": pool(["2", "4"]),
    "--twist-step": pool(["1", "5", "45"]),
    "--window": pool(["10", "40"]),
    "--pad-angle": pool(["20", "30"], NUMBERS + ["60", "180"]),
    "--substrate-angle": pool(["60", "90"], NUMBERS + ["30"]),
    "--surface-tension": pool(["72.8", "20"]),
    "--memory-budget": pool(["64", "512"], ["1e9", "0", "-1", "nan", "1"]),
    "--max-image-mpx": pool(["1", "64"], ["0.0001", "1e9", "-1"]),
}
COMMAND_FLAGS = {
    "energy": {
        "--at": pool(["0,0,0", "3,-2,5"], POSES),
        "--curve": st.sampled_from(["x", "y", "twist", "z"]),
        "--from": pool(["-20", "0"]),
        "--to": pool(["20", "10"]),
        "--json": pool(["e.json"], ["pad.png", "/dev/null", ".", ""]),
    },
    "simulate": {
        "--start": pool(["4,-2,0", "10,0,5"], POSES),
        "--max-steps": pool(["1", "50"], ["0", "-5", "1000000000", "1000000000000", "1e3"]),
        "--method": st.sampled_from(["greedy", "gradient", "newton"]),
        "--json": pool(["t.json"], ["pad.png"]),
        "--volume": pool(["0.5", "20"]),
    },
    "montecarlo": {
        "--random": pool(["1", "20"], ["0", "1e7", "1e8", "1.5", "x"]),
        "--grid": pool(["-4:4:2,-4:4:2", "0,0"], RANGES),
        "--spread": pool(["2,2,1", "0,0,0"], POSES),
        "--seed": pool(["0", "7"], ["-1", "1e3", "x"]),
        "--max-steps": pool(["1", "50"], ["0", "3000000000"]),
        "--csv": pool(["m.csv"], ["pad.png"]),
        "--chunk": pool(["1", "64"], ["0", "1e9"]),
    },
}


@st.composite
def cli_args(draw):
    command = draw(st.sampled_from(sorted(COMMAND_FLAGS)))
    args = [command, "--pattern", "pad.png"]
    flags = {**SCENE_FLAGS, **COMMAND_FLAGS[command]}
    chosen = draw(st.lists(st.sampled_from(sorted(flags)), min_size=1, max_size=4, unique=True))
    if "--chip-size" not in chosen:
        args += ["--chip-size", "20"]
    if "--memory-budget" not in chosen:
        args += ["--memory-budget", "512"]
    required = {
        "energy": [("--at", "0,0,0")],
        "simulate": [("--start", "4,-2,0")],
        "montecarlo": [] if "--grid" in chosen else [("--random", "10"), ("--spread", "2,2,1")],
    }[command]
    for flag, value in required:
        if flag not in chosen:
            args += [flag, value]
    for flag in chosen:
        args.append(f"{flag}={draw(flags[flag])}")
    if command != "energy":
        args.append("--quiet")
    return args


@settings(max_examples=60, **SETTINGS)
@given(args=cli_args())
def test_fuzz_cli_flags(args):
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        small_pattern(d)
        outputs = {a.split("=", 1)[1] for a in args if a.startswith(("--json=", "--csv="))}
        rc, err, peak = run_traced(args, d)
        check_run(rc, err, peak, d, {"pad.png"}, outputs)


# ------------------------------------------------------------------ TOML scenes
TOML_VALUES = st.sampled_from(
    [
        "1",
        "0",
        "-1",
        "1e300",
        "-1e300",
        "nan",
        "inf",
        "true",
        "false",
        '"false"',
        '"no"',
        '"water"',
        "[1, 2, 3]",
        "[]",
        "[200]",
        "[20, 10]",
        '"pad.png"',
        '"missing.png"',
        "42",
        "{a = 1}",
        "9" * 40,
        "[[1], [2]]",
        '"float16"',
        '"float64"',
        "2.0",
        "0.5",
    ]
)
TOML_KEYS = [
    (None, "chip_size_um"),
    (None, "um_per_px"),
    (None, "resolution_um"),
    (None, "dtype"),
    (None, "window_um"),
    (None, "memory_budget_mb"),
    (None, "accuracy"),
    (None, "pattern"),
    (None, "colour"),
    ("materials", "surface_tension_mN_m"),
    ("materials", "pad_angle_deg"),
    ("materials", "allow_repulsive"),
    ("twist", "step_deg"),
    ("twist", "min_deg"),
    ("effects", "twist"),
    ("liquid", "volume_nl"),
    ("simulate", "metod"),
    ("montecarlo", "random"),
]


@st.composite
def toml_scene(draw):
    entries = draw(
        st.lists(
            st.tuples(st.sampled_from(TOML_KEYS), TOML_VALUES), max_size=6, unique_by=lambda e: e[0]
        )
    )
    top = {k: v for (t, k), v in entries if t is None}
    top.setdefault("pattern", '"pad.png"')
    top.setdefault("chip_size_um", "20")
    top.setdefault("memory_budget_mb", "512")
    lines = [f"{k} = {v}" for k, v in top.items()]
    for table in sorted({t for (t, _), _ in entries if t}):
        lines.append(f"[{table}]")
        lines += [f"{k} = {v}" for (t, k), v in entries if t == table]
    return "\n".join(lines) + "\n"


@settings(max_examples=40, **SETTINGS)
@given(text=toml_scene())
def test_fuzz_toml_scene(text):
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        small_pattern(d)
        (d / "scene.toml").write_text(text)
        rc, err, peak = run_traced(["energy", "scene.toml", "--at", "0,0,0", "--json", "e.json"], d)
        check_run(rc, err, peak, d, {"pad.png", "scene.toml"}, {"e.json"})


# ------------------------------------------------------------------ PNG reader
def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return (
        struct.pack(">I", len(data))
        + kind
        + data
        + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    )


@st.composite
def png_bytes(draw):
    h, w = draw(st.integers(1, 12)), draw(st.integers(1, 12))
    mode = draw(st.sampled_from(["L", "LA", "RGB", "RGBA", "1", "P", "I;16", "F"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    if mode == "I;16":
        im = Image.fromarray((rng.random((h, w)) * 65535).astype(np.uint16))
    else:
        im = Image.fromarray((rng.random((h, w)) * 255).astype(np.uint8)).convert(
            mode if mode != "F" else "L"
        )
    info = PngImagePlugin.PngInfo()
    note = draw(
        st.sampled_from(
            [
                None,
                "{}",
                '{"um_per_px": "x"}',
                '{"um_per_px": -1}',
                "[" * 200 + "]" * 200,
                "not json",
                '{"parameters": {"gap": {"value": 1e999}}}',
                '{"design": 5}',
            ]
        )
    )
    if note is not None:
        info.add_text("selfalign", note)
    px_per_m = draw(st.sampled_from([None, 1, 1000, 10**6, 2**31 - 1]))
    buf = io.BytesIO()
    kw = {"dpi": (px_per_m * 0.0254,) * 2} if px_per_m else {}
    im.save(buf, format="PNG", pnginfo=info, **kw)
    data = bytearray(buf.getvalue())
    damage = draw(st.sampled_from(["none", "truncate", "flip", "huge_ihdr"]))
    if damage == "truncate":
        data = data[: draw(st.integers(8, len(data)))]
    elif damage == "flip":
        i = draw(st.integers(8, len(data) - 1))
        data[i] ^= 1 << draw(st.integers(0, 7))
    elif damage == "huge_ihdr":  # claims 60000 x 60000 px in a tiny file
        ihdr = struct.pack(">IIBBBBB", 60000, 60000, 8, 0, 0, 0, 0)
        data = bytearray(
            b"\x89PNG\r\n\x1a\n"
            + _png_chunk(b"IHDR", ihdr)
            + _png_chunk(b"IDAT", zlib.compress(b"\0" * 100))
            + _png_chunk(b"IEND", b"")
        )
    return bytes(data)


@settings(max_examples=80, **SETTINGS)
@given(data=png_bytes(), scale=st.sampled_from([None, 1.0]))
def test_fuzz_png_reader(data, scale):
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "in.png"
        p.write_bytes(data)
        tracemalloc.start()
        try:
            try:
                m = read_mask(p, um_per_px=scale)
            except InputError as err:
                assert "\n" not in str(err)
            else:
                assert (
                    np.all(np.isfinite(m.data))
                    and 0 <= m.data.min()
                    and m.data.max() <= 1
                    and m.um_per_px > 0
                )
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < MEMORY_LIMIT


@settings(max_examples=20, **SETTINGS)
@given(data=png_bytes())
def test_fuzz_png_through_the_cli(data):
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        (d / "in.png").write_bytes(data)
        rc, err, peak = run_traced(
            [
                "energy",
                "--pattern",
                "in.png",
                "--um-per-px",
                "1",
                "--chip-size",
                "5",
                "--at",
                "0,0,0",
                "--memory-budget",
                "512",
                "--json",
                "e.json",
            ],
            d,
        )
        check_run(rc, err, peak, d, {"in.png"}, {"e.json"})
