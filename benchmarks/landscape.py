"""Landscape benchmark: selfalign against the peers a user would otherwise reach for.

The job: the overlap landscape ``A[t, y, x]``, i.e. the *full linear* (zero-padded,
never circular) 2-D cross-correlation of a pattern image P (N x N, float32) with
the chip image rotated by each twist (-90..90 degrees, 1 degree steps = 181
twists by default):

    A[t, m + h - 1, n + w - 1] = sum_{k,l} chip_t[k, l] * P[k + m, l + n]

for every shift (m, n) with any overlap, an array of shape (T, N + h - 1, N + w - 1).
This is what ``cv2.matchTemplate(TM_CCORR)`` gives on P zero-padded by the chip
size minus 1 on each side, and what ``scipy.signal.correlate(P, chip, "full")`` gives.

Inputs (not timed; every method gets the same arrays): P is a four-pad pattern
filling the N x N image (pads of side (N - g)/2 around a cross-shaped gap of
g = N/10, rounded to even). The chip image is N x N with a centred square of side
0.7 N (even), rotated about the image centre, so the rotated diagonal (0.99 N)
fits: by exact area-coverage rasterization (``--chips exact``, default, what the
engine uses) or by ``cv2.warpAffine`` INTER_LINEAR (``--chips opencv``).

Peers (each a function ``(pattern, chips) -> (T, N+h-1, N+w-1)`` stack):

* ``opencv-matchTemplate``: ``cv2.matchTemplate(TM_CCORR)`` per twist on the padded
  pattern (OpenCV switches to its own tiled DFT for large templates).
* ``opencv-dft``: ``cv2.dft`` of the pattern once at ``cv2.getOptimalDFTSize``;
  per twist ``cv2.dft`` of the chip, ``cv2.mulSpectrums(conjB=True)``,
  ``cv2.idft``, then un-wrap the circular result into the full linear layout.
* ``scipy-fftconvolve``: ``scipy.signal.fftconvolve(P, chip[::-1, ::-1], "full")``
  per twist (re-transforms the pattern every time).
* ``scipy-rfft2``: ``scipy.fft.rfft2`` of the pattern once at ``next_fast_len``,
  per twist rfft2 of the flipped chip, product, irfft2, crop; ``workers=2``.
* ``naive-per-pose``: what a 2014 MATLAB simulator did for each pose: translate the
  rotated chip into a pattern-sized zero canvas, multiply by the pattern and sum,
  O(N^2) per pose. Far too slow for the full landscape, so it is timed on a random
  sample of poses (default 2000) and the time is **extrapolated** to all
  T (2N-1)^2 poses (marked "extrap." in the table).
* ``scipy-rfft2-f64``: the float64 reference (same algorithm as scipy-rfft2 in
  float64); errors of every method are measured against it.
* ``selfalign`` / ``selfalign-jax``: the hook :func:`selfalign_method`, which calls
  ``simulator.landscape.correlate_stack`` (auto backend, and the JAX backend).

Measured per method, each in its own fresh ``multiprocessing`` "spawn" subprocess, all
of them alive at once: the timed calls go round the methods in turn (A B C, A B C, ...),
so that a shared machine's load falls on every method alike and the ratios of one run
hold (the best and every timed call are kept):

* total seconds for the whole stack (pattern transforms and padding included,
  chip rotation not), and ms per twist; the process's CPU seconds (all its threads) of
  its least-CPU call, which a shared machine's load moves less than the wall time;
* peak memory: the rise of the process's peak RSS over its RSS just before the
  call (Linux VmHWM, reset through /proc/self/clear_refs when allowed, else the
  ``ru_maxrss`` delta). It includes the output stack, listed separately;
* max |A - A_ref| / chip area on a sample of twists (default 12) against the
  float64 reference, i.e. the error in units of "whole chip overlaps".

Every method (but the sampled naive one) is called once to warm up (JIT compiling
on the JAX backend, FFT plans, first touch of memory; its time is in the notes), the
warm-ups one after another, then timed on the best of ``--repeats`` rounds (default 3):
the machine is shared and single timings move by up to 2x. Thread counts: OpenCV uses its default pool (all cores),
scipy-rfft2 ``workers=2``, fftconvolve and the naive loop one thread.

Usage::

    python benchmarks/landscape.py [--sizes 512 1024] [--twists 181]
        [--large-twists 46] [--methods NAME ...] [--chips exact opencv]
        [--pattern four-pad|four-pad-notch] [--repeats 3] [--json OUT]

``--smoke OUT``: N = 64 at 5 twists, one timed round of scipy-rfft2, selfalign and the
naive loop (on 50 poses), exact chips, the meniscus row at 20 um/px; the table goes to OUT
and the rows as JSON beside it (OUT with .json).

``--chips`` takes one kind or both (the default): each kind is its own run of every
method, with its own ratios.

At sizes above 512 the twist count is capped at ``--large-twists`` (default 46,
every 4 degrees) to keep the default run within a few minutes on a 2-core machine
and the output stack under 1 GB; ms/twist stays comparable and the table also
gives the time extrapolated to the full twist count. ``--large-twists 0`` removes
the cap.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import math
import multiprocessing as mp
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from _memory import mark, peak_mb  # noqa: E402  (benchmarks/ is on sys.path)
from _smoke import add_smoke_arg, smoke_out, tee_stdout  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

REFERENCE = "scipy-rfft2-f64"


# ------------------------------------------------------------------------ inputs


PATTERNS = ("four-pad", "four-pad-notch")


def make_pattern(n: int, kind: str = "four-pad") -> np.ndarray:
    """Four-pad pattern filling an n x n float32 image: pads around a cross gap of ~n/10.

    ``four-pad-notch``: the same with a notch of n/16 x n/8 px cut into the top-left
    pad's outer corner, which breaks the pattern's mirror symmetry (what a fabrication
    defect does), so no engine can copy a twist's plane from its mirror twin's.
    """
    g = 2 * round(n / 20)
    p = (n - g) // 2
    img = np.zeros((n, n), np.float32)
    for r0 in (0, p + g):
        for c0 in (0, p + g):
            img[r0 : r0 + p, c0 : c0 + p] = 1.0
    if kind == "four-pad-notch":
        img[: n // 16, : n // 8] = 0.0
    return img


def chip_side(n: int) -> int:
    """Side of the square chip: 0.7 n rounded to even, so its diagonal fits in n."""
    return 2 * round(0.35 * n)


def make_chips(n: int, twists_deg: np.ndarray, kind: str = "exact") -> np.ndarray:
    """(T, n, n) float32: the centred square chip rotated by each twist (CCW).

    ``exact``: area-coverage rasterization of the rotated square (what selfalign's
    engine feeds its correlation for a chip with exact geometry); rasters 90 degrees
    apart are then the same, as they are for the real square chip.
    ``opencv``: ``cv2.warpAffine`` INTER_LINEAR of the axis-aligned raster (what a
    user rotating a chip PNG gets); rasters 90 degrees apart differ by interpolation.
    """
    if kind == "exact":
        from shapely import affinity
        from shapely.geometry import box

        from patterns.geometry import rasterize

        h = chip_side(n) / 2
        sq = box(-h, -h, h, h)
        return np.stack(
            [
                rasterize(affinity.rotate(sq, float(a), origin=(0, 0)), 1.0, shape=(n, n))
                for a in twists_deg
            ]
        ).astype(np.float32)
    import cv2

    s = chip_side(n)
    base = np.zeros((n, n), np.float32)
    o = (n - s) // 2
    base[o : o + s, o : o + s] = 1.0
    out = np.empty((len(twists_deg), n, n), np.float32)
    centre = ((n - 1) / 2.0, (n - 1) / 2.0)
    for i, a in enumerate(twists_deg):
        m = cv2.getRotationMatrix2D(centre, float(a), 1.0)
        cv2.warpAffine(base, m, (n, n), dst=out[i], flags=cv2.INTER_LINEAR, borderValue=0.0)
    return out


def full_shape(pattern: np.ndarray, chips: np.ndarray) -> tuple[int, int, int]:
    (hp, wp), (t, hc, wc) = pattern.shape, chips.shape
    return t, hp + hc - 1, wp + wc - 1


# ------------------------------------------------------------------------- peers


def opencv_match_template(pattern: np.ndarray, chips: np.ndarray) -> np.ndarray:
    import cv2

    _, hc, wc = chips.shape
    padded = cv2.copyMakeBorder(
        pattern, hc - 1, hc - 1, wc - 1, wc - 1, cv2.BORDER_CONSTANT, value=0
    )
    out = np.empty(full_shape(pattern, chips), np.float32)
    for t, chip in enumerate(chips):
        out[t] = cv2.matchTemplate(padded, chip, cv2.TM_CCORR)
    return out


def _unwrap_circular(circ: np.ndarray, dst: np.ndarray, hc: int, wc: int) -> None:
    """Write circ rolled by (hc - 1, wc - 1) and cropped to dst's shape into dst.

    ``circ[m, n] = sum chip[k, l] P[k + m, l + n]`` with negative shifts wrapped to the
    end; the full linear layout puts shift -(hc - 1) at row 0.
    """
    ny, nx = circ.shape
    H, W = dst.shape
    a, b = hc - 1, wc - 1
    dst[:a, :b] = circ[ny - a :, nx - b :]
    dst[:a, b:] = circ[ny - a :, : W - b]
    dst[a:, :b] = circ[: H - a, nx - b :]
    dst[a:, b:] = circ[: H - a, : W - b]


def opencv_dft(pattern: np.ndarray, chips: np.ndarray) -> np.ndarray:
    import cv2

    t, H, W = full_shape(pattern, chips)
    _, hc, wc = chips.shape
    ny, nx = cv2.getOptimalDFTSize(H), cv2.getOptimalDFTSize(W)
    hp, wp = pattern.shape
    pp = cv2.copyMakeBorder(pattern, 0, ny - hp, 0, nx - wp, cv2.BORDER_CONSTANT, value=0)
    pat_spec = cv2.dft(pp, nonzeroRows=hp)  # CCS-packed real spectrum
    cbuf = np.zeros((ny, nx), np.float32)
    out = np.empty((t, H, W), np.float32)
    for i, chip in enumerate(chips):
        cbuf[:hc, :wc] = chip
        spec = cv2.dft(cbuf, nonzeroRows=hc)
        prod = cv2.mulSpectrums(pat_spec, spec, 0, conjB=True)
        circ = cv2.idft(prod, flags=cv2.DFT_REAL_OUTPUT | cv2.DFT_SCALE)
        _unwrap_circular(circ, out[i], hc, wc)
    return out


def scipy_fftconvolve(pattern: np.ndarray, chips: np.ndarray) -> np.ndarray:
    from scipy.signal import fftconvolve

    out = np.empty(full_shape(pattern, chips), np.float32)
    for t, chip in enumerate(chips):
        out[t] = fftconvolve(pattern, chip[::-1, ::-1], mode="full")
    return out


def _scipy_rfft2(pattern: np.ndarray, chips: np.ndarray, dtype) -> np.ndarray:
    import scipy.fft as sfft

    t, H, W = full_shape(pattern, chips)
    shape = (sfft.next_fast_len(H, real=True), sfft.next_fast_len(W, real=True))
    pat_spec = sfft.rfft2(pattern.astype(dtype, copy=False), s=shape, workers=2)
    out = np.empty((t, H, W), dtype)
    for i, chip in enumerate(chips):
        spec = sfft.rfft2(chip[::-1, ::-1].astype(dtype), s=shape, workers=2)
        spec *= pat_spec
        out[i] = sfft.irfft2(spec, s=shape, workers=2)[:H, :W]
    return out


def scipy_rfft2(pattern: np.ndarray, chips: np.ndarray) -> np.ndarray:
    return _scipy_rfft2(pattern, chips, np.float32)


def scipy_rfft2_f64(pattern: np.ndarray, chips: np.ndarray) -> np.ndarray:
    return _scipy_rfft2(pattern, chips, np.float64)


def naive_poses(pattern: np.ndarray, chips: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """The 2014-style evaluation: per pose, shift the chip into a zero canvas, multiply, sum.

    ``poses`` is (K, 3) integer (t, row, col) indices into the full landscape.
    """
    hp, wp = pattern.shape
    _, hc, wc = chips.shape
    vals = np.empty(len(poses), np.float64)
    canvas = np.empty_like(pattern)
    for i, (t, r, c) in enumerate(poses):
        m, n = r - (hc - 1), c - (wc - 1)  # pattern row/col under chip row/col 0
        canvas.fill(0.0)
        r0, r1 = max(m, 0), min(m + hc, hp)
        c0, c1 = max(n, 0), min(n + wc, wp)
        canvas[r0:r1, c0:c1] = chips[t, r0 - m : r1 - m, c0 - n : c1 - n]
        vals[i] = np.sum(pattern * canvas, dtype=np.float64)
    return vals


# ------------------------------------------------------- selfalign hook (lead's API)


def selfalign_method(
    pattern: np.ndarray, chips: np.ndarray, backend: str | None = None
) -> np.ndarray:
    """HOOK: selfalign's own correlation, ``simulator.landscape.correlate_stack``.

    Expected signature: ``correlate_stack(pattern (H, W), chips (T, h, w), dtype)
    -> (T, H + h - 1, W + w - 1)`` in the layout of this module's docstring.
    Raises ImportError when it is not available (the method is then skipped).
    """
    from simulator.landscape import correlate_stack

    if backend is None:
        return np.asarray(correlate_stack(pattern, chips, "float32"))
    return np.asarray(correlate_stack(pattern, chips, "float32", backend=backend))


def selfalign_jax_method(pattern: np.ndarray, chips: np.ndarray) -> np.ndarray:
    return selfalign_method(pattern, chips, backend="jax")


METHODS = {
    "opencv-matchTemplate": opencv_match_template,
    "opencv-dft": opencv_dft,
    "scipy-fftconvolve": scipy_fftconvolve,
    "scipy-rfft2": scipy_rfft2,
    "naive-per-pose": None,  # special: sampled poses, extrapolated
    REFERENCE: scipy_rfft2_f64,
    "selfalign": selfalign_method,
    "selfalign-jax": selfalign_jax_method,
}


# ------------------------------------------------------------------ measurement


def _error_twists(t: int, k: int) -> np.ndarray:
    return np.unique(np.linspace(0, t - 1, min(k, t)).round().astype(int))


def _reference_at(pattern: np.ndarray, chips: np.ndarray, idx: np.ndarray) -> np.ndarray:
    return scipy_rfft2_f64(pattern, chips[idx])


def _serve(
    conn,
    name: str,
    n: int,
    twists: list[float],
    err_twists: int,
    chips_kind: str = "exact",
    pattern_kind: str = "four-pad",
) -> None:
    """One method in this (fresh) process: warm up, then one timed call per "time" request,
    and on "finish" the row (seconds = the best call, every call in ``times_s``)."""
    import cv2  # noqa: F401  (import cost outside the timed region)
    import scipy.fft  # noqa: F401
    import scipy.signal  # noqa: F401

    tw = np.asarray(twists, np.float64)
    pattern = make_pattern(n, pattern_kind)
    chips = make_chips(n, tw, chips_kind)
    t, H, W = full_shape(pattern, chips)
    row = {"N": n, "method": name, "twists": t, "chips": chips_kind, "notes": []}
    fn = METHODS[name]
    try:
        # One warm-up call (JIT compiling, FFT plans, first touch of pages).
        t0 = time.perf_counter()
        fn(pattern, chips)
        row["notes"].append(f"warm-up call {time.perf_counter() - t0:.2f} s")
    except ImportError as err:
        row["skipped"] = f"not available: {err}"
    except TypeError as err:
        row["skipped"] = f"signature mismatch: {err}"
    conn.send(row.get("skipped"))
    if "skipped" in row:
        return
    before = mark()
    times, cpu, out = [], [], None
    while conn.recv() == "time":
        out = None
        c0, t0 = time.process_time(), time.perf_counter()
        out = fn(pattern, chips)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        conn.send(times[-1])
    if out is None:
        conn.send({**row, "skipped": "no timed call"})
        return
    row["peak_mb"] = peak_mb(before)
    row.update(
        seconds=min(times),
        times_s=[round(x, 4) for x in times],
        cpu_s=min(cpu),
        extrapolated=False,
        out_mb=out.nbytes / 2**20,
        dtype=str(out.dtype),
    )
    if out.shape != (t, H, W):
        row["notes"].append(f"wrong shape {out.shape}, expected {(t, H, W)}")
        row["max_err_per_area"] = math.nan
    else:
        area = float(chips[0].sum(dtype=np.float64))
        eidx = _error_twists(t, err_twists)
        ref = _reference_at(pattern, chips, eidx)
        err = np.max(np.abs(out[eidx].astype(np.float64) - ref))
        row["max_err_per_area"] = float(err / area)
    conn.send(row)


def _naive(
    n: int,
    twists: list[float],
    err_twists: int,
    samples: int,
    seed: int,
    chips_kind: str = "exact",
    pattern_kind: str = "four-pad",
) -> dict:
    """The naive per-pose loop on a sample of poses in this (fresh) process, extrapolated."""
    tw = np.asarray(twists, np.float64)
    pattern = make_pattern(n, pattern_kind)
    chips = make_chips(n, tw, chips_kind)
    t, H, W = full_shape(pattern, chips)
    area = float(chips[0].sum(dtype=np.float64))
    eidx = _error_twists(t, err_twists)
    row = {"N": n, "method": "naive-per-pose", "twists": t, "chips": chips_kind, "notes": []}
    rng = np.random.default_rng(seed)
    poses = np.column_stack(
        [rng.choice(eidx, samples), rng.integers(0, H, samples), rng.integers(0, W, samples)]
    )
    before = mark()
    t0 = time.perf_counter()
    vals = naive_poses(pattern, chips, poses)
    dt = time.perf_counter() - t0
    row["peak_mb"] = peak_mb(before)
    total = dt / samples * t * H * W
    row.update(seconds=total, extrapolated=True, out_mb=0.0)
    row["notes"].append(f"{samples} poses in {dt:.2f} s, extrapolated to {t * H * W:.3g} poses")
    ref = _reference_at(pattern, chips, eidx)
    pos = {int(k): i for i, k in enumerate(eidx)}
    exact = ref[[pos[int(k)] for k in poses[:, 0]], poses[:, 1], poses[:, 2]]
    row["max_err_per_area"] = float(np.max(np.abs(vals - exact)) / area)
    return row


def run_naive(n: int, twists: np.ndarray, chips_kind: str, args: argparse.Namespace) -> dict:
    ctx = mp.get_context("spawn")
    with cf.ProcessPoolExecutor(max_workers=1, mp_context=ctx) as pool:
        fut = pool.submit(
            _naive,
            n,
            list(map(float, twists)),
            args.error_twists,
            args.samples,
            args.seed,
            chips_kind,
            args.pattern,
        )
        return fut.result()


def run_interleaved(
    names: list[str], n: int, twists: np.ndarray, chips_kind: str, args: argparse.Namespace
) -> list[dict]:
    """Every method in its own fresh process, warmed up one after another, then timed in
    rounds: one call of each method per round, ``args.repeats`` rounds."""
    ctx = mp.get_context("spawn")
    procs, rows = {}, {}
    try:
        for name in names:
            print(f"[N={n}, {chips_kind} chips] {name}: warm-up ...", file=sys.stderr, flush=True)
            mine, theirs = ctx.Pipe()
            p = ctx.Process(
                target=_serve,
                args=(
                    theirs,
                    name,
                    n,
                    list(map(float, twists)),
                    args.error_twists,
                    chips_kind,
                    args.pattern,
                ),
            )
            p.start()
            try:
                skipped = mine.recv()
            except EOFError:
                skipped = "subprocess died (out of memory?)"
            if skipped:
                print(f"  skipped: {skipped}", file=sys.stderr)
                p.join()
                rows[name] = {"N": n, "method": name, "twists": len(twists), "skipped": skipped}
                continue
            procs[name] = (p, mine)
        for k in range(args.repeats):
            for name, (_, conn) in list(procs.items()):
                try:
                    conn.send("time")
                    dt = conn.recv()
                except (EOFError, BrokenPipeError):
                    rows[name] = {
                        "N": n,
                        "method": name,
                        "twists": len(twists),
                        "skipped": "subprocess died (out of memory?)",
                    }
                    del procs[name]
                    continue
                print(f"  round {k + 1}: {name} {dt:.3f} s", file=sys.stderr, flush=True)
        for name, (p, conn) in procs.items():
            conn.send("finish")
            rows[name] = conn.recv()
            p.join()
    finally:
        for p, _ in procs.values():
            if p.is_alive():
                p.terminate()
    return [rows[name] for name in names if name in rows]


# ------------------------------------------------------------------------ report


def _fmt(x: float, spec: str) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


def table(rows: list[dict], full_twists: int) -> str:
    head = (
        f"| N | chips | method | twists | total s | ms/twist | s for {full_twists} twists | "
        "peak MB (out MB) | max err / chip area | notes |"
    )
    lines = [head, "|---|---|---|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        chips = r.get("chips", "-")
        if "skipped" in r:
            lines.append(
                f"| {r['N']} | {chips} | {r['method']} | {r['twists']} | - | - | - | - | - | skipped: {r['skipped']} |"
            )
            continue
        per = r["seconds"] / r["twists"]
        extrap = " (extrap.)" if r["extrapolated"] else ""
        scaled = per * full_twists
        scaled_s = _fmt(scaled, ".3g") + (
            " (extrap.)" if r["extrapolated"] or r["twists"] != full_twists else ""
        )
        mem = f"{r['peak_mb']:.0f} ({r['out_mb']:.0f})"
        times = r.get("times_s")
        notes = r["notes"] + ([f"calls {', '.join(f'{x:.3g}' for x in times)} s"] if times else [])
        if "cpu_s" in r:
            notes.append(f"CPU {r['cpu_s']:.3g} s")
        lines.append(
            f"| {r['N']} | {chips} | {r['method']} | {r['twists']} | {_fmt(r['seconds'], '.3g')}{extrap} | "
            f"{_fmt(per * 1e3, '.3g')} | {scaled_s} | {mem} | {_fmt(r['max_err_per_area'], '.2e')} | "
            f"{'; '.join(notes)} |"
        )
    return "\n".join(lines)


PEERS = ("opencv-matchTemplate", "opencv-dft", "scipy-fftconvolve", "scipy-rfft2")
CHIP_KINDS = ("exact", "opencv")


def speedups(rows: list[dict]) -> list[str]:
    """Per size and chip kind: selfalign against the fastest peer measured (time and error)."""
    out = []
    for n, kind in sorted({(r["N"], r.get("chips", "")) for r in rows}):
        done = {
            r["method"]: r
            for r in rows
            if r["N"] == n
            and r.get("chips", "") == kind
            and "skipped" not in r
            and not r.get("extrapolated")
        }
        peers = [done[m] for m in PEERS if m in done]
        if "selfalign" not in done or not peers:
            continue
        best, me = min(peers, key=lambda r: r["seconds"]), done["selfalign"]
        out.append(
            f"N = {n}, {kind} chips: selfalign {me['seconds']:.3g} s against the fastest peer, {best['method']}, "
            f"{best['seconds']:.3g} s: {best['seconds'] / me['seconds']:.2f}x, error "
            f"{me['max_err_per_area']:.2e} against {best['max_err_per_area']:.2e} of the chip area"
            + (
                f"; CPU {me['cpu_s']:.3g} s against {best['cpu_s']:.3g} s "
                f"({best['cpu_s'] / me['cpu_s']:.2f}x)"
                if "cpu_s" in me and "cpu_s" in best
                else ""
            )
        )
    return out


def machine() -> dict:
    import cv2
    import scipy

    info = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "opencv": cv2.__version__,
        "cpus": os.cpu_count(),
        "processor": platform.processor() or platform.machine(),
    }
    try:
        import jax

        info["jax"] = jax.__version__
    except ImportError:
        pass
    return info


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[512, 1024], help="image sizes N (px)")
    ap.add_argument(
        "--twists",
        type=int,
        default=181,
        help="twists from -90 to 90 degrees (181 = 1 degree steps)",
    )
    ap.add_argument(
        "--large-twists",
        type=int,
        default=46,
        help="cap on twists for N > 512 (46 = 4 degree steps; 0 = no cap)",
    )
    ap.add_argument(
        "--methods", nargs="+", default=list(METHODS), choices=list(METHODS), metavar="NAME"
    )
    ap.add_argument("--samples", type=int, default=2000, help="poses timed for naive-per-pose")
    ap.add_argument(
        "--error-twists", type=int, default=12, help="twists checked against the float64 reference"
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--chips",
        choices=CHIP_KINDS,
        nargs="+",
        default=list(CHIP_KINDS),
        help="rotated chip rasters, one kind or both (default): exact area coverage "
        "(selfalign's own; symmetric chips repeat) and cv2.warpAffine bilinear (none alike)",
    )
    ap.add_argument(
        "--pattern",
        choices=PATTERNS,
        default="four-pad",
        help="four-pad (default, mirror-symmetric) or four-pad-notch (a corner notch breaks the symmetry)",
    )
    ap.add_argument(
        "--repeats",
        type=int,
        default=3,
        help="timed calls per method after a warm-up; the best is reported",
    )
    ap.add_argument(
        "--json", type=Path, default=None, metavar="OUT", help="also write the rows as JSON"
    )
    ap.add_argument("--meniscus-only", action="store_true", help="run only the finite-meniscus row")
    add_smoke_arg(ap, "the table (and the rows as JSON beside it)")
    args = ap.parse_args(argv)
    smoke = smoke_out(ap, args.smoke)
    if smoke:
        args.sizes, args.twists, args.samples, args.error_twists, args.repeats = [64], 5, 50, 2, 1
        args.chips, args.json = ["exact"], smoke.with_suffix(".json")
        if args.methods == list(METHODS):
            args.methods = ["scipy-rfft2", "selfalign", "naive-per-pose"]
    with tee_stdout(smoke):
        return _main(args, 20.0 if smoke else 2.0)


def _main(args: argparse.Namespace, meniscus_um_per_px: float) -> int:
    if args.meniscus_only:
        print(meniscus_row(args.repeats, meniscus_um_per_px))
        return 0
    if min(args.twists, args.samples, args.error_twists, args.repeats) < 1:
        raise SystemExit("--twists, --samples, --error-twists and --repeats must be >= 1")

    rows, notes = [], []
    for n in args.sizes:
        t = args.twists
        if n > 512 and args.large_twists and t > args.large_twists:
            t = args.large_twists
            notes.append(
                f"N = {n}: {t} twists instead of {args.twists} (--large-twists); 'extrap.' totals scale ms/twist"
            )
        twists = np.linspace(-90.0, 90.0, t)
        for kind in args.chips:
            timed = [m for m in args.methods if m != "naive-per-pose"]
            rows += run_interleaved(timed, n, twists, kind, args)
            if "naive-per-pose" in args.methods:
                print(f"[N={n}, {kind} chips] naive-per-pose ...", file=sys.stderr, flush=True)
                rows.append(run_naive(n, twists, kind, args))

    info = machine()
    print(
        f"\nLandscape benchmark: full linear correlation, {args.pattern} pattern N x N float32, "
        f"{' and '.join(args.chips)} chip rasters, chip side 0.7 N, "
        f"twists -90..90 deg. Machine: {info['cpus']} CPUs, numpy {info['numpy']}, scipy {info['scipy']}, "
        f"opencv {info['opencv']}{', jax ' + info['jax'] if 'jax' in info else ''}.\n"
    )
    print(table(rows, args.twists))
    for line in speedups(rows):
        print(f"\n* {line}")
    for note in notes:
        print(f"\n* {note}")
    print(
        "* naive-per-pose: timed on a random pose sample and extrapolated; its error is on those poses."
    )
    print(
        f"* errors: max over {args.error_twists} evenly spaced twists vs {REFERENCE}, divided by the chip area (px^2)."
    )
    print("* peak MB: rise of peak RSS during the call, output stack included (in brackets).")
    mrow = meniscus_row(args.repeats, meniscus_um_per_px)
    print(f"\n{mrow}")
    if args.json:
        args.json.write_text(
            json.dumps(
                {
                    "machine": info,
                    "args": {
                        k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()
                    },
                    "rows": rows,
                },
                indent=2,
            )
        )
        print(f"\nwrote {args.json}")
    return 0


def meniscus_row(repeats: int = 3, um_per_px: float = 2.0) -> str:
    """The finite meniscus's cost as a ratio to the overlap-only landscape, in one run:
    ``build_landscape`` of the 730/50 um four-pad at 2 um/px, 730 um chip, 1 degree twists
    over the chip's period, 20 nl (h = 37.5 um), overlap only and with ``meniscus``,
    interleaved, best of ``repeats`` each."""
    from dataclasses import replace

    from simulator.landscape import build_landscape
    from simulator.scene import Scene

    base = Scene.from_inputs(
        ROOT / "patterns/library/four_pad_730_50.png", chip_size_um=730, resolution_um=um_per_px
    )
    men = base.replace(effects=replace(base.effects, meniscus=True))
    build_landscape(base), build_landscape(men)  # warm-up
    t = {"overlap": [], "meniscus": []}
    for _ in range(max(1, repeats)):
        for name, sc in (("overlap", base), ("meniscus", men)):
            t0 = time.perf_counter()
            build_landscape(sc)
            t[name].append(time.perf_counter() - t0)
    a, b = min(t["overlap"]), min(t["meniscus"])
    return (
        f"meniscus row: four_pad_730_50 at {um_per_px:g} um/px, {base.twist_axis.count} twists, h = {men.meniscus_height_um:.1f} um: "
        f"overlap {a:.2f} s, meniscus {b:.2f} s, ratio {b / a:.2f} (best of {max(1, repeats)}, interleaved)"
    )


if __name__ == "__main__":
    raise SystemExit(main())
