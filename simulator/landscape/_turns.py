"""The pattern's quarter turns and its mirror y -> -y, and the arrays they move: what lets
the footprint state's planes of one pad or pair be another's turned or mirrored
(:mod:`simulator.landscape._footprint`, docs/physics.md §3.5).

A symmetry of the pattern is found pad by pad (:func:`_pattern_turns`,
:func:`_pattern_mirror`: each pad's image, compared on its moved bounding box only); the
arrays it moves are turned as views (:func:`_turn` for grids and rasters with rows y up,
:func:`_turn_image` for image rows), their boxes with them (:func:`_grid_box_turned`), and a
float raster is the same turned within :data:`SAME_CHIP_TOL` (:func:`_same_turned`), as the
chip's own symmetries are told (:mod:`simulator.landscape._symmetry`).
"""

from __future__ import annotations

import numpy as np

from ._symmetry import SAME_CHIP_TOL


def _turn(a: np.ndarray, m: int) -> np.ndarray:
    """``a`` (..., rows y up, columns x) turned by ``m`` quarter turns clockwise about its
    centre: the value at (x, y) moves to (y, -x) for m = 1 (a view)."""
    return np.rot90(a, m, axes=(-2, -1))


def _turn_image(a: np.ndarray, m: int) -> np.ndarray:
    """As :func:`_turn` for an image whose rows run down (a pattern's masks)."""
    return np.rot90(a[::-1], m)[::-1]


def _same_turned(a: np.ndarray, b: np.ndarray, m: int) -> bool:
    """Whether ``a`` turned by ``m`` (:func:`_turn`) is ``b``: booleans and integers exactly,
    float rasters within :data:`SAME_CHIP_TOL` per pixel, as the chip's own symmetries are
    told (a square chip's raster turned differs from it by at most 1.2e-14 of its largest
    value, 1, measured: its rotated coordinates are rounded in another order; a pixel read
    elsewhere by 1e-3 and more)."""
    t = _turn(a, m)
    if t.shape != b.shape:
        return False
    if not np.issubdtype(b.dtype, np.floating):
        return bool(np.array_equal(t, b))
    return bool(np.abs(t - b).max(initial=0.0) <= SAME_CHIP_TOL)


def _pad_images(masks: list, data: np.ndarray, move_box, move) -> list[int] | None:
    """The pad each pad becomes under a symmetry of the pattern, or None where one becomes
    no pad: ``move`` moves a pad's values on its box (image rows), ``move_box`` takes its box
    (r0, r1, c0, c1) where the symmetry takes it. A pad is compared only with the pads on
    its moved box, on that box (many pads of a large pattern cost their boxes, not a
    pattern each)."""
    boxes = []  # (r0, r1, c0, c1) of each pad, image rows
    for mk in masks:
        rows, cols = np.flatnonzero(mk.any(axis=1)), np.flatnonzero(mk.any(axis=0))
        boxes.append((int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1))
    by_box: dict[tuple, list[int]] = {}
    for k, b in enumerate(boxes):
        by_box.setdefault(b, []).append(k)

    def crop(k: int, box) -> np.ndarray:
        r0, r1, c0, c1 = box
        return np.where(masks[k][r0:r1, c0:c1], data[r0:r1, c0:c1], 0.0)

    image = []
    for j, b in enumerate(boxes):
        box = move_box(b)
        t = move(crop(j, b))
        hit = [k for k in by_box.get(box, []) if np.array_equal(t, crop(k, box))]
        if not hit:
            return None
        image.append(hit[0])
    return image


def _pattern_turns(masks: list, data: np.ndarray, grid) -> dict[int, list[int]]:
    """The quarter turns (m = 1, 2, 3 clockwise about the pattern's centre) that take every
    pad onto a pad, its values with it, on a pose grid that the turn takes onto itself: for
    each, the image of each pad (``images[m][j]`` = k: pad k is pad j turned;
    :func:`_pad_images`)."""
    _, ny, nx = grid.shape
    centred = 2 * grid.x_first_px + nx - 1 == 0 and 2 * grid.y_first_px + ny - 1 == 0
    if not centred or not masks:
        return {}
    h, w = data.shape
    turns: dict[int, list[int]] = {}
    for m in (1, 2, 3):
        if m % 2 and (ny != nx or h != w):
            continue
        hh = w if m % 2 else h

        def turned_box(b, m=m, hh=hh) -> tuple:
            # to rows y up, turned as the grid's, back to image rows
            y0, y1, x0, x1 = _grid_box_turned((h - b[1], h - b[0], b[2], b[3]), m, (h, w))
            return (hh - y1, hh - y0, x0, x1)

        image = _pad_images(masks, data, turned_box, lambda a, m=m: _turn_image(a, m))
        if image is not None:
            turns[m] = image
    return turns


def _pattern_mirror(masks: list, data: np.ndarray, grid) -> list[int] | None:
    """The image of each pad under the mirror y -> -y about the pattern's centre
    (``image[j]`` = k: pad k is pad j upside down, its values with it), where the mirror
    takes every pad onto a pad and the pose grid onto itself; else None
    (:func:`_pad_images`)."""
    _, ny, _ = grid.shape
    if 2 * grid.y_first_px + ny - 1 != 0 or not masks:
        return None
    h = data.shape[0]
    return _pad_images(masks, data, lambda b: (h - b[1], h - b[0], b[2], b[3]), lambda a: a[::-1])


def _grid_box_turned(box: tuple[int, int, int, int], m: int, shape) -> tuple[int, ...]:
    """The box (y0, y1, x0, x1) of a (ny, nx) grid turned by :func:`_turn`'s ``m``."""
    y0, y1, x0, x1 = box
    ny, nx = shape
    for _ in range(m % 4):  # one clockwise quarter turn: (row, col) -> (nx - 1 - col, row)
        y0, y1, x0, x1 = nx - x1, nx - x0, y0, y1
        ny, nx = nx, ny
    return y0, y1, x0, x1
