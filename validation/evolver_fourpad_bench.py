#!/usr/bin/env python3
"""Surface Evolver: the bench's protocol on the four-pad pattern (droplet first, chip released offset).

Companion of ``validation/evolver_fourpad.py`` (imported as a module, not modified; the same
model: chip of side L = 730 um over a four-pad pattern of outer size 730 um with a cross-shaped
gap g = 50 or 100 um, pads 30 deg, substrate 60 deg, C1-smoothed wettability steps of 4 um,
contact-line wetting integral by Green's theorem, chip edges pinned, free chip height
``chipz``, V = 2.0e7 um^3 = 20 nl, gamma = 0.072 N/m, F_x and F_y by the harness's in-run
envelope derivative, F_x also by its +-2.5 um relaxed finite difference).

What differs is the **initial surface**.  On the bench the 20 nl droplet is dispensed on the
pattern first (above the critical volume it wets all four pads), then the chip is released
on it at a placement offset.  So every pose here is a separate Evolver run (no continuation)
whose starting liquid covers the union of the pattern square and the chip footprint: ruled
walls go from the chip edges (at the height that gives the volume) down to the outline of
that union, so the far pads start wet.  The chip is held at the pose (x, y) (twist 0), its
height is free, and the surface is relaxed (a long conjugate-gradient pre-relaxation at the
starting mesh, then the harness's schedule: ``r; qrelax`` per level, ``qrelax; qreport``).

Two variants bound what contact-angle hysteresis can do:

* ``free``: the whole substrate contact line is free (no hysteresis: receding angle = the
  equilibrium angle).  The far pads may de-wet.
* ``held``: the contact-line vertices on the far pads' outer edges (the part of the
  pattern's outer boundary that belongs to the far pads, and the gap ends between two far
  pads) are fixed there (the limit of a receding angle near 0: the line cannot recede from
  the far pads; it is also kept from advancing beyond the pattern edge there, which a
  30/60 deg step does anyway for apparent angles below 60 deg).  The rest of the line is free.
  The fixed edges stay on the wetting constraint, so both variants have the same energy
  functional.

Far pads: for a pose along x (y = 0) the left pads (x <= -g/2); for the diagonal pose
(300, -300) the three pads other than the one under the chip's centre (top-left, top-right,
bottom-left).  ``far_wet_area_um2`` is the wetted area on the far pads outside the chip
footprint (sharp pads, polygon clipping of the contact line); ``far_pads_wet`` is that area
> 1 um^2 (the harness's ``left_pads_wetted`` threshold; for the x poses it is the same
quantity).  ``z_min_free_um`` is the lowest free vertex off the contact line (with its x, y
where recorded): a value near 0 means the liquid surface touches the substrate away from the
contact line (nothing keeps it above z = 0); the plain runs reach -0.13 um at worst. Six of
the twelve relaxed free runs (``free-long``) pass more than ``TOUCH_TOL_UM`` below it, down to
-52 um: touch-downs the run cannot make (a new contact line), their rows reported not valid.

Output: ``validation/evolver_fourpad_bench.csv`` (one row per gap, variant, pose and level;
rewritten atomically after every pose) and ``validation/FOURPAD_BENCH.md`` (``--report``).

Run (as the stored files were made; each Evolver process under ``nice``)::

    nice -n 10 python validation/evolver_fourpad_bench.py --gaps 50,100 --levels 1 --variants free,held
    nice -n 10 python validation/evolver_fourpad_bench.py --gaps 50,100 --levels 2 --append
    nice -n 10 python validation/evolver_fourpad_bench.py --gaps 50,100 --levels 1 --variants free \
        --pre-max 400 --tag long --append
    python validation/evolver_fourpad_bench.py --report

Diagnostic (``--trace N``): a level-0 relaxation trace of N pre-relaxation rounds, printed
every 5 rounds (energy, chip height, leftmost contact-line x, pressure), to see whether the far
pads' liquid is still draining.

Runtime: level 1 took 45-290 s per pose (mostly 120-250 s) on the shared 2-core machine under
a load average of 6-8; a level-2 pose takes several times longer, so level 2 was run for one
pose only (see the page).  A ``--trace 90`` run takes 2-4 min.  Stdlib + numpy (through the
harness).

Status of the stored numbers (details on the page): the free-variant rows are NOT equilibria
(the far pads' liquid was still draining when the pre-relaxation stopped); the held-variant
rows at x >= 500 um are not converged (the chip sinks); the rest are level-1 values.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import math
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.dont_write_bytecode = True  # leave validation/__pycache__ alone
sys.path.insert(0, str(HERE))
import evolver_fourpad as ef  # noqa: E402
import numpy as np  # noqa: E402

OUT = HERE / "evolver_fourpad_bench.csv"
OUTWARD_LEVELS = HERE / "evolver_fourpad_levels.csv"
MD = HERE / "FOURPAD_BENCH.md"
NOTES_MARK = "<!-- notes: text below this line is kept when the report is regenerated -->"

L_CHIP = 730.0
VOLUME = 2.0e7
X_POSES = ((400.0, 0.0), (450.0, 0.0), (500.0, 0.0), (550.0, 0.0), (600.0, 0.0), (300.0, -300.0))
ROW_LEN = 50.0  # um: horizontal run per row of quads on the starting walls
PRE_G = 20  # conjugate-gradient steps per pre-relaxation round (then u; V; Newton loop)
PRE_MAX = 20  # at most this many rounds
PRE_TOL = 1.0  # gamma um^2: stop the pre-relaxation when a round lowers E by less
TOUCH_TOL_UM = 1.0  # um: a free vertex lower than this below z = 0 is a touch-down the run missed
TOL = 1e-6  # geometric tolerance (um)


# ----------------------------------------------------------------------------
# geometry of the starting surface


def union_outline(a: float, x0: float, y0: float) -> list[tuple[float, float]]:
    """Counter-clockwise outline of the union of the pattern square [-a, a]^2 and the chip
    footprint [x0-a, x0+a] x [y0-a, y0+a] (axis-aligned), without collinear vertices."""
    xs = sorted({-a, a, x0 - a, x0 + a})
    ys = sorted({-a, a, y0 - a, y0 + a})

    def inside(px: float, py: float) -> bool:
        return (abs(px) < a and abs(py) < a) or (abs(px - x0) < a and abs(py - y0) < a)

    nx, ny = len(xs) - 1, len(ys) - 1
    cell = [
        [inside((xs[i] + xs[i + 1]) / 2, (ys[j] + ys[j + 1]) / 2) for j in range(ny)]
        for i in range(nx)
    ]

    def filled(i: int, j: int) -> bool:
        return 0 <= i < nx and 0 <= j < ny and cell[i][j]

    nxt: dict[tuple[float, float], tuple[float, float]] = {}
    for i in range(nx):
        for j in range(ny):
            if not cell[i][j]:
                continue
            x_a, x_b, y_a, y_b = xs[i], xs[i + 1], ys[j], ys[j + 1]
            if not filled(i, j - 1):
                nxt[(x_a, y_a)] = (x_b, y_a)
            if not filled(i + 1, j):
                nxt[(x_b, y_a)] = (x_b, y_b)
            if not filled(i, j + 1):
                nxt[(x_b, y_b)] = (x_a, y_b)
            if not filled(i - 1, j):
                nxt[(x_a, y_b)] = (x_a, y_a)
    start = min(nxt)
    loop = [start]
    while True:
        q = nxt[loop[-1]]
        if q == start:
            break
        loop.append(q)
    out = []
    for k, q in enumerate(loop):
        p0, p1 = loop[k - 1], loop[(k + 1) % len(loop)]
        cross = (q[0] - p0[0]) * (p1[1] - q[1]) - (q[1] - p0[1]) * (p1[0] - q[0])
        if abs(cross) > TOL:
            out.append(q)
    return out


def _on_segment(q, p0, p1) -> bool:
    d = math.dist(p0, p1)
    return (
        abs(math.dist(p0, q) + math.dist(q, p1) - d) < 1e-9
        and math.dist(p0, q) > TOL
        and math.dist(q, p1) > TOL
    )


def with_breakpoints(
    outline: list[tuple[float, float]], a: float, g: float
) -> list[tuple[float, float]]:
    """Insert the pattern's outer corners and the ends of the gap arms where they lie inside an
    outline edge, so that every pad/gap boundary on the outline is a mesh vertex."""
    b = g / 2
    cand = [(sx * a, sy * a) for sx in (-1, 1) for sy in (-1, 1)]
    cand += [(s * b, t * a) for s in (-1, 1) for t in (-1, 1)] + [
        (t * a, s * b) for s in (-1, 1) for t in (-1, 1)
    ]
    out: list[tuple[float, float]] = []
    for k, p0 in enumerate(outline):
        p1 = outline[(k + 1) % len(outline)]
        out.append(p0)
        pts = [q for q in cand if _on_segment(q, p0, p1)]
        pts.sort(key=lambda q: math.dist(p0, q))
        out += pts
    return out


def chip_ring(a: float, n_side: int) -> list[tuple[float, float]]:
    """Chip-edge points in chip-local coordinates, the harness's order (CCW from (-a, -a))."""
    L = 2 * a
    pts = [(-a + L * i / n_side, -a) for i in range(n_side)]
    pts += [(a, -a + L * i / n_side) for i in range(n_side)]
    pts += [(a - L * i / n_side, a) for i in range(n_side)]
    pts += [(-a, a - L * i / n_side) for i in range(n_side)]
    return pts


def bottom_ring(a: float, g: float, x0: float, y0: float, n_side: int) -> list[tuple[float, float]]:
    """Contact-line points of the starting surface: for chip side j (corner j -> j + 1), the
    union outline between the anchors of the two corners, with n_side segments spread over its
    pieces by length (at least one each), so every outline vertex and breakpoint is a point."""
    outl = with_breakpoints(union_outline(a, x0, y0), a, g)
    corners = [(x0 - a, y0 - a), (x0 + a, y0 - a), (x0 + a, y0 + a), (x0 - a, y0 + a)]
    signs = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    anchors = []
    for c, (sx, sy) in zip(corners, signs, strict=True):
        hit = [k for k, q in enumerate(outl) if math.dist(q, c) < TOL]
        if hit:
            anchors.append(hit[0])
        else:
            best = max(sx * q[0] + sy * q[1] for q in outl)
            ks = [k for k, q in enumerate(outl) if sx * q[0] + sy * q[1] > best - TOL]
            anchors.append(min(ks, key=lambda k: math.dist(outl[k], c)))
    ring: list[tuple[float, float]] = []
    n = len(outl)
    for j in range(4):
        k0, k1 = anchors[j], anchors[(j + 1) % 4]
        path = [outl[k0]]
        k = k0
        while k != k1:
            k = (k + 1) % n
            path.append(outl[k])
        lens = [math.dist(path[i], path[i + 1]) for i in range(len(path) - 1)]
        if not lens or len(lens) > n_side:
            raise ValueError(f"cannot map chip side {j} onto the outline ({len(lens)} pieces)")
        tot = sum(lens)
        alloc = [max(1, round(n_side * s / tot)) for s in lens]
        while sum(alloc) > n_side:
            i = max(range(len(alloc)), key=lambda i: (alloc[i] > 1, alloc[i] / lens[i]))
            alloc[i] -= 1
        while sum(alloc) < n_side:
            i = max(range(len(alloc)), key=lambda i: lens[i] / alloc[i])
            alloc[i] += 1
        for i, s in enumerate(alloc):
            (xa, ya), (xb, yb) = path[i], path[i + 1]
            ring += [(xa + (xb - xa) * t / s, ya + (yb - ya) * t / s) for t in range(s)]
    return ring


def pad_of(q: tuple[float, float], a: float, g: float) -> set[str] | None:
    """Pads that a point on the pattern's outer boundary belongs to: one pad, or the two pads
    on either side of a gap end; None if the point is not on the outer boundary."""
    b = g / 2
    x, y = q
    if not (abs(abs(x) - a) < TOL and abs(y) <= a + TOL) and not (
        abs(abs(y) - a) < TOL and abs(x) <= a + TOL
    ):
        return None

    def side(v: float) -> list[str]:
        if v > b - TOL:
            return ["+"]
        if v < -b + TOL:
            return ["-"]
        return ["-", "+"]

    names = {("-", "+"): "TL", ("+", "+"): "TR", ("-", "-"): "BL", ("+", "-"): "BR"}
    return {names[(sx, sy)] for sx in side(x) for sy in side(y)}


def far_pads(x0: float, y0: float) -> set[str]:
    """The far pads: all but the pads under the chip centre's quadrant (along x: the two left pads)."""
    if abs(y0) < TOL:
        return {"TL", "BL"} if x0 > 0 else {"TR", "BR"}
    q = ("T" if y0 > 0 else "B") + ("R" if x0 > 0 else "L")
    return {"TL", "TR", "BL", "BR"} - {q}


def held_mask(ring: list[tuple[float, float]], a: float, g: float, far: set[str]) -> list[bool]:
    """A contact-line point is held if it is on the pattern's outer boundary and every pad it
    belongs to is a far pad."""
    out = []
    for q in ring:
        pads = pad_of(q, a, g)
        out.append(bool(pads) and pads <= far)
    return out


def pad_rects(a: float, g: float) -> dict[str, tuple[float, float, float, float]]:
    b = g / 2
    return {"TL": (-a, -b, b, a), "TR": (b, a, b, a), "BL": (-a, -b, -a, -b), "BR": (b, a, -a, -b)}


def rect_minus_rect(r, c) -> list[tuple[float, float, float, float]]:
    """Axis-aligned rectangle r minus rectangle c, as up to four disjoint rectangles."""
    x0, x1, y0, y1 = r
    cx0, cx1, cy0, cy1 = c
    ix0, ix1, iy0, iy1 = max(x0, cx0), min(x1, cx1), max(y0, cy0), min(y1, cy1)
    if ix0 >= ix1 or iy0 >= iy1:
        return [r]
    out = []
    if y0 < iy0:
        out.append((x0, x1, y0, iy0))
    if iy1 < y1:
        out.append((x0, x1, iy1, y1))
    if x0 < ix0:
        out.append((x0, ix0, iy0, iy1))
    if ix1 < x1:
        out.append((ix1, x1, iy0, iy1))
    return out


# ----------------------------------------------------------------------------
# the Evolver data file and command file


@dataclasses.dataclass(frozen=True)
class BenchCase:
    g: float
    variant: str  # "free" or "held"
    x: float
    y: float

    @property
    def name(self) -> str:
        return f"bench_730_{self.g:g}_{self.variant}_x{self.x:g}_y{self.y:g}"

    def path(self) -> ef.Path_:
        return ef.Path_(self.name, L_CHIP, self.g, VOLUME, ((self.x, self.y),))


def geometry(c: BenchCase) -> dict:
    p = c.path()
    a = p.L / 2
    n_side = max(4, round(p.L / p.seg))
    top = chip_ring(a, n_side)
    bot = bottom_ring(a, p.g, c.x, c.y, n_side)
    assert len(top) == len(bot)
    held = held_mask(bot, a, p.g, far_pads(c.x, c.y)) if c.variant == "held" else [False] * len(bot)
    run = max(math.dist((tx + c.x, ty + c.y), b) for (tx, ty), b in zip(top, bot, strict=True))
    m = max(2, math.ceil(run / ROW_LEN))
    return {"top": top, "bot": bot, "held": held, "m": m, "n": len(top), "run": run}


def _mesh_volume_per_height(top, bot, x0, y0, m) -> float:
    """Volume of the starting mesh at chip height 1 (it scales with the height)."""
    n = len(top)
    rings = []
    for k in range(m + 1):
        t = k / m
        rings.append(
            [
                ((1 - t) * bx + t * (tx + x0), (1 - t) * by + t * (ty + y0), t)
                for (tx, ty), (bx, by) in zip(top, bot, strict=True)
            ]
        )
    vol = 0.0
    for k in range(m):
        for i in range(n):
            a, b = rings[k][i], rings[k][(i + 1) % n]
            c, d = rings[k + 1][(i + 1) % n], rings[k + 1][i]
            for tri in ((a, b, c), (a, c, d)):
                (x1, y1, z1), (x2, y2, z2), (x3, y3, z3) = tri
                area_xy = 0.5 * ((x2 - x1) * (y3 - y1) - (x3 - x1) * (y2 - y1))
                vol += (
                    area_xy * (z1 + z2 + z3) / 3
                )  # outward normals: n_z > 0 on walls sloping down outward
    # chip face at z = 1 (outward normal +z)
    xs = np.array([tx + x0 for tx, _ in top])
    ys = np.array([ty + y0 for _, ty in top])
    vol += 0.5 * float(np.sum(xs * np.roll(ys, -1) - np.roll(xs, -1) * ys))
    return vol


def datafile(c: BenchCase) -> str:
    """Evolver datafile: walls ruled from the chip edges (boundary 1, fixed) down to the
    contact-line ring on the union outline (constraint 1; held points fixed), m rows of quads."""
    p = c.path()
    geo = geometry(c)
    top, bot, held, m, n = geo["top"], geo["bot"], geo["held"], geo["m"], geo["n"]
    x0, y0 = c.x, c.y
    h = p.volume / _mesh_volume_per_height(top, bot, x0, y0, m)
    iv = ef._pad_intervals(p.L, p.g)
    P = " + ".join(ef._indicator("x", lo, hi, p.delta) for lo, hi in iv)
    Q = " + ".join(ef._integral("y", lo, hi, p.delta) for lo, hi in iv)

    def vid(k: int, i: int) -> int:
        return k * n + (i % n) + 1

    out = [
        f"// {p.name}: four-pad L={p.L:g} g={p.g:g} V={p.volume:g}; start wetting the union of pattern "
        f"and chip footprint; variant {c.variant} ({sum(held)} held contact-line points); {m} rows",
        f"parameter xshift = {x0!r}",
        f"parameter yshift = {y0!r}",
        f"optimizing_parameter chipz = {h!r}",
        f"parameter cp = cos({p.theta_p!r}*pi/180)",
        f"parameter cs = cos({p.theta_s!r}*pi/180)",
        "gravity_constant 0",
        "boundary 1 parameters 2",
        "x1: p1 + xshift",
        "x2: p2 + yshift",
        "x3: chipz",
        "",
        "constraint 1",
        "formula: x3 = 0",
        "energy:",
        f"e1: cs*y + (cp-cs)*({P})*({Q})",
        "e2: 0",
        "e3: 0",
        "",
        "vertices",
    ]
    for k in range(m + 1):
        t = k / m
        for i in range(n):
            (tx, ty), (bx, by) = top[i], bot[i]
            if k == 0:
                out.append(
                    f"{vid(k, i)} {bx!r} {by!r} 0 constraint 1" + (" fixed" if held[i] else "")
                )
            elif k == m:
                out.append(f"{vid(k, i)} {tx!r} {ty!r} boundary 1 fixed")
            else:
                out.append(
                    f"{vid(k, i)} {(1 - t) * bx + t * (tx + x0)!r} {(1 - t) * by + t * (ty + y0)!r} {t * h!r}"
                )
    edge_id: dict[tuple[int, int], int] = {}
    edges: list[str] = []

    def add(u: int, v: int, attr: str = "") -> None:
        edge_id[(u, v)] = len(edges) + 1
        edges.append(f"{len(edges) + 1} {u} {v} {attr}".rstrip())

    def signed(u: int, v: int) -> int:
        return edge_id[(u, v)] if (u, v) in edge_id else -edge_id[(v, u)]

    for k in range(m + 1):
        for i in range(n):
            if k == 0:
                attr = "constraint 1" + (" fixed" if held[i] and held[(i + 1) % n] else "")
            else:
                attr = "boundary 1 fixed" if k == m else ""
            add(vid(k, i), vid(k, i + 1), attr)
    for k in range(m):
        for i in range(n):
            add(vid(k, i), vid(k + 1, i))
            if (i + k) % 2 == 0:
                add(vid(k, i), vid(k + 1, i + 1))
            else:
                add(vid(k, i + 1), vid(k + 1, i))
    faces: list[str] = []
    for k in range(m):
        for i in range(n):
            a_, b_, c_, d_ = vid(k, i), vid(k, i + 1), vid(k + 1, i + 1), vid(k + 1, i)
            tris = (
                [(a_, b_, c_), (a_, c_, d_)] if (i + k) % 2 == 0 else [(a_, b_, d_), (b_, c_, d_)]
            )
            for tri in tris:
                faces.append(" ".join(str(signed(tri[j], tri[(j + 1) % 3])) for j in range(3)))
    topf = " ".join(str(signed(vid(m, i), vid(m, i + 1))) for i in range(n))
    faces.append(f"{topf} density 0 boundary 1 fixed")
    out += ["", "edges", *edges, "", "faces"]
    out += [f"{j + 1} {f}" for j, f in enumerate(faces)]
    body = " ".join(str(j + 1) for j in range(len(faces)))
    out += ["", "bodies", f"1 {body} volume {p.volume!r}", "", "read", ""]
    return "\n".join(out)


_VARS = "qzmin := 0; qzx := 0; qzy := 0; qpe := 0; qpd := 0; qpn := 0\n"
_PRE = """\
qpre := {{ qpn := 0; qpd := 1e30;
  while (abs(qpd) > {tol!r} and qpn < {nmax}) do {{ qpe := total_energy; g {ng}; u; V; qconv; qpd := total_energy - qpe; qpn := qpn + 1 }};
  printf "PRE rounds=%d lastdE=%.6g E=%.12g Z=%.8g\\n", qpn, qpd, total_energy, chipz }}
"""
_HARNESS_START = "U; g 50; u; V; g 50; qconv\n"
_PRINT_TAIL = 'DHM=%.4g\\n", '
_ARGS_TAIL = "qdfp, qdfm;"


def command_file(p: ef.Path_, s: ef.Schedule) -> str:
    """The harness's command file, with a pre-relaxation after its first relaxation and the
    lowest off-line vertex height and the pre-relaxation rounds added to its POSE line."""
    text = _harness_command_file(p, s)
    assert _HARNESS_START in text and _PRINT_TAIL in text and _ARGS_TAIL in text
    assert text.startswith("quiet on\n")
    text = "quiet on\n" + _VARS + text[len("quiet on\n") :]
    pre = _PRE.format(tol=PRE_TOL, nmax=_pre_max[0], ng=PRE_G)
    text = text.replace(_HARNESS_START, pre + _HARNESS_START + "qpre\n", 1)
    text = text.replace(
        _PRINT_TAIL, 'DHM=%.4g ZMIN=%.6g ZMINX=%.6g ZMINY=%.6g PRE=%d PREDE=%.6g\\n", ', 1
    )
    text = text.replace(_ARGS_TAIL, "qdfp, qdfm, qzmin, qzx, qzy, qpn, qpd;", 1)
    text = text.replace(
        "qreport := {",
        "qreport := { qzmin := min(vertex where not fixed and not on_constraint 1, z); "
        "qzx := avg(vertex where not fixed and not on_constraint 1 and z <= qzmin, x); "
        "qzy := avg(vertex where not fixed and not on_constraint 1 and z <= qzmin, y);",
        1,
    )
    return text


_harness_command_file = ef.command_file
_harness_datafile = ef.datafile
_pre_max = [PRE_MAX]  # --pre-max changes it for a diagnostic run


def trace(c: BenchCase, rounds: int, every: int = 5) -> list[dict[str, float]]:
    """Relaxation trace at the starting mesh (level 0): the harness's first steps, then
    ``rounds`` pre-relaxation rounds (``g 20; u; V;`` Newton loop, no stopping test), printing
    E, chip height, pressure and the leftmost contact-line x every ``every`` rounds."""
    import subprocess
    import tempfile

    head = command_file(c.path(), ef.Schedule(level=0)).split(_HARNESS_START)[0]
    body = (
        'qx := 0\nqpr := { qx := min(vertex where on_constraint 1, x); printf "R %d E=%.6f Z=%.6f XMIN=%.4f '
        'P=%.8f T=%.2f\\n", qpn, total_energy, chipz, qx, body[1].pressure, clock }\n'
        + _HARNESS_START
        + "qpn := 0; qpr\n"
        + f"for (qpn := 1; qpn <= {rounds}; qpn += 1) {{ g {PRE_G}; u; V; qconv; if qpn % {every} == 0 then qpr }}\n"
        + "quit 0\n"
    )
    out = []
    with tempfile.TemporaryDirectory(prefix="selfalign_bench_trace_") as tmp:
        (Path(tmp) / "case.fe").write_text(datafile(c))
        (Path(tmp) / "case.cmd").write_text(head + body)
        proc = subprocess.run(
            [ef.find_evolver(), "-x", "-f", "case.cmd", "case.fe"],
            cwd=tmp,
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
        )
        for line in proc.stdout.splitlines():
            if line.startswith("R "):
                parts = line.split()
                rec = {"round": float(parts[1])}
                rec.update({k: float(v) for k, _, v in (t.partition("=") for t in parts[2:])})
                out.append(rec)
                print(line, flush=True)
        if proc.returncode:
            print(proc.stdout[-2000:], file=sys.stderr)
    return out


# ----------------------------------------------------------------------------
# rows

COLUMNS = (
    "gap_um",
    "variant",
    "x_um",
    "y_um",
    "level",
    "force_x_N",
    "force_y_N",
    "force_x_fd_N",
    "energy_gamma_um2",
    "energy_J",
    "area_um2",
    "chip_z_um",
    "far_pads",
    "far_pads_wet",
    "far_wet_area_um2",
    "far_region_um2",
    "far_wet_frac",
    "wet_TL_um2",
    "wet_TR_um2",
    "wet_BL_um2",
    "wet_BR_um2",
    "wet_area_um2",
    "xmin_y0_um",
    "xmax_y0_um",
    "cl_xmin_um",
    "cl_xmax_um",
    "z_min_free_um",
    "z_min_x_um",
    "z_min_y_um",
    "held_points",
    "rows0",
    "pre_rounds",
    "pre_last_dE",
    "pressure_per_um",
    "volume_um3_measured",
    "vertices",
    "facets",
    "last_newton_dE",
    "newton_settled",
    "flag",
    "seconds",
    "L_um",
    "volume_um3",
    "theta_pad_deg",
    "theta_sub_deg",
    "delta_um",
)


def far_stats(edges: np.ndarray, c: BenchCase) -> dict[str, float]:
    a, g = L_CHIP / 2, c.g
    poly = ef._chain(edges)
    rects = pad_rects(a, g)
    out = {}
    for k, r in rects.items():
        out[f"wet_{k}_um2"] = abs(ef._area(ef._clip(poly, *r)))
    chip = (c.x - a, c.x + a, c.y - a, c.y + a)
    far_wet = far_area = 0.0
    for k in sorted(far_pads(c.x, c.y)):
        for r in rect_minus_rect(rects[k], chip):
            far_wet += abs(ef._area(ef._clip(poly, *r)))
            far_area += (r[1] - r[0]) * (r[3] - r[2])
    out["far_wet_area_um2"] = far_wet
    out["far_region_um2"] = far_area
    return out


def bench_row(c: BenchCase, rec: dict, edges: np.ndarray | None) -> dict[str, str]:
    p = c.path()
    lr = ef.level_row(p, rec)
    geo = geometry(c)
    row = {
        "gap_um": ef._f(c.g),
        "variant": c.variant,
        "x_um": ef._f(c.x),
        "y_um": ef._f(c.y),
        "level": lr["level"],
        "force_x_N": lr["force_x_N"],
        "force_y_N": lr["force_y_N"],
        "force_x_fd_N": lr["force_x_fd_N"],
        "energy_gamma_um2": lr["energy_gamma_um2"],
        "energy_J": lr["energy_J"],
        "area_um2": lr["area_um2"],
        "chip_z_um": lr["chip_height_um"],
        "far_pads": "+".join(sorted(far_pads(c.x, c.y))),
        "wet_area_um2": lr["wet_area_um2"],
        "xmin_y0_um": lr["cl_xmin_y0_um"],
        "xmax_y0_um": lr["cl_xmax_y0_um"],
        "cl_xmin_um": lr["cl_xmin_um"],
        "cl_xmax_um": lr["cl_xmax_um"],
        "z_min_free_um": ef._f(rec.get("ZMIN")),
        "z_min_x_um": ef._f(rec.get("ZMINX")),
        "z_min_y_um": ef._f(rec.get("ZMINY")),
        "held_points": str(sum(geo["held"])),
        "rows0": str(geo["m"]),
        "pre_rounds": str(int(rec.get("PRE", -1))),
        "pre_last_dE": ef._f(rec.get("PREDE")),
        "pressure_per_um": lr["pressure_per_um"],
        "volume_um3_measured": lr["volume_um3_measured"],
        "vertices": lr["vertices"],
        "facets": lr["facets"],
        "last_newton_dE": lr["last_newton_dE"],
        "newton_settled": str(lr["flag"] != "newton_not_settled"),
        "flag": lr["flag"],
        "seconds": lr["seconds"],
        "L_um": ef._f(L_CHIP),
        "volume_um3": ef._f(VOLUME),
        "theta_pad_deg": ef._f(p.theta_p),
        "theta_sub_deg": ef._f(p.theta_s),
        "delta_um": ef._f(p.delta),
    }
    if edges is not None and len(edges):
        try:
            fs = far_stats(edges, c)
            for k, v in fs.items():
                row[k] = ef._f(v)
            row["far_wet_frac"] = ef._f(fs["far_wet_area_um2"] / fs["far_region_um2"])
            row["far_pads_wet"] = str(fs["far_wet_area_um2"] > 1.0)
        except Exception as exc:  # post-processing must not kill the run
            row["flag"] += f";far_stats_error {exc!r}"[:80]
    return {k: row.get(k, "") for k in COLUMNS}


def cases(gaps, variants, poses=X_POSES) -> list[BenchCase]:
    return [BenchCase(g, v, x, y) for g in gaps for v in variants for (x, y) in poses]


# ----------------------------------------------------------------------------
# report


def _fl(s) -> float:
    try:
        return float(s)
    except (TypeError, ValueError):
        return float("nan")


def _num(v: float, fmt: str) -> str:
    return "" if math.isnan(v) else format(v, fmt)


def _yn(s: str) -> str:
    return {"True": "yes", "False": "no"}.get(s, "-")


def status(r: dict[str, str]) -> str:
    """Plain-words status of a stored row: a free row whose pre-relaxation stopped while the far
    pads' liquid was still draining is not an equilibrium; a row whose envelope and finite-difference
    forces differ by more than 10 % is not converged."""
    de = _fl(r.get("pre_last_dE", ""))
    # the pre-relaxation stops below PRE_TOL or at its cap (PRE_MAX, or --pre-max for a tagged
    # run): a last round still lowering E by more than 10 PRE_TOL is a draining liquid
    if r["variant"].startswith("free") and (math.isnan(de) or abs(de) > 10 * PRE_TOL):
        return "draining, not an equilibrium"
    # the free surface passed more than TOUCH_TOL_UM below the substrate: a real liquid would
    # have touched down there (a new contact line), which the run cannot make
    if _fl(r.get("z_min_free_um", "")) < -TOUCH_TOL_UM:
        return "surface through the substrate, not valid"
    f, fd = _fl(r["force_x_N"]), _fl(r["force_x_fd_N"])
    if abs(f - fd) > 0.1 * abs(fd):
        return "not converged (F vs F_fd)"
    return f"level-{r['level']} value"


def report() -> str:
    rows = ef.read_csv(OUT) if OUT.exists() else []
    gam = ef.GAMMA_N_PER_M
    L = [
        "# Four-pad chip, the bench's protocol: droplet on all four pads first, chip released at an offset",
        "",
        f"Generated by `validation/evolver_fourpad_bench.py --report` on {dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC "
        "from `validation/evolver_fourpad_bench.csv`.",
        "",
        "## Set-up",
        "",
        "* Model and schedule of `validation/evolver_fourpad.py` (imported, not modified; see "
        "[FOURPAD.md](FOURPAD.md)): chip L = 730 um over four pads (outer size 730 um, cross-shaped gap "
        "g = 50 or 100 um), pads 30 deg, substrate 60 deg, 4 um smoothed steps, V = 2.0e7 um^3 (20 nl), chip "
        "edges pinned, chip height free (no vertical load), chip position fixed at the pose, twist 0. "
        "F_x, F_y: in-run envelope derivative (+-0.05 um, Lagrange-corrected); F_fd: +-2.5 um relaxed "
        "finite difference; gamma = 0.072 N/m, F < 0 points back to the centred pose.",
        "* **Start (the bench's protocol):** every pose is its own Evolver run.  The starting liquid covers the "
        "union of the pattern and the chip footprint: ruled walls from the chip edges (at the height that "
        "gives 20 nl, 26-30 um) down to the outline of that union, so all four pads start wet.  Relaxation: "
        f"the harness's first steps, then up to {PRE_MAX} rounds of `g {PRE_G}; u; V;` Newton loop until a round lowers E by "
        f"less than {PRE_TOL:g} gamma um^2 (starting mesh), then per level `r; qrelax`, and `qrelax; qreport` at "
        "the pose (the harness's schedule).",
        "* **free**: the whole substrate contact line is free (no hysteresis).  **held**: the contact-line "
        "points on the far pads' outer edges (and on the gap ends between two far pads) are fixed there, the "
        "limit of a receding angle near 0; the rest of the line is free.  The new model with a receding "
        "angle must lie between the two.",
        "* **free-long**: the free variant relaxed to equilibrium: up to 400 pre-relaxation rounds "
        "(`--pre-max 400 --tag long`), which stop once a round lowers E by less than "
        f"{PRE_TOL:g} gamma um^2 (the plain free runs stop after {PRE_MAX}, still draining).",
        "* Far pads: along x (y = 0) the two left pads (x <= -g/2); for (300, -300) the three pads other "
        "than the bottom-right one under the chip's centre.  `far wet` = wetted area on the far pads outside "
        "the chip footprint > 1 um^2 (the harness's `left_pads_wetted` threshold), with that area and its "
        "fraction of the far region.  `xmin(y=0)` = leftmost contact-line crossing of y = 0 (the left pads "
        "start at -g/2 and end at -365).",
        "* Levels as the harness defines them: level k = k refinements of the starting mesh (chip edges "
        "40 um -> 20 um at level 1, 10 um at level 2; the starting walls here have more rows, one per "
        f"{ROW_LEN:g} um of horizontal run, and the contact line on the stretched sides has longer edges). "
        "`nns` = newton_not_settled (harness flag: the last Newton step, or one in the finite-difference "
        "states, still changed E by more than 1e-6 |E| + 1e-3).",
        "",
    ]
    if not rows:
        return "\n".join(L + ["No results stored yet.", ""])
    for g in sorted({r["gap_um"] for r in rows}, key=_fl):
        extra = sorted({r["variant"] for r in rows} - {"free", "held"})
        for var in ("free", "held", *extra):
            sub = [r for r in rows if r["gap_um"] == g and r["variant"] == var]
            if not sub:
                continue
            L += [
                f"## g = {_fl(g):g} um, {var}",
                "",
                "| x um | y um | level | far wet | far wet area um^2 (frac) | F_x uN | F_y uN | F_fd uN | "
                "xmin(y=0) um | chip z um | E gamma um^2 | pre-relaxation: rounds, last dE | z_min um (at x, y) | facets | s | flag | status |",
                "|---:|---:|---:|:---:|---:|---:|---:|---:|---:|---:|---:|:---|:---|---:|---:|:---|:---|",
            ]
            sub.sort(key=lambda r: (_fl(r["y_um"]) != 0, _fl(r["x_um"]), int(r["level"] or 0)))
            for r in sub:
                if not r["energy_gamma_um2"]:
                    L.append(
                        f"| {_fl(r['x_um']):g} | {_fl(r['y_um']):g} | {r['level']} | | | FAILED | | | | | | | | | | {r['flag']} |"
                    )
                    continue
                fl = r["flag"].replace("newton_not_settled", "nns")
                L.append(
                    f"| {_fl(r['x_um']):g} | {_fl(r['y_um']):g} | {r['level']} | {_yn(r['far_pads_wet'])} | "
                    f"{_num(_fl(r['far_wet_area_um2']), '.0f')} ({_num(_fl(r['far_wet_frac']), '.3f')}) | "
                    f"{_fl(r['force_x_N']) * 1e6:+.3f} | {_fl(r['force_y_N']) * 1e6:+.3f} | "
                    f"{_fl(r['force_x_fd_N']) * 1e6:+.3f} | {_num(_fl(r['xmin_y0_um']), '.1f')} | "
                    f"{_num(_fl(r['chip_z_um']), '.2f')} | {_num(_fl(r['energy_gamma_um2']), '.0f')} | "
                    f"{r['pre_rounds']}, {_num(_fl(r['pre_last_dE']), '.0f') or 'not recorded'} | "
                    f"{_num(_fl(r['z_min_free_um']), '.2f')}"
                    + (
                        f" ({_fl(r['z_min_x_um']):.0f}, {_fl(r['z_min_y_um']):.0f})"
                        if r.get("z_min_x_um")
                        else ""
                    )
                    + f" | {r['facets']} | {_num(_fl(r['seconds']), '.0f')} | {'' if fl == 'ok' else fl} | "
                    f"{status(r)} |"
                )
            L.append("")
    outl = ef.read_csv(OUTWARD_LEVELS) if OUTWARD_LEVELS.exists() else []
    if outl:
        L += [
            "## For comparison: the harness's outward continuation at the same x (`evolver_fourpad_levels.csv`)",
            "",
            "The state a free contact line reaches when it recedes with the chip (x = 0 -> 500 um, one pose after "
            "the other), at each stored level.",
            "",
            "| g um | x um | level | left pads wetted (um^2) | F_x uN | xmin(y=0) um | chip z um | E gamma um^2 |",
            "|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for g in (50, 100):
            for x in (400, 450, 500):
                for r in outl:
                    if (
                        r["path"] == f"x_730_{g}"
                        and abs(_fl(r["x_um"]) - x) < 1e-6
                        and r["energy_gamma_um2"]
                    ):
                        L.append(
                            f"| {g} | {x} | {r['level']} | {_yn(r['left_pads_wetted'])} ({_fl(r['wet_left_pads_um2']):.0f}) | "
                            f"{_fl(r['force_x_N']) * 1e6:+.3f} | {_fl(r['cl_xmin_y0_um']):.1f} | "
                            f"{_fl(r['chip_height_um']):.2f} | {_fl(r['energy_gamma_um2']):.0f} |"
                        )
        L.append("")
    # convergence
    L += [
        "## Convergence (level 2 against level 1, same pose)",
        "",
        "| g um | variant | x um | y um | F_x L1 uN | F_x L2 uN | dF_x uN | dF_y uN | dE/E | far wet L1/L2 |",
        "|---:|:---|---:|---:|---:|---:|---:|---:|---:|:---:|",
    ]
    by = {
        (r["gap_um"], r["variant"], r["x_um"], r["y_um"], r["level"]): r
        for r in rows
        if r["energy_gamma_um2"]
    }
    n_pairs = 0
    for (g, var, x, y, lev), r2 in sorted(
        by.items(), key=lambda t: (_fl(t[0][0]), t[0][1], _fl(t[0][3]) != 0, _fl(t[0][2]))
    ):
        if lev != "2" or (g, var, x, y, "1") not in by:
            continue
        r1 = by[(g, var, x, y, "1")]
        n_pairs += 1
        f1, f2 = _fl(r1["force_x_N"]) * 1e6, _fl(r2["force_x_N"]) * 1e6
        dfy = (_fl(r2["force_y_N"]) - _fl(r1["force_y_N"])) * 1e6
        e1, e2 = _fl(r1["energy_gamma_um2"]), _fl(r2["energy_gamma_um2"])
        L.append(
            f"| {_fl(g):g} | {var} | {_fl(x):g} | {_fl(y):g} | {f1:+.3f} | {f2:+.3f} | {f2 - f1:+.3f} | {dfy:+.3f} | "
            f"{abs(e2 - e1) / abs(e2):.1e} | {_yn(r1['far_pads_wet'])}/{_yn(r2['far_pads_wet'])} |"
        )
    if not n_pairs:
        L.append("| (no level-2 rows yet) | | | | | | | | | |")
    secs = sum(_fl(r["seconds"]) for r in rows if r["seconds"])
    L += [
        "",
        f"Stored: {len(rows)} rows; summed Evolver wall time {secs:.0f} s ({secs / 60:.1f} min); "
        f"energies in gamma um^2 (E[J] = {gam} * 1e-12 * E).",
        "",
        "## Rerun",
        "",
        "```",
        "nice -n 10 python validation/evolver_fourpad_bench.py --gaps 50,100 --levels 1 --variants free,held",
        "nice -n 10 python validation/evolver_fourpad_bench.py --gaps 50,100 --levels 2 --append",
        "nice -n 10 python validation/evolver_fourpad_bench.py --gaps 50,100 --levels 1 --variants free "
        "--pre-max 400 --tag long --append",
        "python validation/evolver_fourpad_bench.py --report     # only this page",
        "```",
        "",
        "`--poses 400,0;300,-300` runs a subset; `--deadline HH:MM` (UTC) starts no run after that time and "
        "kills a running one then; the CSV is rewritten after every pose.",
        "",
    ]
    old_notes = ""
    if MD.exists():
        txt = MD.read_text()
        if NOTES_MARK in txt:
            old_notes = txt.split(NOTES_MARK, 1)[1]
    L.append(NOTES_MARK)
    return "\n".join(L) + (old_notes if old_notes else "\n")


def write_md() -> None:
    tmp = MD.with_suffix(".md.tmp")
    tmp.write_text(report())
    tmp.replace(MD)


# ----------------------------------------------------------------------------


def _seconds_to(deadline: str | None) -> float:
    if not deadline:
        return float("inf")
    now = dt.datetime.now(dt.UTC)
    hh, mm = (int(t) for t in deadline.split(":"))
    return (now.replace(hour=hh, minute=mm, second=0, microsecond=0) - now).total_seconds()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--gaps", default="50,100", help="comma-separated gaps (um) of the L = 730 pattern"
    )
    ap.add_argument(
        "--levels", default="1", help="comma-separated refinement levels (each pose a separate run)"
    )
    ap.add_argument("--variants", default="free,held", help="free, held or both")
    ap.add_argument(
        "--poses", default=None, help="'x,y;x,y;...' (um) instead of the six bench poses"
    )
    ap.add_argument("--append", action="store_true", help="keep the rows already in the CSV")
    ap.add_argument(
        "--report", action="store_true", help="only rewrite FOURPAD_BENCH.md from the CSV"
    )
    ap.add_argument(
        "--deadline",
        default=None,
        help="HH:MM UTC: start no run after it, kill a running one at it",
    )
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per Evolver process")
    ap.add_argument(
        "--out", type=Path, default=OUT, help="CSV (default validation/evolver_fourpad_bench.csv)"
    )
    ap.add_argument(
        "--pre-max",
        type=int,
        default=PRE_MAX,
        help=f"pre-relaxation rounds at most (default {PRE_MAX}); with --tag for a diagnostic run",
    )
    ap.add_argument(
        "--tag",
        default="",
        help="appended to the variant name in the CSV (e.g. 'long' -> free-long)",
    )
    ap.add_argument(
        "--trace",
        type=int,
        default=None,
        metavar="N",
        help="instead: print a level-0 relaxation trace of N rounds for the first selected case",
    )
    ap.add_argument(
        "--print-datafile", action="store_true", help="print the first case's data file and stop"
    )
    args = ap.parse_args(argv)
    if args.report:
        write_md()
        print(f"wrote {MD}", file=sys.stderr)
        return 0
    gaps = [float(t) for t in args.gaps.split(",")]
    variants = args.variants.split(",")
    levels = [int(t) for t in args.levels.split(",")]
    poses = X_POSES
    if args.poses:
        poses = tuple(tuple(float(v) for v in t.split(",")) for t in args.poses.split(";"))
    todo = cases(gaps, variants, poses)
    _pre_max[0] = args.pre_max
    if args.print_datafile:
        print(datafile(todo[0]))
        return 0
    if args.trace is not None:
        trace(todo[0], args.trace)
        return 0
    ef.find_evolver()
    rows = ef.read_csv(args.out) if args.append and args.out.exists() else []
    failed = 0
    t_all = time.perf_counter()
    for lev in levels:
        for c in todo:
            left = _seconds_to(args.deadline)
            if left < 60:
                print(f"deadline: not starting {c.name} level {lev}", file=sys.stderr)
                continue
            vname = c.variant + ("-" + args.tag if args.tag else "")
            key = (ef._f(c.g), vname, ef._f(c.x), ef._f(c.y), str(lev))
            rows[:] = [
                r
                for r in rows
                if (r["gap_um"], r["variant"], r["x_um"], r["y_um"], r["level"]) != key
            ]
            captured: dict = {}

            def keep_edges(edges, L, g, captured=captured):
                captured["edges"] = np.array(edges)
                return ef_stats(edges, L, g)

            ef.datafile = lambda p, c=c: datafile(c)
            ef.command_file = command_file
            ef.contact_line_stats = keep_edges
            s = ef.Schedule(level=lev, timeout_s=min(args.timeout, left))

            def on_pose(rec: dict, c=c, captured=captured) -> None:
                row = bench_row(c, rec, captured.get("edges"))
                if args.tag:
                    row["variant"] += "-" + args.tag
                rows.append(row)
                ef.write_csv_atomic(args.out, COLUMNS, rows)

            tp = time.perf_counter()
            recs, err = ef.run_path(c.path(), s, on_pose, sys.stderr)
            msg = f"{c.name} level {lev}: {time.perf_counter() - tp:.0f} s" + (
                f"; FAILED: {err}" if err else ""
            )
            print(msg, file=sys.stderr, flush=True)
            if err:
                failed += 1
                if not recs:
                    rows.append(
                        {
                            **{k: "" for k in COLUMNS},
                            "gap_um": key[0],
                            "variant": vname,
                            "x_um": key[2],
                            "y_um": key[3],
                            "level": str(lev),
                            "flag": "failed: " + err.replace("\n", " ")[:200],
                        }
                    )
                ef.write_csv_atomic(args.out, COLUMNS, rows)
    ef.datafile, ef.command_file, ef.contact_line_stats = (
        _harness_datafile,
        _harness_command_file,
        ef_stats,
    )
    print(f"wrote {args.out}; wall {time.perf_counter() - t_all:.0f} s", file=sys.stderr)
    return 1 if failed else 0


ef_stats = ef.contact_line_stats

if __name__ == "__main__":
    sys.exit(main())
