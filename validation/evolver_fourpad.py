#!/usr/bin/env python3
"""Surface Evolver reference: chip over a four-pad pattern, free substrate contact line.

A square chip of side ``L`` (um) hangs on a liquid bridge over a four-pad pattern of outer
size ``L`` with a cross-shaped gap of width ``g`` (docs/physics.md §6: pads occupy
``|x|, |y|`` in ``[g/2, L/2]``).  Pads have contact angle ``theta_p`` (30 deg), the
substrate (gaps and outside) ``theta_s`` (60 deg).

* Chip: its whole underside is wetted; the liquid-air surface is pinned on the chip's
  edges (Gibbs' inequality at the 90 deg edge: the contact line stays on the edge for
  apparent angles 60..150 deg, docs/physics.md §2).  The chip face is a fixed, zero-tension
  facet on the Evolver boundary 1 that moves with ``xshift``, ``yshift`` (chip centre)
  and ``chipz`` (chip height, an ``optimizing_parameter``: no vertical load).  No twist.
* Substrate contact line: free on the plane z = 0 (constraint 1).  The wetting energy
  ``-cos(theta(x, y))`` per unit wetted area is a contact-line integral (Green's theorem),
  ``oint M dx`` with ``M = cs*y + (cp - cs) * P(x) * Q(y)``: ``P`` is the (smoothed) 1-D
  pad indicator, ``Q(y) = int_0^y P``.  The pad indicator is the product ``P(x) P(y)``
  of 1-D indicators whose steps are smoothed by a C1 smoothstep of full width ``delta``
  (default 4 um; 2 um for L = 200), so the integrand is continuous and has continuous gradients; no
  rotation of axes is needed.
* Energy ``E = liquid-air area + wetting integral`` in ``gamma um^2`` (the chip wetting
  energy is a constant and dropped); ``E[J] = gamma * E * 1e-12`` with ``gamma = 0.072``.
* Force ``F_x = -dE/dx`` at fixed volume: in-run central difference with the Lagrange
  correction ``E - p (V - V0)`` (the envelope method of evolver.py, shear of the free
  vertices by ``delta_x * z / chipz``).  Cross-check (``--crosscheck X``): central
  difference of separately converged energies at ``X +- step``.
* Continuation: a path of poses runs in one Evolver process; each pose starts from the
  previous converged surface, translated rigidly with the chip (contact line included;
  a shear that leaves the contact line behind gives wrong, lagging states because the
  contact-line vertices then have to slide tangentially, which only gradient steps do).  Every
  path runs at each refinement level in ``--levels`` (a separate process per level,
  coarse first), so the last two levels give the convergence figures.

Run ``python validation/evolver_fourpad.py --help``.  Stdlib + numpy.  CSVs are written
atomically after every finished pose (nothing is lost if the run is stopped).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import math
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from evolver import EvolverError, find_evolver, write_csv_atomic  # noqa: E402,F401  (the pinned-bridge harness's I/O)

GAMMA_N_PER_M = 0.072
UM2_TO_M2 = 1e-12
UM_TO_M = 1e-6
HERE = Path(__file__).resolve().parent
DEFAULT_OUT = HERE / "evolver_fourpad.csv"


@dataclasses.dataclass(frozen=True)
class Path_:
    """One continuation path: pattern, volume, and the poses (x, y) in order."""

    name: str
    L: float
    g: float
    volume: float
    poses: tuple[tuple[float, float], ...]
    theta_p: float = 30.0
    theta_s: float = 60.0
    delta: float = 4.0  # smoothing width of the pad/substrate step, um
    seg: float = 40.0  # starting contact-line edge length, um (before refinement)

    @property
    def h0(self) -> float:
        return self.volume / self.L**2


@dataclasses.dataclass(frozen=True)
class Schedule:
    level: int = 2  # refinements of the starting mesh
    dshift: float = 0.05  # in-run derivative step, um
    timeout_s: float = 7200.0
    gsteps: int = 60  # conjugate-gradient steps before each Newton loop
    fd_step: float = (
        2.5  # um; F_x = -(E(x+d) - E(x-d)) / 2d, the +-d states relaxed by Newton steps
    )
    tol: float = 1e-3  # stop the Newton loop when one hessian_seek lowers E by less (gamma um^2)
    newton_max: int = 10
    integral_order: int = (
        16  # Gauss order of the contact-line integral (resolves the smoothed step)
    )


# ----------------------------------------------------------------------------
# wettability expressions (smoothed steps, Evolver syntax)


def _H(z: str) -> str:  # int_{-inf}^z of the smoothstep 3t^2 - 2t^3 (clamped to [0, 1])
    c = f"minimum(maximum({z},0),1)"
    return f"(({c})^3 - ({c})^4/2 + maximum(({z})-1,0))"


def _step(z: str) -> str:
    c = f"minimum(maximum({z},0),1)"
    return f"(3*({c})^2 - 2*({c})^3)"


def _indicator(v: str, x0: float, x1: float, d: float) -> str:
    return f"({_step(f'(({v})-({x0!r}))/{d!r}+0.5')} - {_step(f'(({v})-({x1!r}))/{d!r}+0.5')})"


def _integral(v: str, x0: float, x1: float, d: float) -> str:  # int_0^v of the indicator
    c = f"({d!r}*{_H(f'(0-({x0!r}))/{d!r}+0.5')} - {d!r}*{_H(f'(0-({x1!r}))/{d!r}+0.5')})"
    return f"({d!r}*{_H(f'(({v})-({x0!r}))/{d!r}+0.5')} - {d!r}*{_H(f'(({v})-({x1!r}))/{d!r}+0.5')} - {c})"


def _pad_intervals(L: float, g: float) -> list[tuple[float, float]]:
    return [(-L / 2, -g / 2), (g / 2, L / 2)]


def datafile(p: Path_) -> str:
    """Evolver datafile at the first pose of the path (vertical walls)."""
    x0, y0 = p.poses[0]
    L, h = p.L, p.h0
    iv = _pad_intervals(p.L, p.g)
    P = " + ".join(_indicator("x", a, b, p.delta) for a, b in iv)
    Q = " + ".join(_integral("y", a, b, p.delta) for a, b in iv)
    n_side = max(4, round(L / p.seg))
    pts = [(-L / 2 + L * i / n_side, -L / 2) for i in range(n_side)]
    pts += [(L / 2, -L / 2 + L * i / n_side) for i in range(n_side)]
    pts += [(L / 2 - L * i / n_side, L / 2) for i in range(n_side)]
    pts += [(-L / 2, L / 2 - L * i / n_side) for i in range(n_side)]
    n = len(pts)
    m = 2  # rows of quads up the wall

    def vid(k: int, i: int) -> int:
        return k * n + (i % n) + 1

    out = [
        f"// {p.name}: four-pad L={L:g} g={p.g:g} V={p.volume:g}, free contact line on z=0",
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
        for i, (px, py) in enumerate(pts):
            if k == 0:
                out.append(f"{vid(k, i)} {px + x0!r} {py + y0!r} 0 constraint 1")
            elif k == m:
                out.append(f"{vid(k, i)} {px!r} {py!r} boundary 1 fixed")
            else:
                out.append(f"{vid(k, i)} {px + x0!r} {py + y0!r} {t * h!r}")
    edge_id: dict[tuple[int, int], int] = {}
    edges: list[str] = []

    def add(u: int, v: int, attr: str = "") -> None:
        edge_id[(u, v)] = len(edges) + 1
        edges.append(f"{len(edges) + 1} {u} {v} {attr}".rstrip())

    def signed(u: int, v: int) -> int:
        return edge_id[(u, v)] if (u, v) in edge_id else -edge_id[(v, u)]

    for k in range(m + 1):
        attr = "constraint 1" if k == 0 else ("boundary 1 fixed" if k == m else "")
        for i in range(n):
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
            a, b, c, d = vid(k, i), vid(k, i + 1), vid(k + 1, i + 1), vid(k + 1, i)
            tris = [(a, b, c), (a, c, d)] if (i + k) % 2 == 0 else [(a, b, d), (b, c, d)]
            for tri in tris:
                faces.append(" ".join(str(signed(tri[j], tri[(j + 1) % 3])) for j in range(3)))
    top = " ".join(str(signed(vid(m, i), vid(m, i + 1))) for i in range(n))
    faces.append(f"{top} density 0 boundary 1 fixed")
    out += ["", "edges", *edges, "", "faces"]
    out += [f"{j + 1} {f}" for j, f in enumerate(faces)]
    body = " ".join(str(j + 1) for j in range(len(faces)))
    out += ["", "bodies", f"1 {body} volume {p.volume!r}", "", "read", ""]
    return "\n".join(out)


_COMMANDS = """\
quiet on
integral_order_1d := {iorder}
qdx := {dshift!r}
qvol := body[1].target
qpres := 0; qe := 0; qep := 0; qem := 0; qfx := 0; qfy := 0; qlev := 0; qpose := 0
qsx := 0; qsy := 0; qefp := 0; qefm := 0; qdfp := 0; qdfm := 0; qfdx := 0; qdd := {fdstep!r}
qeh := 0; qdeh := 0; qit := 0; qmx := 0; qmy := 0; qarea := 0
qelag := {{ qe := total_energy - qpres*(body[1].volume - qvol) }}
qcalcfx := {{ qpres := body[1].pressure;
  xshift := xshift + qdx; set vertex x x + qdx*z/chipz where not fixed; recalc; qelag; qep := qe;
  xshift := xshift - 2*qdx; set vertex x x - 2*qdx*z/chipz where not fixed; recalc; qelag; qem := qe;
  xshift := xshift + qdx; set vertex x x + qdx*z/chipz where not fixed; recalc;
  qfx := -(qep - qem)/(2*qdx) }}
qcalcfy := {{ qpres := body[1].pressure;
  yshift := yshift + qdx; set vertex y y + qdx*z/chipz where not fixed; recalc; qelag; qep := qe;
  yshift := yshift - 2*qdx; set vertex y y - 2*qdx*z/chipz where not fixed; recalc; qelag; qem := qe;
  yshift := yshift + qdx; set vertex y y + qdx*z/chipz where not fixed; recalc;
  qfy := -(qep - qem)/(2*qdx) }}
qmove := {{ xshift := xshift + qmx; yshift := yshift + qmy;
  set vertex x x + qmx where not fixed; set vertex y y + qmy where not fixed;
  recalc }}
qconv := {{ qit := 0; qdeh := 1e30;
  while (abs(qdeh) > {tol!r} and qit < {nit}) do {{ qeh := total_energy; hessian_seek; qdeh := total_energy - qeh; qit := qit + 1 }} }}
qrelax := {{ u; V; g {g1}; u; V; qconv; g {g1}; qconv; g {g1}; qconv }}
qconvq := {{ qit := 0; qdeh := 1e30;
  while (abs(qdeh) > {tol!r} and qit < {nit}) do {{ qeh := total_energy; hessian_seek; qdeh := total_energy - qeh; qit := qit + 1 }} }}
qshear := {{ xshift := xshift + qmx; set vertex x x + qmx*z/chipz where not fixed; recalc }}
qfd := {{ qsx := qmx; qsy := qmy; qmy := 0;
  qmx := qdd; qshear; qconvq; qefp := total_energy; qdfp := qdeh;
  qmx := -2*qdd; qshear; qconvq; qefm := total_energy; qdfm := qdeh;
  qmx := qdd; qshear; qconvq; qfdx := -(qefp - qefm)/(2*qdd); qmx := qsx; qmy := qsy }}
qreport := {{ qfd; qcalcfx; qcalcfy; qarea := sum(facet where not fixed, area);
  printf "POSE %d %d X=%.10g Y=%.10g E=%.15g A=%.15g V=%.15g Z=%.12g P=%.12g FX=%.12g FY=%.12g NV=%d NF=%d T=%.3f DH=%.6g NIT=%d FD=%.12g DHP=%.4g DHM=%.4g\\n", qpose, qlev, xshift, yshift, total_energy, qarea, body[1].volume, chipz, body[1].pressure, qfx, qfy, vertex_count, facet_count, clock, qdeh, qit, qfdx, qdfp, qdfm;
  foreach edge ee where on_constraint 1 do printf "CL %.10g %.10g %.10g %.10g\\n", ee.vertex[1].x, ee.vertex[1].y, ee.vertex[2].x, ee.vertex[2].y;
  printf "ENDPOSE %d\\n", qpose }}
U; g 50; u; V; g 50; qconv
"""


def command_file(p: Path_, s: Schedule) -> str:
    text = _COMMANDS.format(
        fdstep=s.fd_step,
        iorder=s.integral_order,
        dshift=s.dshift,
        g1=s.gsteps,
        tol=s.tol,
        nit=s.newton_max,
    )
    for _ in range(s.level):
        text += "r; qrelax\n"
    text += f"qlev := {s.level}\n"
    px, py = p.poses[0]
    for j, (x, y) in enumerate(p.poses):
        if j:
            text += f"qmx := {x - px!r}; qmy := {y - py!r}; qmove\n"
        text += f"qpose := {j}; qrelax; qreport\n"
        px, py = x, y
    return text + "quit 0\n"


# ----------------------------------------------------------------------------
# contact-line geometry (from the CL edge lines)


def _chain(edges: np.ndarray) -> np.ndarray:
    """Order the contact-line edges (rows x1 y1 x2 y2) into a closed polygon."""
    keyed = {}
    for e in edges:
        keyed[(round(e[0], 6), round(e[1], 6))] = e
    start = next(iter(keyed))
    poly = []
    cur = start
    for _ in range(len(keyed)):
        e = keyed[cur]
        poly.append((e[0], e[1]))
        cur = (round(e[2], 6), round(e[3], 6))
        if cur == start:
            break
    return np.array(poly)


def _clip(poly: np.ndarray, x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    """Sutherland-Hodgman clip of a polygon by an axis-aligned rectangle."""
    pts = [tuple(p) for p in poly]
    for axis, bound, keep_ge in ((0, x0, True), (0, x1, False), (1, y0, True), (1, y1, False)):
        if not pts:
            break
        new = []
        for i in range(len(pts)):
            a, b = pts[i - 1], pts[i]
            ina = a[axis] >= bound if keep_ge else a[axis] <= bound
            inb = b[axis] >= bound if keep_ge else b[axis] <= bound
            if inb:
                if not ina:
                    t = (bound - a[axis]) / (b[axis] - a[axis])
                    new.append((a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])))
                new.append(b)
            elif ina:
                t = (bound - a[axis]) / (b[axis] - a[axis])
                new.append((a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])))
        pts = new
    return np.array(pts) if pts else np.zeros((0, 2))


def _area(poly: np.ndarray) -> float:
    if len(poly) < 3:
        return 0.0
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def contact_line_stats(edges: np.ndarray, L: float, g: float) -> dict[str, float]:
    """Wetted area, x-extent on y = 0, min x, and wetted areas on pads (sharp pads)."""
    wet = abs(float(np.sum(edges[:, 0] * edges[:, 3] - edges[:, 2] * edges[:, 1]) / 2))
    poly = _chain(edges)
    # crossings of y = 0
    xs = []
    for xa, ya, xb, yb in edges:
        if (ya <= 0 < yb) or (yb <= 0 < ya):
            xs.append(xa + (0 - ya) * (xb - xa) / (yb - ya))
    a, b = L / 2, g / 2
    left = _area(_clip(poly, -a, -b, b, a)) + _area(_clip(poly, -a, -b, -a, -b))
    right = _area(_clip(poly, b, a, b, a)) + _area(_clip(poly, b, a, -a, -b))
    far = _area(_clip(poly, -a, -b, -a, -b))
    return {
        "wet_area_um2": wet,
        "cl_xmin_um": float(edges[:, 0].min()),
        "cl_xmax_um": float(edges[:, 0].max()),
        "cl_xmin_y0_um": min(xs) if xs else float("nan"),
        "cl_xmax_y0_um": max(xs) if xs else float("nan"),
        "wet_left_pads_um2": abs(left),
        "wet_right_pads_um2": abs(right),
        "wet_far_pad_um2": abs(far),
        "chain_ok": float(len(poly) == len(edges)),
    }


# ----------------------------------------------------------------------------
# running


_POSE_RE = re.compile(r"^POSE (\d+) (\d+) (.*)$")


def run_path(p: Path_, s: Schedule, on_pose=None, log=None) -> tuple[list[dict], str | None]:
    """Run one continuation path at one level, streaming poses to ``on_pose(rec)``.

    Returns (records, error or None).  Records hold the POSE fields, the contact-line
    statistics and ``seconds`` (wall time since the previous pose or the start)."""
    exe = find_evolver()
    recs: list[dict] = []
    err = None
    with tempfile.TemporaryDirectory(prefix="selfalign_fourpad_") as tmp:
        fe, cmd = Path(tmp) / "case.fe", Path(tmp) / "case.cmd"
        fe.write_text(datafile(p))
        cmd.write_text(command_file(p, s))
        t0 = last = time.perf_counter()
        proc = subprocess.Popen(
            [exe, "-x", "-f", str(cmd), str(fe)],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            cwd=tmp,
        )
        cur: dict | None = None
        cl: list[list[float]] = []
        tail: list[str] = []
        try:
            assert proc.stdout is not None
            for line in proc.stdout:
                tail = (tail + [line])[-40:]
                if time.perf_counter() - t0 > s.timeout_s:
                    proc.kill()
                    err = f"timeout after {s.timeout_s:g} s"
                    break
                m = _POSE_RE.match(line)
                if m:
                    cur = {"pose": int(m.group(1)), "level": int(m.group(2))}
                    for item in m.group(3).split():
                        k, _, v = item.partition("=")
                        cur[k] = float(v)
                    cl = []
                elif line.startswith("CL ") and cur is not None:
                    cl.append([float(t) for t in line.split()[1:5]])
                elif line.startswith("ENDPOSE") and cur is not None:
                    now = time.perf_counter()
                    cur["seconds"] = now - last
                    last = now
                    try:
                        cur.update(contact_line_stats(np.array(cl), p.L, p.g))
                    except Exception as exc:  # geometry post-processing must not kill the run
                        cur["stats_error"] = repr(exc)
                    recs.append(cur)
                    if on_pose is not None:
                        on_pose(cur)
                    if log is not None:
                        print(
                            f"  {p.name} L{s.level} pose {cur['pose']} x={cur['X']:g} y={cur['Y']:g} "
                            f"E={cur['E']:.6f} FD={cur['FD']:.5g} FX={cur['FX']:.5g} Z={cur['Z']:.4g} NF={int(cur['NF'])} "
                            f"DH={cur['DH']:.2g} {cur['seconds']:.1f}s",
                            file=log,
                            flush=True,
                        )
                    cur = None
            rc = proc.wait()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    if err is None and rc != 0:
        err = f"evolver exited {rc}: " + " | ".join(t.strip() for t in tail[-5:])
    if err is None and len(recs) != len(p.poses):
        err = f"only {len(recs)} of {len(p.poses)} poses"
    return recs, err


# ----------------------------------------------------------------------------
# cases


def _arange(a: float, b: float, step: float) -> list[float]:
    n = int(round((b - a) / step))
    return [round(a + i * step, 6) for i in range(n + 1)]


def xpath_730() -> list[float]:
    return _arange(0, 250, 25) + _arange(260, 450, 10) + [475.0, 500.0]


def case_paths(quick: bool = False) -> list[Path_]:
    if quick:
        return [Path_("quick_730_50", 730.0, 50.0, 2.0e7, ((0.0, 0.0), (25.0, 0.0), (50.0, 0.0)))]
    xs = sorted(set(xpath_730()))
    xs3 = sorted(set(_arange(0, 60, 10) + _arange(60, 130, 5) + [140.0, 150.0]))
    diag = _arange(0, 300, 25)
    return [
        Path_("x_730_50", 730.0, 50.0, 2.0e7, tuple((x, 0.0) for x in xs)),
        Path_("x_730_100", 730.0, 100.0, 2.0e7, tuple((x, 0.0) for x in xs)),
        Path_("x_200_20", 200.0, 20.0, 5.0e5, tuple((x, 0.0) for x in xs3), delta=2.0, seg=12.5),
        Path_("diag_730_50", 730.0, 50.0, 2.0e7, tuple((x, x) for x in diag)),
        Path_("diag_730_100", 730.0, 100.0, 2.0e7, tuple((x, x) for x in diag)),
    ]


# ----------------------------------------------------------------------------
# CSV rows

LEVEL_COLUMNS = (
    "path",
    "L_um",
    "g_um",
    "volume_um3",
    "delta_um",
    "seg0_um",
    "level",
    "x_um",
    "y_um",
    "energy_gamma_um2",
    "energy_J",
    "area_um2",
    "wetting_gamma_um2",
    "force_x_N",
    "force_x_fd_N",
    "force_y_N",
    "chip_height_um",
    "pressure_per_um",
    "volume_um3_measured",
    "wet_area_um2",
    "cl_xmin_um",
    "cl_xmax_um",
    "cl_xmin_y0_um",
    "cl_xmax_y0_um",
    "wet_left_pads_um2",
    "wet_right_pads_um2",
    "wet_far_pad_um2",
    "left_pads_wetted",
    "vertices",
    "facets",
    "last_newton_dE",
    "seconds",
    "flag",
)

COLUMNS = (
    "path",
    "L_um",
    "g_um",
    "volume_um3",
    "theta_pad_deg",
    "theta_sub_deg",
    "delta_um",
    "x_um",
    "y_um",
    "level",
    "energy_gamma_um2",
    "energy_J",
    "area_um2",
    "force_x_N",
    "force_x_fd_N",
    "force_y_N",
    "chip_height_um",
    "wet_area_um2",
    "cl_xmin_um",
    "cl_xmax_um",
    "cl_xmin_y0_um",
    "cl_xmax_y0_um",
    "wet_left_pads_um2",
    "wet_far_pad_um2",
    "left_pads_wetted",
    "energy_from_force_J",
    "prev_level",
    "energy_prev_gamma_um2",
    "force_x_prev_N",
    "energy_change_rel",
    "force_x_change_N",
    "force_x_change_rel",
    "seconds",
    "flag",
)


def _f(v) -> str:
    if v is None:
        return ""
    v = float(v)
    return "" if math.isnan(v) else repr(v)


def level_row(p: Path_, rec: dict, flag: str = "ok") -> dict[str, str]:
    E, A = rec["E"], rec["A"]
    fl = flag
    if abs(rec["V"] - p.volume) > 1e-5 * p.volume:
        fl = "volume_drift"
    elif max(abs(rec["DH"]), abs(rec["DHP"]), abs(rec["DHM"])) > 1e-6 * abs(E) + 1e-3:
        fl = "newton_not_settled"
    if "stats_error" in rec:
        fl += ";cl_stats_error"
    left = rec.get("wet_left_pads_um2", float("nan"))
    return {
        "path": p.name,
        "L_um": _f(p.L),
        "g_um": _f(p.g),
        "volume_um3": _f(p.volume),
        "delta_um": _f(p.delta),
        "seg0_um": _f(p.seg),
        "level": str(rec["level"]),
        "x_um": _f(rec["X"]),
        "y_um": _f(rec["Y"]),
        "energy_gamma_um2": _f(E),
        "energy_J": _f(GAMMA_N_PER_M * E * UM2_TO_M2),
        "area_um2": _f(A),
        "wetting_gamma_um2": _f(E - A),
        "force_x_N": _f(GAMMA_N_PER_M * rec["FX"] * UM_TO_M),
        "force_x_fd_N": _f(GAMMA_N_PER_M * rec["FD"] * UM_TO_M),
        "force_y_N": _f(GAMMA_N_PER_M * rec["FY"] * UM_TO_M),
        "chip_height_um": _f(rec["Z"]),
        "pressure_per_um": _f(rec["P"]),
        "volume_um3_measured": _f(rec["V"]),
        **{
            k: _f(rec.get(k))
            for k in (
                "wet_area_um2",
                "cl_xmin_um",
                "cl_xmax_um",
                "cl_xmin_y0_um",
                "cl_xmax_y0_um",
                "wet_left_pads_um2",
                "wet_right_pads_um2",
                "wet_far_pad_um2",
            )
        },
        "left_pads_wetted": str(bool(left > 1.0)) if not math.isnan(left) else "",
        "vertices": str(int(rec["NV"])),
        "facets": str(int(rec["NF"])),
        "last_newton_dE": _f(rec["DH"]),
        "seconds": f"{rec['seconds']:.2f}",
        "flag": fl,
    }


def pose_rows(level_rows: list[dict[str, str]], paths: Sequence[Path_]) -> list[dict[str, str]]:
    """One row per (path, pose): the finest level, compared with the next coarser one."""
    by: dict[tuple[str, str, str], dict[int, dict[str, str]]] = {}
    order: list[tuple[str, str, str]] = []
    for r in level_rows:
        key = (r["path"], r["x_um"], r["y_um"])
        if key not in by:
            by[key] = {}
            order.append(key)
        by[key][int(r["level"])] = r
    meta = {p.name: p for p in paths}
    rows = []
    for key in order:
        lv = by[key]
        top = max(lv)
        r = lv[top]
        p = meta.get(key[0])
        row = {k: r.get(k, "") for k in COLUMNS if k in r}
        row["theta_pad_deg"] = _f(p.theta_p) if p else ""
        row["theta_sub_deg"] = _f(p.theta_s) if p else ""
        flag = r["flag"]
        lower = [k for k in lv if k < top]
        if lower and r["energy_gamma_um2"] and lv[max(lower)]["energy_gamma_um2"]:
            q = lv[max(lower)]
            e1, e0 = float(r["energy_gamma_um2"]), float(q["energy_gamma_um2"])
            f1, f0 = float(r["force_x_N"]), float(q["force_x_N"])
            row.update(
                prev_level=str(max(lower)),
                energy_prev_gamma_um2=q["energy_gamma_um2"],
                force_x_prev_N=q["force_x_N"],
                energy_change_rel=_f(abs(e1 - e0) / abs(e1)),
                force_x_change_N=_f(f1 - f0),
                force_x_change_rel=_f(abs(f1 - f0) / max(abs(f1), 1e-7)),
            )
            if q["flag"] != "ok" and flag == "ok":
                flag = "prev_level_" + q["flag"]
        else:
            row.update(
                prev_level="",
                energy_prev_gamma_um2="",
                force_x_prev_N="",
                energy_change_rel="",
                force_x_change_N="",
                force_x_change_rel="",
            )
            if flag == "ok":
                flag = "single_level"
        row["flag"] = flag
        rows.append({k: row.get(k, "") for k in COLUMNS})
    _integrate_force(rows)
    return rows


def _integrate_force(rows: list[dict[str, str]]) -> None:
    """Fill ``energy_from_force_J``: minus the trapezoid integral of the force along each
    path from its first pose (the in-run envelope forces are smoother than the path
    energies, whose mesh-relaxation noise is larger than the energy changes between poses)."""
    start: dict[str, tuple[float, float, float, float, float]] = {}
    for r in rows:
        if not r["force_x_N"] or not r["energy_gamma_um2"]:
            continue
        x, y = float(r["x_um"]), float(r["y_um"])
        fx, fy = float(r["force_x_N"]), float(r["force_y_N"] or 0.0)
        if r["path"] not in start:
            acc = 0.0
        else:
            x0, y0, fx0, fy0, acc = start[r["path"]]
            acc -= 0.5 * (fx + fx0) * (x - x0) * UM_TO_M + 0.5 * (fy + fy0) * (y - y0) * UM_TO_M
        start[r["path"]] = (x, y, fx, fy, acc)
        r["energy_from_force_J"] = _f(acc)


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


# ----------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--out", type=Path, default=None, help="pose CSV (default validation/evolver_fourpad.csv)"
    )
    ap.add_argument(
        "--levels-out", type=Path, default=None, help="per-level CSV (default <out>_levels.csv)"
    )
    ap.add_argument(
        "--quick", action="store_true", help="3 poses (730/50, x = 0, 25, 50) at level 1"
    )
    ap.add_argument(
        "--levels", default="1,2", help="comma-separated refinement levels (default 1,2)"
    )
    ap.add_argument("--paths", default=None, help="comma-separated path names to run (default all)")
    ap.add_argument("--delta", type=float, default=None, help="override the smoothing width (um)")
    ap.add_argument(
        "--crosscheck",
        type=float,
        default=None,
        metavar="X",
        help="instead: x-path 0..X-step, X-step, X, X+step on the first selected path",
    )
    ap.add_argument(
        "--xs",
        default=None,
        help="comma-separated x values replacing the poses of the selected paths "
        "(y = 0, or y = x on diagonal paths); the path name gets a _xs suffix",
    )
    ap.add_argument(
        "--same-name",
        action="store_true",
        help="with --xs: keep the path name, so these rows merge with the full path "
        "(used to add a finer level on a subset of poses)",
    )
    ap.add_argument("--step", type=float, default=2.5, help="step of --crosscheck (um)")
    ap.add_argument("--append", action="store_true", help="keep the rows already in the level CSV")
    ap.add_argument(
        "--rebuild",
        action="store_true",
        help="only rewrite the pose CSV from the level CSV (no Evolver run)",
    )
    ap.add_argument(
        "--jobs", type=int, default=1, help="accepted for symmetry; paths run one at a time"
    )
    ap.add_argument(
        "--timeout", type=float, default=Schedule.timeout_s, help="seconds per Evolver process"
    )
    args = ap.parse_args(argv)
    try:
        find_evolver()
    except EvolverError as exc:
        print(f"evolver_fourpad.py: {exc}", file=sys.stderr)
        return 2
    paths = case_paths(args.quick)
    if args.paths:
        names = args.paths.split(",")
        paths = [p for p in paths if p.name in names]
    if args.delta is not None:
        paths = [
            dataclasses.replace(p, delta=args.delta, name=f"{p.name}_d{args.delta:g}")
            for p in paths
        ]
    if args.xs:
        xv = [float(t) for t in args.xs.split(",")]
        paths = [
            dataclasses.replace(
                p,
                name=p.name if args.same_name else f"{p.name}_xs",
                poses=tuple((x, x if p.name.startswith("diag") else 0.0) for x in xv),
            )
            for p in paths
        ]
    if args.crosscheck is not None:
        p = paths[0]
        X, st = args.crosscheck, args.step
        xs = [x for x in _arange(0, 250, 25) if x < X - st] + [X - st, X, X + st]
        paths = [
            dataclasses.replace(p, name=f"{p.name}_xc{X:g}", poses=tuple((x, 0.0) for x in xs))
        ]
    levels = (
        [1] if args.quick and args.levels == "1,2" else [int(t) for t in args.levels.split(",")]
    )
    out = args.out or (Path("/tmp/evolver_fourpad_quick.csv") if args.quick else DEFAULT_OUT)
    lout = args.levels_out or out.with_name(out.stem + "_levels.csv")
    lrows: list[dict[str, str]] = read_csv(lout) if args.append and lout.exists() else []
    all_paths = case_paths(False) + paths

    if args.rebuild:
        lrows = read_csv(lout)
        write_csv_atomic(out, COLUMNS, pose_rows(lrows, all_paths))
        print(f"rebuilt {out} from {lout}", file=sys.stderr)
        return 0

    def flush() -> None:
        write_csv_atomic(lout, LEVEL_COLUMNS, lrows)
        write_csv_atomic(out, COLUMNS, pose_rows(lrows, all_paths))

    t0 = time.perf_counter()
    failed = 0
    for p in paths:
        for lev in levels:
            s = Schedule(level=lev, timeout_s=args.timeout)
            print(f"{p.name} level {lev}: {len(p.poses)} poses", file=sys.stderr, flush=True)
            # drop stale rows of this (path, level)
            lrows[:] = [r for r in lrows if not (r["path"] == p.name and r["level"] == str(lev))]

            def on_pose(rec: dict, p=p) -> None:
                lrows.append(level_row(p, rec))
                flush()

            tp = time.perf_counter()
            recs, err = run_path(p, s, on_pose, sys.stderr)
            print(
                f"{p.name} level {lev}: {len(recs)} poses in {time.perf_counter() - tp:.0f} s"
                + (f"; FAILED: {err}" if err else ""),
                file=sys.stderr,
                flush=True,
            )
            if err:
                failed += 1
                done = {(r["X"], r["Y"]) for r in recs}
                for x, y in p.poses:
                    if not any(abs(x - a) < 1e-6 and abs(y - b) < 1e-6 for a, b in done):
                        lrows.append(
                            {
                                **{k: "" for k in LEVEL_COLUMNS},
                                "path": p.name,
                                "L_um": _f(p.L),
                                "g_um": _f(p.g),
                                "volume_um3": _f(p.volume),
                                "level": str(lev),
                                "x_um": _f(x),
                                "y_um": _f(y),
                                "flag": "failed: " + err.replace("\n", " ")[:200],
                            }
                        )
                        break  # one failure row marks where the path stopped
                flush()
    print(f"wrote {out} and {lout}; wall {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
