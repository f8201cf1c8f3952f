#!/usr/bin/env python3
"""Surface Evolver reference for the equilibrium pose over a pad with one triangular defect.

A 200 um square chip face sits over a 200 um square pad that carries ONE triangular edge
defect (docs/physics.md §10, types A, B, C on the right edge, inward or outward; the geometry
is ``patterns.geometry.defect_type``, so it is exactly the project's).  Liquid of volume
``V`` fills the gap.  Both contact lines are **pinned**: the liquid is held at the pad's
boundary polygon (defect included) and at the chip's four edges.  Only the liquid-air
area counts, ``E = gamma * area`` with ``gamma = 0.072 N/m`` (lengths in um, so
``E[J] = gamma * area_um2 * 1e-12``); gravity is neglected.

The chip pose -- centre ``(xshift, yshift)`` relative to the centre of the NOMINAL
square, twist ``twdeg`` in degrees counter-clockwise seen from above (docs/physics.md §1) --
and, by default, the chip height ``chipz`` are Evolver ``optimizing_parameter`` s.
Evolver minimises the area over them together with the surface (gradient steps, then
Newton steps with ``hessian_seek``, whose Hessian includes the parameters), so the
reported pose is where force and torque vanish.  At every refinement level the residual
force, torque and vertical force are measured independently by the envelope method of
``evolver.py`` (central differences of ``E - p (V - V0)`` with the free vertices moved
along, at fixed volume) and must be ~0 relative to ``2 gamma L``.

Mesh: the pad boundary is walked counter-clockwise together with the nominal square (the
chip edge); a pad vertex at perimeter position ``s`` of the nominal square is joined to
the chip edge point at the same ``s`` (for the defect on the right edge: the same y).
Every vertex of the pad polygon (the triangle's corners) is a mesh vertex.  The wall band
has ``vertical`` rows of quads split into two triangles; the diagonals are chosen by the
sign of ``x*y`` of the quad centre, so the starting mesh is mirror-symmetric about
y = 0 (and about x = 0 for the square pad) and the symmetric cases stay symmetric to
round-off.  Pad vertices are fixed; chip-edge vertices lie on the two-parameter
boundary 1 (the chip plane in chip-local coordinates) that moves with the pose.

Run ``--quick`` for one coarse case (one refinement, about a second), or without it
for the 12 defect cases plus the two defect-free sanity cases (4 refinements, about
17 min on one core).  Each finished case is written to the CSV at once (atomically);
cases already in the output file are skipped, so an interrupted run resumes.  See
validation/DEFECTS.md for the set-up, the convergence evidence and the results.  Standard library plus numpy (and the
project's ``patterns.geometry``).
"""

from __future__ import annotations

import argparse
import calendar
import csv
import dataclasses
import math
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from patterns.geometry import DEFECT_TYPES, defect_type  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from evolver import EvolverError, find_evolver, write_csv_atomic  # noqa: E402,F401  (the pinned-bridge harness's I/O)

GAMMA_N_PER_M = 0.072
UM2_TO_M2 = 1e-12
UM_TO_M = 1e-6
SIZE_UM = 200.0
DEFAULT_OUT = HERE / "evolver_defects.csv"

COLUMNS = (
    "defect",
    "kind",
    "volume_um3",
    "volume_nl",
    "height_mode",
    "x_um",
    "y_um",
    "twist_deg",
    "h_um",
    "area_um2",
    "energy_J",
    "pressure_um_inv",
    "force_x_N",
    "force_y_N",
    "torque_Nm",
    "force_z_N",
    "force_rel_2gL",
    "torque_rel_2gL2",
    "dx_last_um",
    "dy_last_um",
    "dtwist_last_deg",
    "dh_last_um",
    "refinements",
    "vertices",
    "facets",
    "newton_steps_last",
    "energy_change_last_newton_um2",
    "x_um_by_level",
    "y_um_by_level",
    "twist_deg_by_level",
    "h_um_by_level",
    "area_um2_by_level",
    "vertices_by_level",
    "seconds",
)


@dataclasses.dataclass(frozen=True)
class Case:
    """One equilibrium problem.  ``defect`` is 'A', 'B', 'C' or 'none' (plain square pad)."""

    defect: str
    kind: str
    volume: float  # um^3
    free_height: bool = True

    def __post_init__(self) -> None:
        if self.defect == "none":
            if self.kind != "none":
                raise ValueError("the defect-free pad has kind 'none'")
        elif self.defect not in DEFECT_TYPES or self.kind not in ("inward", "outward"):
            raise ValueError(f"bad case {self.defect!r} {self.kind!r}")
        if not self.volume > 0:
            raise ValueError("volume must be > 0 um^3")

    @property
    def label(self) -> str:
        tag = "free" if self.free_height else "fixed"
        return f"{self.defect}_{self.kind}_V{self.volume / 1e6:g}nl_{tag}"

    def pad_ring(self) -> list[tuple[float, float]]:
        """Pad boundary polygon, counter-clockwise, without the closing point."""
        if self.defect == "none":
            a = SIZE_UM / 2
            return [(a, -a), (a, a), (-a, a), (-a, -a)]
        poly = defect_type(self.defect, self.kind, size=SIZE_UM, edge="right")
        ring = poly.exterior
        coords = list(ring.coords)[:-1]
        if not ring.is_ccw:
            coords = coords[::-1]
        return [(float(x), float(y)) for x, y in coords]

    def pad_area(self) -> float:
        ring = self.pad_ring()
        xs = np.array([p[0] for p in ring])
        ys = np.array([p[1] for p in ring])
        return 0.5 * float(np.sum(xs * np.roll(ys, -1) - np.roll(xs, -1) * ys))


@dataclasses.dataclass(frozen=True)
class Schedule:
    """Mesh and convergence schedule (see the module docstring and DEFECTS.md)."""

    refinements: int = 4
    seg_per_h: float = 1.0
    max_seg_um: float = 20.0
    vertical: int = 2
    delta_rel: float = 1e-3  # shift step of the residual-force check, fraction of h
    dtheta_rad: float = 1e-4  # twist step of the residual-torque check
    newton_tol_um2: float = 1e-10  # stop Newton when the energy change falls below this
    newton_max: int = 20
    timeout_s: float = 3600.0


# ---------------------------------------------------------------------------- geometry


def _square_point(s: float, L: float = SIZE_UM) -> tuple[float, float]:
    """Point at perimeter position s of the nominal square, CCW from (-L/2, -L/2)."""
    a = L / 2
    s = s % (4 * L)
    if s < L:
        return (-a + s, -a)
    if s < 2 * L:
        return (a, -a + (s - L))
    if s < 3 * L:
        return (a - (s - 2 * L), a)
    return (-a, a - (s - 3 * L))


def _perimeter_s(p: tuple[float, float], L: float = SIZE_UM) -> float:
    """Perimeter position of a pad vertex: nominal-square edge points go to themselves,
    defect vertices (right edge, -L/2 < y < L/2) to the right-edge point at the same y."""
    a, tol = L / 2, 1e-9
    x, y = p
    if abs(y + a) < tol and -a - tol <= x <= a + tol:
        return x + a
    if abs(y - a) < tol and -a - tol <= x <= a + tol:
        return 2 * L + (a - x)
    if abs(x + a) < tol and -a - tol <= y <= a + tol:
        return 3 * L + (a - y)
    if x > 0 and -a < y < a:
        return L + (y + a)
    raise ValueError(f"pad vertex {p} is neither on the nominal square nor a right-edge defect")


def boundary_nodes(case: Case, seg: float) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """Pairs (pad point, chip-local point) around the perimeter, counter-clockwise,
    starting at the corner (-L/2, -L/2).  Every pad polygon vertex is a node."""
    L = SIZE_UM
    ring = case.pad_ring()
    verts = sorted((_perimeter_s(p), p) for p in ring)
    s_v = [s for s, _ in verts]
    if verts[0][0] != 0.0 or len(set(s_v)) != len(s_v):
        raise ValueError("pad polygon must contain the corner (-L/2, -L/2) and map one-to-one")
    # the sorted order must be the ring's own order (walk is monotone in s)
    start = ring.index(verts[0][1])
    if [p for _, p in verts] != ring[start:] + ring[:start]:
        raise ValueError("pad polygon is not monotone along the nominal perimeter")
    n = max(2, round(L / seg))
    n += n % 2  # even: no quad is centred on a symmetry line
    grid = [k * L / n for k in range(4 * n)]
    keep = [s for s in grid if min(abs(s - t) for t in s_v + [4 * L]) > 0.3 * L / n or s in s_v]
    nodes = sorted(set(keep) | set(s_v))
    sv = np.array(s_v + [4 * L])
    xv = np.array([p[0] for _, p in verts] + [verts[0][1][0]])
    yv = np.array([p[1] for _, p in verts] + [verts[0][1][1]])
    out = []
    for s in nodes:
        bottom = (float(np.interp(s, sv, xv)), float(np.interp(s, sv, yv)))
        out.append((bottom, _square_point(s)))
    for _, p in verts:  # exactness: every polygon vertex is a node, bit for bit
        if p not in [b for b, _ in out]:
            raise AssertionError(f"pad vertex {p} is not a mesh node")
    return out


def datafile(case: Case, schedule: Schedule = Schedule()) -> str:
    """Evolver datafile text for ``case`` (starting pose 0, 0, 0)."""
    L = SIZE_UM
    h_nom = case.volume / (L * L)
    seg = min(schedule.seg_per_h * h_nom, schedule.max_seg_um)
    nodes = boundary_nodes(case, seg)
    n = len(nodes)
    m = schedule.vertical
    a_pad = case.pad_area()
    if case.free_height:
        z0 = case.volume / (0.5 * (a_pad + L * L))  # the starting ruled body holds about V
    else:
        z0 = case.volume / a_pad

    def vid(k: int, i: int) -> int:
        return k * n + (i % n) + 1

    opt = "optimizing_parameter"
    out = [
        f"// {case.label}: pinned liquid bridge over a defect pad, area in um^2 (tension 1)",
        f"{opt} xshift = 0 pdelta = 1e-4 pscale = 1",
        f"{opt} yshift = 0 pdelta = 1e-4 pscale = 1",
        f"{opt} twdeg = 0 pdelta = 1e-4 pscale = 1",
        ("optimizing_parameter" if case.free_height else "parameter")
        + f" chipz = {z0!r}"
        + (" pdelta = 1e-4 pscale = 1" if case.free_height else ""),
        "boundary 1 parameters 2",
        "x1: p1*cos(twdeg*pi/180) - p2*sin(twdeg*pi/180) + xshift",
        "x2: p1*sin(twdeg*pi/180) + p2*cos(twdeg*pi/180) + yshift",
        "x3: chipz",
        "",
        "vertices",
    ]
    for k in range(m + 1):
        t = k / m
        for i, ((bx, by), (tx, ty)) in enumerate(nodes):
            if k == 0:
                out.append(f"{vid(k, i)} {bx!r} {by!r} 0 fixed")
            elif k == m:
                out.append(f"{vid(k, i)} {tx!r} {ty!r} boundary 1 fixed")
            else:
                out.append(f"{vid(k, i)} {bx + t * (tx - bx)!r} {by + t * (ty - by)!r} {t * z0!r}")

    edge_id: dict[tuple[int, int], int] = {}
    edge_lines: list[str] = []

    def add_edge(u: int, v: int, attr: str = "") -> None:
        edge_id[(u, v)] = len(edge_lines) + 1
        edge_lines.append(f"{len(edge_lines) + 1} {u} {v} {attr}".rstrip())

    def signed(u: int, v: int) -> int:
        return edge_id[(u, v)] if (u, v) in edge_id else -edge_id[(v, u)]

    def diag_type(k: int, i: int) -> int:
        (x0, y0), (x1, y1) = nodes[i][1], nodes[(i + 1) % n][1]
        xc, yc = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        if xc * yc == 0.0:
            raise AssertionError("a quad is centred on a symmetry line")
        return int(xc * yc > 0) ^ (k % 2)

    for k in range(m + 1):
        attr = "fixed" if k == 0 else ("boundary 1 fixed" if k == m else "")
        for i in range(n):
            add_edge(vid(k, i), vid(k, i + 1), attr)
    for k in range(m):
        for i in range(n):
            add_edge(vid(k, i), vid(k + 1, i))
            if diag_type(k, i) == 0:
                add_edge(vid(k, i), vid(k + 1, i + 1))
            else:
                add_edge(vid(k, i + 1), vid(k + 1, i))

    faces: list[str] = []
    for k in range(m):
        for i in range(n):
            p, q, r, t = vid(k, i), vid(k, i + 1), vid(k + 1, i + 1), vid(k + 1, i)
            tris = [(p, q, r), (p, r, t)] if diag_type(k, i) == 0 else [(p, q, t), (q, r, t)]
            for tri in tris:  # counter-clockwise perimeter -> outward normal
                faces.append(" ".join(str(signed(tri[j], tri[(j + 1) % 3])) for j in range(3)))
    top = " ".join(str(signed(vid(m, i), vid(m, i + 1))) for i in range(n))
    faces.append(f"{top} density 0 boundary 1 fixed")

    out += ["", "edges", *edge_lines, "", "faces"]
    out += [f"{j + 1} {f}" for j, f in enumerate(faces)]
    body = " ".join(str(j + 1) for j in range(len(faces)))
    out += ["", "bodies", f"1 {body} volume {case.volume!r}", "", "read", ""]
    return "\n".join(out)


# ---------------------------------------------------------------------------- commands

_COMMANDS = """\
quiet on
qdx := {delta!r}
qdth := {dtheta!r}
qtol := {tol!r}
qnmax := {nmax:d}
qvol := body[1].target
qpres := 0; qe := 0; qep := 0; qem := 0; qfx := 0; qfy := 0; qtq := 0; qfz := 0; qlev := 0
qeh := 0; qdeh := 0; qrang := 0; qs := 0; qcx := 0; qcy := 0; qan := 0; qxx := 0; qyy := 0
qni := 0; qz0 := 0; qneg := -1
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
qcalcfz := {{ qpres := body[1].pressure; qz0 := chipz;
  chipz := qz0 + qdx; set vertex z z*(qz0 + qdx)/qz0 where not fixed; recalc; qelag; qep := qe;
  set vertex z z*(qz0 - qdx)/(qz0 + qdx) where not fixed; chipz := qz0 - qdx; recalc; qelag; qem := qe;
  set vertex z z*qz0/(qz0 - qdx) where not fixed; chipz := qz0; recalc;
  qfz := -(qep - qem)/(2*qdx) }}
qrot := {{ foreach vertex vv where not fixed do {{
    qs := vv.z/chipz; qcx := qs*xshift; qcy := qs*yshift; qan := qs*qrang;
    qxx := vv.x - qcx; qyy := vv.y - qcy;
    vv.x := qcx + qxx*cos(qan) - qyy*sin(qan); vv.y := qcy + qxx*sin(qan) + qyy*cos(qan) }};
  twdeg := twdeg + qrang*180/pi; recalc }}
qcalctq := {{ qpres := body[1].pressure;
  qrang := qdth; qrot; qelag; qep := qe;
  qrang := -2*qdth; qrot; qelag; qem := qe;
  qrang := qdth; qrot;
  qtq := -(qep - qem)/(2*qdth) }}
qnewton := {{ qni := 0;
  do {{ qeh := total_energy; hessian_seek; qdeh := total_energy - qeh; qni := qni + 1 }}
  while ((abs(qdeh) > qtol or qni < 4) and qni < qnmax) }}
qreport := {{ qcalcfx; qcalcfy; qcalctq; qcalcfz;
  printf "LEVEL %d E=%.15g V=%.15g X=%.15g Y=%.15g TW=%.15g Z=%.15g P=%.12g FX=%.12g FY=%.12g TQ=%.12g FZ=%.12g NV=%d NF=%d T=%.3f DH=%.6g NI=%d NEG=%d\\n", qlev, total_energy, body[1].volume, xshift, yshift, twdeg, chipz, body[1].pressure, qfx, qfy, qtq, qfz, vertex_count, facet_count, clock, qdeh, qni, qneg }}
qfixp := {{ fix xshift; fix yshift; fix twdeg{fixz} }}
qunfixp := {{ unfix xshift; unfix yshift; unfix twdeg{unfixz} }}
qprobe := {{ quiet off; eigenprobe 0; quiet on; qneg := eigen_neg }}
qrelax := {{ u; V; u; qfixp; g 5; qunfixp; qnewton; u; V; u; qnewton; qprobe }}
qfixp; g 30; qunfixp; qnewton; u; V; u; qnewton; qprobe
qreport
"""


def command_file(case: Case, schedule: Schedule = Schedule()) -> str:
    h = case.volume / SIZE_UM**2
    text = _COMMANDS.format(
        delta=schedule.delta_rel * h,
        dtheta=schedule.dtheta_rad,
        tol=schedule.newton_tol_um2,
        nmax=schedule.newton_max,
        fixz="; fix chipz" if case.free_height else "",
        unfixz="; unfix chipz" if case.free_height else "",
    )
    for level in range(1, schedule.refinements + 1):
        text += f"qlev := {level}; r; qrelax; qreport\n"
    return text + "quit 0\n"


_LEVEL_RE = re.compile(r"^LEVEL (\d+) (.*)$", re.M)


def parse_levels(text: str) -> list[dict[str, float]]:
    levels = []
    for match in _LEVEL_RE.finditer(text):
        rec: dict[str, float] = {"level": int(match.group(1))}
        for item in match.group(2).split():
            key, _, value = item.partition("=")
            rec[key] = float(value)
        levels.append(rec)
    return levels


def run_case(
    case: Case,
    schedule: Schedule = Schedule(),
    evolver: str | None = None,
    keep_dir: Path | None = None,
) -> dict:
    """Run Evolver on one case; return ``{case, levels, seconds, warnings}``."""
    exe = evolver or find_evolver()
    with tempfile.TemporaryDirectory(prefix="selfalign_evdef_") as tmp:
        fe = Path(tmp) / "case.fe"
        cmd = Path(tmp) / "case.cmd"
        fe.write_text(datafile(case, schedule))
        cmd.write_text(command_file(case, schedule))
        start = time.perf_counter()
        try:
            proc = subprocess.run(
                [exe, "-x", "-f", str(cmd), str(fe)],
                stdin=subprocess.DEVNULL,
                capture_output=True,
                text=True,
                timeout=schedule.timeout_s,
                cwd=tmp,
            )
        except subprocess.TimeoutExpired as exc:
            raise EvolverError(f"{case.label}: timed out after {schedule.timeout_s:g} s") from exc
        seconds = time.perf_counter() - start
        if keep_dir is not None:
            keep_dir.mkdir(parents=True, exist_ok=True)
            shutil.copy(fe, keep_dir / f"{case.label}.fe")
            shutil.copy(cmd, keep_dir / f"{case.label}.cmd")
            (keep_dir / f"{case.label}.out").write_text(proc.stdout + proc.stderr)
    if proc.returncode != 0:
        raise EvolverError(
            f"{case.label}: evolver exited {proc.returncode}:\n{(proc.stdout + proc.stderr)[-2000:]}"
        )
    levels = parse_levels(proc.stdout)
    if len(levels) != schedule.refinements + 1:
        raise EvolverError(
            f"{case.label}: expected {schedule.refinements + 1} LEVEL lines, got {len(levels)}"
            f"\n{(proc.stdout + proc.stderr)[-2000:]}"
        )
    for rec in levels:
        if abs(rec["V"] - case.volume) > 1e-6 * case.volume:
            raise EvolverError(f"{case.label}: volume {rec['V']} != {case.volume}")
    warnings = sum(
        1 for line in (proc.stdout + proc.stderr).splitlines() if "WARNING" in line.upper()
    )
    return {"case": case, "levels": levels, "seconds": seconds, "warnings": warnings}


# ---------------------------------------------------------------------------- rows and files


def _fmt(value: float) -> str:
    return repr(float(value))


def result_row(res: dict) -> dict[str, str]:
    case: Case = res["case"]
    levels = res["levels"]
    last, prev = levels[-1], levels[-2]
    two_gl = 2 * SIZE_UM  # 2 gamma L in Evolver units (gamma = 1), um
    fres = math.hypot(last["FX"], last["FY"]) / two_gl
    tres = abs(last["TQ"]) / (two_gl * SIZE_UM)

    def joined(key: str) -> str:
        return ";".join(f"{rec[key]:.9g}" for rec in levels)

    return {
        "defect": case.defect,
        "kind": case.kind,
        "volume_um3": _fmt(case.volume),
        "volume_nl": f"{case.volume / 1e6:g}",
        "height_mode": "free" if case.free_height else "fixed",
        "x_um": _fmt(last["X"]),
        "y_um": _fmt(last["Y"]),
        "twist_deg": _fmt(last["TW"]),
        "h_um": _fmt(last["Z"]),
        "area_um2": _fmt(last["E"]),
        "energy_J": _fmt(GAMMA_N_PER_M * last["E"] * UM2_TO_M2),
        "pressure_um_inv": _fmt(last["P"]),
        "force_x_N": _fmt(GAMMA_N_PER_M * last["FX"] * UM_TO_M),
        "force_y_N": _fmt(GAMMA_N_PER_M * last["FY"] * UM_TO_M),
        "torque_Nm": _fmt(GAMMA_N_PER_M * last["TQ"] * UM2_TO_M2),
        "force_z_N": _fmt(GAMMA_N_PER_M * last["FZ"] * UM_TO_M),
        "force_rel_2gL": f"{fres:.3e}",
        "torque_rel_2gL2": f"{tres:.3e}",
        "dx_last_um": _fmt(last["X"] - prev["X"]),
        "dy_last_um": _fmt(last["Y"] - prev["Y"]),
        "dtwist_last_deg": _fmt(last["TW"] - prev["TW"]),
        "dh_last_um": _fmt(last["Z"] - prev["Z"]),
        "refinements": str(len(levels) - 1),
        "vertices": str(int(last["NV"])),
        "facets": str(int(last["NF"])),
        "newton_steps_last": str(int(last["NI"])),
        "energy_change_last_newton_um2": f"{last['DH']:.3e}",
        "x_um_by_level": joined("X"),
        "y_um_by_level": joined("Y"),
        "twist_deg_by_level": joined("TW"),
        "h_um_by_level": joined("Z"),
        "area_um2_by_level": joined("E"),
        "vertices_by_level": ";".join(str(int(rec["NV"])) for rec in levels),
        "seconds": f"{res['seconds']:.1f}",
    }


def read_rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _row_key(row: dict[str, str]) -> tuple:
    return (
        row["defect"],
        row["kind"],
        float(row["volume_um3"]),
        row["height_mode"],
        int(row["refinements"]),
    )


def _case_key(case: Case, refinements: int) -> tuple:
    return (
        case.defect,
        case.kind,
        case.volume,
        "free" if case.free_height else "fixed",
        refinements,
    )


# ---------------------------------------------------------------------------- cases and CLI


def all_cases(free_height: bool = True) -> list[Case]:
    """The 12 defect cases (C, B, A; 0.9 nl first), then the two defect-free checks."""
    cases = []
    for vol in (9.0e5, 5.0e5):
        for name in ("C", "B", "A"):
            for kind in ("inward", "outward"):
                cases.append(Case(name, kind, vol, free_height))
    cases += [Case("none", "none", v, free_height) for v in (9.0e5, 5.0e5)]
    return cases


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output CSV (default validation/evolver_defects.csv; an existing "
        "file is extended: cases already in it with the same number of "
        "refinements are skipped, so a run resumes)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="one coarse case (C outward, 0.9 nl, 1 refinement; default output in the temp folder)",
    )
    parser.add_argument(
        "--cases",
        default=None,
        help="comma-separated labels to run, e.g. C_inward_V0.9nl,none_none_V0.5nl "
        "(the suffix _free/_fixed is added)",
    )
    parser.add_argument(
        "--fixed-height",
        action="store_true",
        help="chip height fixed at V / (pad area) instead of free",
    )
    parser.add_argument("--refinements", type=int, default=Schedule.refinements)
    parser.add_argument("--vertical", type=int, default=Schedule.vertical)
    parser.add_argument("--timeout", type=float, default=Schedule.timeout_s)
    parser.add_argument(
        "--deadline", default=None, help="UTC time HH:MM after which no new case is started"
    )
    parser.add_argument(
        "--keep", type=Path, default=None, help="folder for .fe/.cmd/.out of each run"
    )
    args = parser.parse_args(argv)

    try:
        exe = find_evolver()
    except EvolverError as exc:
        print(f"evolver_defects.py: {exc}", file=sys.stderr)
        return 2
    free = not args.fixed_height
    if args.quick:
        cases = [Case("C", "outward", 9.0e5, free)]
        schedule = Schedule(refinements=1, vertical=args.vertical, timeout_s=args.timeout)
    else:
        cases = all_cases(free)
        schedule = Schedule(
            refinements=args.refinements, vertical=args.vertical, timeout_s=args.timeout
        )
    if args.cases:
        wanted = {
            w.strip()
            + ("" if w.strip().endswith(("_free", "_fixed")) else ("_free" if free else "_fixed"))
            for w in args.cases.split(",")
            if w.strip()
        }
        pool = {c.label: c for c in all_cases(free) + cases}
        missing = wanted - set(pool)
        if missing:
            parser.error(f"unknown case(s): {sorted(missing)}")
        cases = [pool[w] for w in sorted(wanted, key=list(pool).index)]
    out = args.out or (
        Path(tempfile.gettempdir()) / "evolver_defects_quick.csv" if args.quick else DEFAULT_OUT
    )
    rows = read_rows(out) if out.exists() and not args.quick else []
    done = {_row_key(r) for r in rows}
    deadline = None
    if args.deadline:
        hh, mm = (int(v) for v in args.deadline.split(":"))
        now = time.gmtime()
        deadline = calendar.timegm((now.tm_year, now.tm_mon, now.tm_mday, hh, mm, 0, 0, 0, 0))
    t0 = time.perf_counter()
    failed = 0
    for case in cases:
        if _case_key(case, schedule.refinements) in done:
            print(f"skip {case.label} (already in {out})", file=sys.stderr, flush=True)
            continue
        if deadline is not None and time.time() > deadline:
            print(
                f"deadline {args.deadline} UTC passed; not starting {case.label}",
                file=sys.stderr,
                flush=True,
            )
            break
        print(f"run  {case.label} ...", file=sys.stderr, flush=True)
        try:
            res = run_case(case, schedule, exe, args.keep)
        except EvolverError as exc:
            failed += 1
            print(f"FAILED {exc}", file=sys.stderr, flush=True)
            continue
        row = result_row(res)
        rows.append(row)
        write_csv_atomic(out, COLUMNS, rows)
        print(
            f"done {case.label}: x={float(row['x_um']):+.5f} y={float(row['y_um']):+.5f} um "
            f"tw={float(row['twist_deg']):+.5f} deg h={float(row['h_um']):.5f} um "
            f"|F|/2gL={row['force_rel_2gL']} |T|/2gL^2={row['torque_rel_2gL2']} "
            f"dx_last={float(row['dx_last_um']):+.2e} {row['seconds']} s, warnings {res['warnings']}",
            file=sys.stderr,
            flush=True,
        )
    if out.exists():
        print(f"{out}: {len(rows)} rows; wall {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
