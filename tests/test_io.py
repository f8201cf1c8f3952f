"""PNG reading and writing: modes, scale (pHYs), text chunk, inversion, bad files."""

import json
import struct
import zlib

import numpy as np
import pytest
from PIL import Image

from foundation import InputError
from patterns import TEXT_KEY, read_mask, write_mask
from patterns.geometry import Mask


def chunks(path):
    """[(type, data)] of a PNG file."""
    data, out, i = path.read_bytes(), [], 8
    while i < len(data):
        (n,) = struct.unpack(">I", data[i : i + 4])
        out.append((data[i + 4 : i + 8], data[i + 8 : i + 8 + n]))
        i += 12 + n
    return out


def with_phys(path, px_x, px_y, unit):
    """Rewrite the PNG at ``path`` with a hand-made pHYs chunk right after IHDR."""
    data = path.read_bytes()
    body = b"pHYs" + struct.pack(">IIB", px_x, px_y, unit)
    chunk = struct.pack(">I", 9) + body + struct.pack(">I", zlib.crc32(body))
    path.write_bytes(data[:33] + chunk + data[33:])  # 8-byte signature + 25-byte IHDR
    return path


@pytest.fixture
def levels():
    rng = np.random.default_rng(0)
    d = rng.random((7, 9))
    d[0, 0], d[0, 1] = 0.0, 1.0
    return d


# ---------------------------------------------------------------------------- round trip


@pytest.mark.parametrize("um_per_px", [1.0, 0.5, 3.0, 0.37, 25.0])
def test_write_then_read_gives_back_mask_and_scale(tmp_path, levels, um_per_px):
    path = write_mask(tmp_path / "m.png", Mask(levels, um_per_px, params={"design": "square"}))
    back = read_mask(path)
    assert back.shape == levels.shape
    assert np.max(np.abs(back.data - levels)) <= 0.5 / 65535 + 1e-15
    assert back.um_per_px == um_per_px
    assert back.params == {"design": "square", "um_per_px": um_per_px}
    assert back.data[0, 0] == 0.0 and back.data[0, 1] == 1.0


def test_written_png_is_16_bit_grey_with_phys_in_pixels_per_metre(tmp_path, levels):
    path = write_mask(tmp_path / "m.png", Mask(levels, 0.5))
    with Image.open(path) as im:
        assert im.mode == "I;16"
    found = dict(chunks(path))
    assert found[b"pHYs"] == struct.pack(">IIB", 2_000_000, 2_000_000, 1)
    assert found[b"IHDR"][8] == 16  # bit depth
    key, text = found[b"tEXt"].split(b"\0")
    assert key.decode() == TEXT_KEY and json.loads(text)["um_per_px"] == 0.5


def test_params_argument_overrides_mask_params(tmp_path, levels):
    path = write_mask(
        tmp_path / "m.png", Mask(levels, 1.0, params={"a": 1}), params={"design": "x", "gap": 5}
    )
    assert read_mask(path).params == {"design": "x", "gap": 5, "um_per_px": 1.0}


def test_phys_alone_gives_the_rounded_scale(tmp_path):
    path = tmp_path / "m.png"
    Image.fromarray(np.full((4, 4), 255, np.uint8)).save(path)
    assert read_mask(with_phys(path, 333_333, 333_333, 1)).um_per_px == pytest.approx(
        1e6 / 333_333, rel=1e-15
    )


def test_pillow_dpi_is_read_as_phys(tmp_path):
    path = tmp_path / "m.png"
    Image.fromarray(np.full((4, 4), 255, np.uint8)).save(path, dpi=(25400, 25400))  # 1e6 px/m
    assert read_mask(path).um_per_px == 1.0


def test_explicit_scale_wins_over_phys(tmp_path, levels):
    path = write_mask(tmp_path / "m.png", Mask(levels, 2.0))
    assert read_mask(path, um_per_px=0.25).um_per_px == 0.25


# ---------------------------------------------------------------------------- modes


def save(tmp_path, im, name="in.png", **kw):
    path = tmp_path / name
    im.save(path, **kw)
    return path


def test_mode_1(tmp_path):
    a = np.array([[True, False], [False, True]])
    m = read_mask(save(tmp_path, Image.fromarray(a)), um_per_px=1)
    assert np.array_equal(m.data, a.astype(float))


def test_mode_L_keeps_grey_levels(tmp_path):
    a = np.array([[0, 51, 128, 255]], np.uint8)
    m = read_mask(save(tmp_path, Image.fromarray(a)), um_per_px=1)
    assert np.allclose(m.data, a / 255, atol=1e-15)


def test_mode_I16_scaled_by_65535(tmp_path):
    a = np.array([[0, 1, 32768, 65535]], np.uint16)
    path = save(tmp_path, Image.fromarray(a))
    with Image.open(path) as im:
        assert im.mode == "I;16"
    assert np.allclose(read_mask(path, um_per_px=1).data, a / 65535, atol=1e-15)


def test_mode_RGB_uses_luminance(tmp_path):
    a = np.array([[[255, 255, 255], [0, 0, 0], [255, 0, 0], [0, 255, 0], [0, 0, 255]]], np.uint8)
    path = save(tmp_path, Image.fromarray(a))
    m = read_mask(path, um_per_px=1, channel="luminance")
    assert m.data[0].tolist() == pytest.approx([1.0, 0.0, 0.299, 0.587, 0.114], abs=1e-12)
    assert m.data[0, 0] == 1.0
    for i, name in enumerate(("red", "green", "blue")):  # one channel, exactly
        assert (
            read_mask(path, um_per_px=1, channel=name).data[0].tolist()
            == (a[0, :, i] / 255).tolist()
        )
    with pytest.raises(
        InputError, match=r"channels differ \(by up to 255 of 255 levels\).*--channel"
    ):
        read_mask(path, um_per_px=1)  # colours that disagree: refused without a channel


def test_grey_stored_as_RGB_reads_without_a_channel(tmp_path):
    a = np.array([[[255, 255, 255], [0, 0, 0], [128, 128, 128]]], np.uint8)
    m = read_mask(save(tmp_path, Image.fromarray(a)), um_per_px=1)
    assert m.data[0].tolist() == pytest.approx([1.0, 0.0, 128 / 255], abs=1e-12)


def test_mode_RGBA_is_luminance_times_alpha(tmp_path):
    a = np.array(
        [[[255, 255, 255, 255], [255, 255, 255, 0], [255, 255, 255, 51], [128, 128, 128, 255]]],
        np.uint8,
    )
    m = read_mask(save(tmp_path, Image.fromarray(a, "RGBA")), um_per_px=1)
    assert m.data[0].tolist() == pytest.approx([1.0, 0.0, 0.2, 128 / 255], abs=1e-12)


def test_mode_LA(tmp_path):
    a = np.array([[[255, 255], [255, 0], [102, 255]]], np.uint8)
    m = read_mask(save(tmp_path, Image.fromarray(a, "LA")), um_per_px=1)
    assert m.data[0].tolist() == pytest.approx([1.0, 0.0, 0.4], abs=1e-12)


def test_mode_P_palette(tmp_path):
    im = Image.fromarray(np.array([[0, 1, 2]], np.uint8), "P")
    im.putpalette([0, 0, 0, 255, 255, 255, 255, 0, 0])
    path = save(tmp_path, im)
    with Image.open(path) as check:
        assert check.mode == "P"
    assert read_mask(path, um_per_px=1, channel="luminance").data[0].tolist() == pytest.approx(
        [0.0, 1.0, 0.299], abs=1e-12
    )


def test_mode_P_with_transparency(tmp_path):
    im = Image.fromarray(np.array([[0, 1, 2]], np.uint8), "P")
    im.putpalette([255, 255, 255] * 3)
    path = save(tmp_path, im, transparency=bytes([255, 0, 128]))
    assert read_mask(path, um_per_px=1).data[0].tolist() == pytest.approx(
        [1.0, 0.0, 128 / 255], abs=1e-12
    )


def test_grey_with_transparent_colour_is_not_wettable(tmp_path):
    path = save(tmp_path, Image.fromarray(np.array([[0, 255, 200]], np.uint8)), transparency=200)
    assert read_mask(path, um_per_px=1).data[0].tolist() == [0.0, 1.0, 0.0]


# ---------------------------------------------------------------------------- invert


def test_invert_gives_one_minus_value(tmp_path, levels):
    path = write_mask(tmp_path / "m.png", Mask(levels, 1.0))
    plain, inv = read_mask(path), read_mask(path, invert=True)
    assert np.allclose(inv.data, 1 - plain.data, atol=1e-15)


def test_invert_keeps_transparent_pixels_non_wettable(tmp_path):
    a = np.array([[[0, 0, 0, 255], [0, 0, 0, 0]]], np.uint8)  # black pad, transparent background
    m = read_mask(save(tmp_path, Image.fromarray(a, "RGBA")), um_per_px=1, invert=True)
    assert m.data[0].tolist() == [1.0, 0.0]


# ---------------------------------------------------------------------------- bad files and scales


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"nothere\.png: file does not exist"):
        read_mask(tmp_path / "nothere.png", um_per_px=1)


def test_directory_is_not_an_image(tmp_path):
    with pytest.raises(InputError, match=r"is a directory"):
        read_mask(tmp_path, um_per_px=1)


@pytest.mark.parametrize(
    "content", [b"", b"hello, not an image", b"\x89PNG\r\n\x1a\n" + b"\0" * 40]
)
def test_corrupt_file(tmp_path, content):
    path = tmp_path / "bad.png"
    path.write_bytes(content)
    with pytest.raises(InputError, match=r"bad\.png: not a readable image"):
        read_mask(path, um_per_px=1)


def test_truncated_png(tmp_path, levels):
    path = write_mask(tmp_path / "m.png", Mask(levels, 1.0))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 30])
    with pytest.raises(InputError, match=r"m\.png: not a readable image"):
        read_mask(path)


def test_no_scale(tmp_path):
    path = save(tmp_path, Image.fromarray(np.full((3, 3), 255, np.uint8)), name="plain.png")
    with pytest.raises(
        InputError, match=r"plain\.png has no scale \(pHYs chunk\); pass --um-per-px"
    ):
        read_mask(path)
    assert read_mask(path, um_per_px=2).um_per_px == 2


def test_phys_with_unknown_unit_is_only_an_aspect_ratio(tmp_path):
    path = save(tmp_path, Image.fromarray(np.full((3, 3), 255, np.uint8)), name="aspect.png")
    with pytest.raises(InputError, match=r"has no scale \(pHYs chunk\)"):
        read_mask(with_phys(path, 1000, 1000, 0))


def test_zero_phys_is_a_non_positive_scale(tmp_path):
    path = save(tmp_path, Image.fromarray(np.full((3, 3), 255, np.uint8)), name="zero.png")
    with pytest.raises(InputError, match=r"zero\.png: its pHYs chunk gives a non-positive scale"):
        read_mask(with_phys(path, 0, 0, 1))


def test_non_square_pixels(tmp_path):
    path = save(tmp_path, Image.fromarray(np.full((3, 3), 255, np.uint8)), name="rect.png")
    with pytest.raises(InputError, match=r"non-square pixels"):
        read_mask(with_phys(path, 1_000_000, 500_000, 1))


@pytest.mark.parametrize("bad", [0, -1, float("nan"), "x"])
def test_bad_explicit_scale(tmp_path, bad):
    path = save(tmp_path, Image.fromarray(np.full((3, 3), 255, np.uint8)))
    with pytest.raises(InputError, match=r"--um-per-px must be"):
        read_mask(path, um_per_px=bad)


def test_all_black_image_reads_and_callers_check_emptiness(tmp_path):
    m = read_mask(save(tmp_path, Image.fromarray(np.zeros((3, 3), np.uint8))), um_per_px=1)
    with pytest.raises(InputError, match=r"all black"):
        m.require_nonempty("pattern")


def test_write_to_missing_directory_leaves_nothing(tmp_path, levels):
    with pytest.raises(InputError, match=r"does not exist"):
        write_mask(tmp_path / "no" / "m.png", Mask(levels, 1.0))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "name,match", [("m.tif", r"must end in \.png"), ("sub.png", r"is a directory")]
)
def test_write_rejects_bad_names(tmp_path, levels, name, match):
    (tmp_path / "sub.png").mkdir()
    with pytest.raises(InputError, match=match):
        write_mask(tmp_path / name, Mask(levels, 1.0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sub.png"]


def test_write_failure_leaves_no_partial_file(tmp_path, levels, monkeypatch):
    def boom(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Image.Image, "save", boom)
    with pytest.raises(InputError, match=r"cannot write \(No space left on device\)"):
        write_mask(tmp_path / "m.png", Mask(levels, 1.0))
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- the library


def test_library_files_are_found_and_carry_their_scale():
    from patterns.library import LIBRARY, library_path

    assert len(LIBRARY) == 18
    mask = read_mask(library_path("four_pad_730_50"))
    assert mask.um_per_px == 1.0 and mask.area_um2 == 4 * 340**2
    assert mask.params["design"] == "four-pad"
    assert read_mask(library_path("defect_B_inward")).area_um2 == pytest.approx(
        40000 - 900, abs=1e-2
    )
    with pytest.raises(
        InputError, match=r"no library pattern 'hexagon'; choose one of four_pad_730_50"
    ):
        library_path("hexagon")


def test_build_library_writes_pngs_and_index(tmp_path):
    from patterns.library import LIBRARY, build_library

    index = build_library(tmp_path, overview=False)
    files = sorted(p.name for p in tmp_path.iterdir())
    assert files == sorted([f"{stem}.png" for stem, _, _ in LIBRARY] + ["index.json", "index.md"])
    on_disk = json.loads((tmp_path / "index.json").read_text())
    assert on_disk == json.loads(json.dumps(index))
    for entry in on_disk:
        mask = read_mask(tmp_path / entry["file"])
        assert mask.um_per_px == entry["um_per_px"] == 1.0
        assert mask.area_um2 == pytest.approx(entry["area_um2"], abs=0.05)
        assert all("unit" in v for v in entry["parameters"].values())
    assert "random_jagged_s8.png" in (tmp_path / "index.md").read_text()
    with pytest.raises(InputError, match=r"--out .*missing: directory does not exist"):
        build_library(tmp_path / "missing")


def test_a_16_bit_image_is_read_without_a_64_bit_copy(tmp_path):
    """Reading a 16-bit PNG holds the decoded 16-bit pixels and the float64 mask, no
    int64 copy beside them (a 16-megapixel pattern: 160 MB at the peak, not 290)."""
    import tracemalloc

    levels = np.zeros((900, 1000))
    levels[100:800, 50:950] = 1.0
    levels[400, 400] = 0.25
    path = write_mask(tmp_path / "big.png", Mask(levels, 2.0))
    tracemalloc.start()
    try:
        got = read_mask(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert got.data.dtype == np.float64
    assert np.array_equal(got.data, np.round(levels * 65535) / 65535)
    assert peak < 1.5 * got.data.nbytes


def test_a_float_image_is_read_in_0_to_1_and_refused_outside(tmp_path):
    """A 32-bit float image (a TIFF: PNG stores none) is the one kind whose values can leave
    [0, 1]: read as stored inside, refused with the fix outside or when not finite."""
    good = np.array([[0.0, 0.25], [0.5, 1.0]], np.float32)
    Image.fromarray(good, mode="F").save(tmp_path / "good.tif")
    assert np.array_equal(read_mask(tmp_path / "good.tif", um_per_px=1.0).data, good)
    for name, bad in {"high": 1.5, "negative": -0.1, "nan": np.nan, "inf": np.inf}.items():
        values = good.copy()
        values[0, 0] = bad
        Image.fromarray(values, mode="F").save(tmp_path / f"{name}.tif")
        with pytest.raises(
            InputError,
            match=r"float image with values outside \[0, 1\]; save it as 8- or 16-bit grey",
        ):
            read_mask(tmp_path / f"{name}.tif", um_per_px=1.0)
