#!/usr/bin/env python3
"""Surface Evolver referee for the finite-meniscus energy model.

A chip face (rectangle ``a x b`` um) sits at height ``h`` over an identical pad
(rectangle ``a x b`` at z = 0).  Liquid of volume ``V = a*b*h`` fills the gap
and its contact lines are pinned on the pad edges and on the chip edges.  The
chip is shifted by ``(x, y)`` and turned by ``twist_deg`` (counter-clockwise
seen from above, about the vertical axis through its centre).  Surface Evolver
finds the minimum liquid-air area at fixed volume; the energy is
``E = gamma * area`` with ``gamma = 0.072 N/m`` and lengths in um, so
``E[J] = gamma * area_um2 * 1e-12``.

Force and torque are the central differences ``F = -dE/dx`` and
``tau = -dE/dtheta`` (theta in radians) taken inside one run by the method of
the Evolver example ``column.fe``: after the surface has converged the chip is
moved by ``+-delta`` (the free vertices follow by a uniform shear, or a
twist growing linearly with z), and the energy is corrected to first order
for the volume change with the Lagrange multiplier (the body "pressure"),
``E - p (V - V0)``.  At a converged minimum this is the derivative of the
minimised energy at fixed volume (envelope theorem).  ``--crosscheck``
compares it with the other route, two separately converged runs at
``x +- delta``.

Run as a script (``make validate``) it writes ``validation/evolver_reference.csv``
(see ``--help``).  Importable: :func:`run_case`, :func:`reference_cases`,
:func:`datafile`, :func:`command_file`.  Standard library plus numpy only.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import csv
import dataclasses
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

GAMMA_N_PER_M = 0.072
UM2_TO_M2 = 1e-12
UM_TO_M = 1e-6

FAMILIES = ("shift_x", "shift_y", "twist")

COLUMNS = (
    "family",
    "a_um",
    "b_um",
    "h_um",
    "volume_um3",
    "x_um",
    "y_um",
    "twist_deg",
    "area_um2",
    "energy_J",
    "force_x_N",
    "force_y_N",
    "torque_Nm",
    "gamma_N_per_m",
    "refinements",
    "energy_change_last_refine_rel",
    "seconds",
)

LEVEL_COLUMNS = (
    "family",
    "a_um",
    "b_um",
    "h_um",
    "x_um",
    "y_um",
    "twist_deg",
    "level",
    "vertices",
    "facets",
    "area_um2",
    "volume_um3",
    "chip_z_um",
    "force_x_N",
    "force_y_N",
    "torque_Nm",
    "cpu_s",
)

HERE = Path(__file__).resolve().parent
DEFAULT_OUT = HERE / "evolver_reference.csv"

# Relative energy change between the last two refinement levels that a row
# must stay below to count as converged (checked by tests/test_evolver_reference.py).
CONVERGENCE_TOL = 5e-4


@dataclasses.dataclass(frozen=True)
class Case:
    """One chip pose.  Lengths in um, twist in degrees (CCW seen from above).

    ``free_height`` makes the chip height an Evolver optimizing parameter
    (no vertical load); ``h`` then only sets the volume ``a*b*h`` and the
    starting height.
    """

    family: str
    a: float
    b: float
    h: float
    x: float = 0.0
    y: float = 0.0
    twist_deg: float = 0.0
    free_height: bool = False

    def __post_init__(self) -> None:
        if self.family not in FAMILIES:
            raise ValueError(f"family must be one of {FAMILIES}, got {self.family!r}")
        for name in ("a", "b", "h"):
            value = getattr(self, name)
            if not value > 0:
                raise ValueError(f"{name} must be > 0 um, got {value!r}")

    @property
    def volume(self) -> float:
        return self.a * self.b * self.h

    @property
    def label(self) -> str:
        tag = "free" if self.free_height else "fixed"
        return (
            f"{self.family}_a{self.a:g}_b{self.b:g}_h{self.h:g}"
            f"_x{self.x:g}_y{self.y:g}_t{self.twist_deg:g}_{tag}"
        )


@dataclasses.dataclass(frozen=True)
class Schedule:
    """Mesh and convergence schedule.

    The starting mesh has edges of about ``min(seg_per_h * h, max_seg_um)``
    along the contact lines and ``vertical`` rows of quads (two triangles each) up each wall;
    each of the ``refinements`` levels quarters every triangle and is
    followed by equiangulation (``u``), vertex averaging (``V``), gradient
    descent (``g``) and Newton steps (``hessian``).
    """

    refinements: int = 4
    seg_per_h: float = 1.0
    max_seg_um: float = 20.0  # cap, so a 200 um side has at least 10 segments
    vertical: int = 2
    delta_rel: float = 1e-3  # shift step for -dE/dx, as a fraction of h
    dtheta_rad: float = 1e-4  # twist step for -dE/dtheta
    timeout_s: float = 1800.0

    def __post_init__(self) -> None:
        if self.refinements < 1:
            raise ValueError(f"refinements must be >= 1, got {self.refinements!r}")
        if self.vertical < 2:
            raise ValueError(
                f"vertical must be >= 2 (all-fixed mesh otherwise), got {self.vertical!r}"
            )


def _perimeter(a: float, b: float, seg: float) -> list[tuple[float, float]]:
    """Points on the rectangle's boundary, counter-clockwise from (-a/2, -b/2)."""
    na = max(2, round(a / seg))
    nb = max(2, round(b / seg))
    pts = [(-a / 2 + a * i / na, -b / 2) for i in range(na)]
    pts += [(a / 2, -b / 2 + b * i / nb) for i in range(nb)]
    pts += [(a / 2 - a * i / na, b / 2) for i in range(na)]
    pts += [(-a / 2, b / 2 - b * i / nb) for i in range(nb)]
    return pts


def datafile(case: Case, schedule: Schedule = Schedule()) -> str:
    """Evolver datafile text for ``case``.

    Vertices on the pad edges are fixed; vertices on the chip edges sit on
    the two-parameter boundary 1 (the chip plane in chip-local coordinates
    p1, p2), so changing ``xshift``/``yshift``/``twdeg``/``chipz`` moves the
    pinned chip contact line.  The side walls have tension 1 (energy = area,
    um^2); the chip face is a fixed, zero-tension facet that closes the
    volume; the pad face (z = 0) adds nothing to the z-based volume integral
    and is omitted.
    """
    pts = _perimeter(case.a, case.b, min(schedule.seg_per_h * case.h, schedule.max_seg_um))
    n = len(pts)
    m = schedule.vertical
    c, s = math.cos(math.radians(case.twist_deg)), math.sin(math.radians(case.twist_deg))

    def vid(k: int, i: int) -> int:
        return k * n + (i % n) + 1

    out = [
        f"// {case.label}: pinned liquid bridge, area in um^2 (tension 1)",
        f"parameter xshift = {case.x!r}",
        f"parameter yshift = {case.y!r}",
        f"parameter twdeg = {case.twist_deg!r}",
        ("optimizing_parameter" if case.free_height else "parameter") + f" chipz = {case.h!r}",
        "boundary 1 parameters 2",
        "x1: p1*cos(twdeg*pi/180) - p2*sin(twdeg*pi/180) + xshift",
        "x2: p1*sin(twdeg*pi/180) + p2*cos(twdeg*pi/180) + yshift",
        "x3: chipz",
        "",
        "vertices",
    ]
    for k in range(m + 1):
        t = k / m
        for i, (px, py) in enumerate(pts):
            if k == 0:
                out.append(f"{vid(k, i)} {px!r} {py!r} 0 fixed")
            elif k == m:
                out.append(f"{vid(k, i)} {px!r} {py!r} boundary 1 fixed")
            else:
                cx, cy = c * px - s * py + case.x, s * px + c * py + case.y
                out.append(
                    f"{vid(k, i)} {px + t * (cx - px)!r} {py + t * (cy - py)!r} {t * case.h!r}"
                )

    edge_id: dict[tuple[int, int], int] = {}
    edge_lines: list[str] = []

    def add_edge(u: int, v: int, attr: str = "") -> None:
        edge_id[(u, v)] = len(edge_lines) + 1
        edge_lines.append(f"{len(edge_lines) + 1} {u} {v} {attr}".rstrip())

    def signed(u: int, v: int) -> int:
        return edge_id[(u, v)] if (u, v) in edge_id else -edge_id[(v, u)]

    for k in range(m + 1):
        attr = "fixed" if k == 0 else ("boundary 1 fixed" if k == m else "")
        for i in range(n):
            add_edge(vid(k, i), vid(k, i + 1), attr)
    for k in range(m):
        for i in range(n):
            add_edge(vid(k, i), vid(k + 1, i))
            # alternate the diagonals so the starting mesh has no handedness
            if (i + k) % 2 == 0:
                add_edge(vid(k, i), vid(k + 1, i + 1))
            else:
                add_edge(vid(k, i + 1), vid(k + 1, i))

    faces: list[str] = []
    for k in range(m):
        for i in range(n):
            p, q, r, t = vid(k, i), vid(k, i + 1), vid(k + 1, i + 1), vid(k + 1, i)
            tris = [(p, q, r), (p, r, t)] if (i + k) % 2 == 0 else [(p, q, t), (q, r, t)]
            for tri in tris:  # counter-clockwise perimeter -> outward normal
                faces.append(" ".join(str(signed(tri[j], tri[(j + 1) % 3])) for j in range(3)))
    top = " ".join(str(signed(vid(m, i), vid(m, i + 1))) for i in range(n))
    faces.append(f"{top} density 0 boundary 1 fixed")

    out += ["", "edges", *edge_lines, "", "faces"]
    out += [f"{j + 1} {f}" for j, f in enumerate(faces)]
    body = " ".join(str(j + 1) for j in range(len(faces)))
    out += ["", "bodies", f"1 {body} volume {case.volume!r}", "", "read", ""]
    return "\n".join(out)


_COMMANDS = """\
quiet on
qdx := {delta!r}
qdth := {dtheta!r}
qvol := body[1].target
qpres := 0; qe := 0; qep := 0; qem := 0; qfx := 0; qfy := 0; qtq := 0; qlev := 0
qeh := 0; qdeh := 0; qrang := 0; qs := 0; qcx := 0; qcy := 0; qan := 0; qxx := 0; qyy := 0
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
qreport := {{ qcalcfx; qcalcfy; qcalctq;
  printf "LEVEL %d E=%.15g V=%.15g Z=%.15g P=%.12g FX=%.12g FY=%.12g TQ=%.12g NV=%d NF=%d T=%.3f DH=%.6g\\n", qlev, total_energy, body[1].volume, chipz, body[1].pressure, qfx, qfy, qtq, vertex_count, facet_count, clock, qdeh }}
qrelax := {{ u; V; u; g 3; hessian; hessian; u; V; hessian; hessian;
  qeh := total_energy; hessian; qdeh := total_energy - qeh }}
g 30; hessian; hessian; qeh := total_energy; hessian; qdeh := total_energy - qeh
qreport
"""


def command_file(case: Case, schedule: Schedule = Schedule()) -> str:
    """Evolver command text: converge, then for each refinement level
    ``r`` + relax, printing one ``LEVEL`` line (area, volume, chip height,
    pressure, in-run central-difference derivatives) per level."""
    text = _COMMANDS.format(delta=schedule.delta_rel * case.h, dtheta=schedule.dtheta_rad)
    for level in range(1, schedule.refinements + 1):
        text += f"qlev := {level}; r; qrelax; qreport\n"
    return text + "quit 0\n"


_LEVEL_RE = re.compile(r"^LEVEL (\d+) (.*)$", re.M)


def parse_levels(text: str) -> list[dict[str, float]]:
    """The ``LEVEL`` lines of an Evolver run as dicts (keys E, V, Z, P, FX,
    FY, TQ, NV, NF, T, level); Evolver-internal units (um, um^2)."""
    levels = []
    for match in _LEVEL_RE.finditer(text):
        rec: dict[str, float] = {"level": int(match.group(1))}
        for item in match.group(2).split():
            key, _, value = item.partition("=")
            rec[key] = float(value)
        levels.append(rec)
    return levels


class EvolverError(RuntimeError):
    pass


def find_evolver() -> str:
    path = shutil.which("evolver")
    if path is None:
        raise EvolverError(
            "'evolver' is not on PATH; install it with: apt-get install -y evolver-nox"
        )
    return path


def run_case(case: Case, schedule: Schedule = Schedule(), evolver: str | None = None) -> dict:
    """Run Evolver on one case; return the result record.

    Keys: ``case``, ``levels`` (list from :func:`parse_levels`), ``seconds``
    (wall clock), ``warnings`` (count of Evolver WARNING lines).  Raises
    :class:`EvolverError` on a non-zero exit, a timeout, a missing level or
    a volume that drifted.
    """
    exe = evolver or find_evolver()
    with tempfile.TemporaryDirectory(prefix="selfalign_evolver_") as tmp:
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
    if proc.returncode != 0:
        tail = (proc.stdout + proc.stderr)[-2000:]
        raise EvolverError(f"{case.label}: evolver exited {proc.returncode}:\n{tail}")
    levels = parse_levels(proc.stdout)
    if len(levels) != schedule.refinements + 1:
        raise EvolverError(
            f"{case.label}: expected {schedule.refinements + 1} LEVEL lines, got {len(levels)}"
        )
    for rec in levels:
        if abs(rec["V"] - case.volume) > 1e-6 * case.volume:
            raise EvolverError(f"{case.label}: volume {rec['V']} != {case.volume}")
    warnings = sum(1 for line in proc.stdout.splitlines() if "WARNING" in line)
    return {"case": case, "levels": levels, "seconds": seconds, "warnings": warnings}


def _run_safe(args: tuple[Case, Schedule, str]) -> dict:
    case, schedule, exe = args
    try:
        return run_case(case, schedule, exe)
    except EvolverError as exc:
        return {"case": case, "error": str(exc)}


def run_cases(
    cases: Sequence[Case], schedule: Schedule = Schedule(), jobs: int = 1, log=None
) -> list[dict]:
    """Run ``cases`` in a process pool of ``jobs`` workers; results in input order."""
    exe = find_evolver()
    # poses that differ only in their family label (twist 0 = shift 0) run once
    unique: dict[Case, list[int]] = {}
    for i, c in enumerate(cases):
        unique.setdefault(dataclasses.replace(c, family="shift_x"), []).append(i)
    results: list[dict | None] = [None] * len(cases)
    with cf.ProcessPoolExecutor(max_workers=max(1, jobs)) as pool:
        futures = {
            pool.submit(_run_safe, (cases[idx[0]], schedule, exe)): idx for idx in unique.values()
        }
        for done, fut in enumerate(cf.as_completed(futures), 1):
            idx = futures[fut]
            res = fut.result()
            for i in idx:
                results[i] = {**res, "case": cases[i]}
            if log is not None:
                status = res.get("error") or (
                    f"E={res['levels'][-1]['E']:.6f} um^2, {res['seconds']:.1f} s"
                )
                print(
                    f"[{done}/{len(unique)}] {cases[idx[0]].label}: {status}", file=log, flush=True
                )
    return results  # type: ignore[return-value]


# ----------------------------------------------------------------------------
# cases and closed forms


def reference_cases() -> list[Case]:
    """The reference set (see validation/README.md)."""
    cases: list[Case] = []
    L = 200.0
    for h in (10.0, 20.0, 40.0):
        for r in (0, 0.25, 0.5, 1, 1.5, 2, 3):
            cases.append(Case("shift_x", L, L, h, x=r * h))
    cases.append(Case("shift_x", L, L, 20.0, x=-20.0))  # oddness check
    for r in (0, 0.25, 0.5, 1, 1.5, 2, 3):
        cases.append(Case("shift_x", 200.0, 100.0, 20.0, x=r * 20.0))
    for r in (0, 0.25, 0.5, 1, 1.5, 2, 3):
        cases.append(Case("shift_y", 200.0, 100.0, 20.0, y=r * 20.0))
    for h in (10.0, 20.0, 40.0):
        for t in (0, 0.5, 1, 2, 3):
            cases.append(Case("twist", L, L, h, twist_deg=t))
    cases.append(Case("twist", L, L, 20.0, twist_deg=-1.0))  # oddness check
    return cases


def flat_wall_shift_energy(b: float, h: float, x: float) -> float:
    """Sheared-block (flat wall) energy change in J for a shift x (um) along
    the a-side; b is the edge perpendicular to the shift (docs/physics.md §3.3)."""
    return 2 * GAMMA_N_PER_M * b * UM_TO_M * (math.hypot(x, h) - h) * UM_TO_M


def flat_wall_shift_force(b: float, h: float, x: float) -> float:
    """-dE/dx in N of :func:`flat_wall_shift_energy`."""
    return -2 * GAMMA_N_PER_M * b * UM_TO_M * x / math.hypot(x, h)


def flat_wall_twist_torque(side: float, h: float, theta_rad: float) -> float:
    """Linear flat-wall twist torque in N m of a square of side ``side``:
    stiffness gamma L^3 / (3 h)."""
    return -GAMMA_N_PER_M * (side * UM_TO_M) ** 3 / (3 * h * UM_TO_M) * theta_rad


# ----------------------------------------------------------------------------
# rows and files


def _fmt(value: float | None) -> str:
    return "" if value is None else repr(float(value))


def result_row(res: dict) -> dict[str, str]:
    """One CSV row (strings, SI units where the column says so)."""
    case: Case = res["case"]
    levels = res["levels"]
    last, prev = levels[-1], levels[-2]
    area = last["E"]  # tension 1 on the walls, 0 on the chip face
    rel = abs(last["E"] - prev["E"]) / abs(last["E"])
    return {
        "family": case.family,
        "a_um": _fmt(case.a),
        "b_um": _fmt(case.b),
        "h_um": _fmt(last["Z"]),
        "volume_um3": _fmt(case.volume),
        "x_um": _fmt(case.x),
        "y_um": _fmt(case.y),
        "twist_deg": _fmt(case.twist_deg),
        "area_um2": _fmt(area),
        "energy_J": _fmt(GAMMA_N_PER_M * area * UM2_TO_M2),
        "force_x_N": _fmt(GAMMA_N_PER_M * last["FX"] * UM_TO_M),
        "force_y_N": _fmt(GAMMA_N_PER_M * last["FY"] * UM_TO_M),
        "torque_Nm": _fmt(GAMMA_N_PER_M * last["TQ"] * UM2_TO_M2),
        "gamma_N_per_m": _fmt(GAMMA_N_PER_M),
        "refinements": str(len(levels) - 1),
        "energy_change_last_refine_rel": _fmt(rel),
        "seconds": f"{res['seconds']:.2f}",
    }


def level_rows(res: dict) -> list[dict[str, str]]:
    case: Case = res["case"]
    rows = []
    for rec in res["levels"]:
        rows.append(
            {
                "family": case.family,
                "a_um": _fmt(case.a),
                "b_um": _fmt(case.b),
                "h_um": _fmt(case.h),
                "x_um": _fmt(case.x),
                "y_um": _fmt(case.y),
                "twist_deg": _fmt(case.twist_deg),
                "level": str(int(rec["level"])),
                "vertices": str(int(rec["NV"])),
                "facets": str(int(rec["NF"])),
                "area_um2": _fmt(rec["E"]),
                "volume_um3": _fmt(rec["V"]),
                "chip_z_um": _fmt(rec["Z"]),
                "force_x_N": _fmt(GAMMA_N_PER_M * rec["FX"] * UM_TO_M),
                "force_y_N": _fmt(GAMMA_N_PER_M * rec["FY"] * UM_TO_M),
                "torque_Nm": _fmt(GAMMA_N_PER_M * rec["TQ"] * UM2_TO_M2),
                "cpu_s": _fmt(rec["T"]),
            }
        )
    return rows


def write_csv_atomic(path: Path, columns: Sequence[str], rows: Iterable[dict[str, str]]) -> None:
    """Write ``rows`` to ``path`` through a temporary file and ``os.replace``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(columns), lineterminator="\n")
            writer.writeheader()
            for row in rows:
                writer.writerow(row)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual mode
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def read_reference(path: Path = DEFAULT_OUT) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


# ----------------------------------------------------------------------------
# cross-check: in-run derivative vs two separately converged runs


def crosscheck(
    cases: Sequence[Case], schedule: Schedule, step_rel: float, jobs: int, log
) -> list[dict[str, str]]:
    """For each case (shift_x / shift_y / twist) run the poses at +-step and
    compare the two-run central difference with the in-run derivative at the
    pose.  The step is ``step_rel * h`` for shifts and, for twist, the angle
    that moves the chip corners by ``step_rel * h``."""
    runs: list[Case] = []
    steps: list[float] = []
    for c in cases:
        if c.family == "twist":
            d = step_rel * c.h / (0.5 * math.hypot(c.a, c.b))
            steps.append(d)
            runs += [
                dataclasses.replace(c, twist_deg=c.twist_deg + s * math.degrees(d)) for s in (1, -1)
            ]
        elif c.family == "shift_x":
            steps.append(step_rel * c.h)
            runs += [dataclasses.replace(c, x=c.x + s * step_rel * c.h) for s in (1, -1)]
        else:
            steps.append(step_rel * c.h)
            runs += [dataclasses.replace(c, y=c.y + s * step_rel * c.h) for s in (1, -1)]
    results = run_cases(list(cases) + runs, schedule, jobs, log)
    centre, pm = results[: len(cases)], results[len(cases) :]
    rows = []
    for i, c in enumerate(cases):
        r0, rp, rm = centre[i], pm[2 * i], pm[2 * i + 1]
        if any("error" in r for r in (r0, rp, rm)):
            continue
        ep, em = rp["levels"][-1]["E"], rm["levels"][-1]["E"]
        if c.family == "twist":
            two = -(ep - em) / (2 * steps[i]) * GAMMA_N_PER_M * UM2_TO_M2
            one = r0["levels"][-1]["TQ"] * GAMMA_N_PER_M * UM2_TO_M2
        else:
            key = "FX" if c.family == "shift_x" else "FY"
            two = -(ep - em) / (2 * steps[i]) * GAMMA_N_PER_M * UM_TO_M
            one = r0["levels"][-1][key] * GAMMA_N_PER_M * UM_TO_M
        rows.append(
            {
                "label": c.label,
                "step": repr(steps[i]),
                "in_run": repr(one),
                "two_run": repr(two),
                "rel_diff": repr(abs(one - two) / max(abs(one), 1e-300)),
            }
        )
    return rows


# ----------------------------------------------------------------------------
# command line


def _quick_cases() -> list[Case]:
    return [
        Case("shift_x", 200.0, 200.0, 20.0, x=0.0),
        Case("shift_x", 200.0, 200.0, 20.0, x=20.0),
        Case("twist", 200.0, 200.0, 20.0, twist_deg=1.0),
    ]


def _crosscheck_cases() -> list[Case]:
    return [
        Case("shift_x", 200.0, 200.0, 20.0, x=10.0),
        Case("shift_x", 200.0, 200.0, 40.0, x=80.0),
        Case("shift_y", 200.0, 100.0, 20.0, y=20.0),
        Case("twist", 200.0, 200.0, 20.0, twist_deg=1.0),
        Case("twist", 200.0, 200.0, 40.0, twist_deg=2.0),
    ]


def _free_height_cases() -> list[Case]:
    cases = []
    for h in (10.0, 20.0):
        for r in (0, 0.5, 1, 2):
            cases.append(Case("shift_x", 200.0, 200.0, h, x=r * h, free_height=True))
        for t in (1.0, 2.0):
            cases.append(Case("twist", 200.0, 200.0, h, twist_deg=t, free_height=True))
    return cases


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help=f"output CSV (default {DEFAULT_OUT.relative_to(HERE.parent)}; an existing "
        "default file is only overwritten when --out names it)",
    )
    parser.add_argument(
        "--levels-out",
        type=Path,
        default=None,
        help="per-refinement-level CSV (default: <out stem>_levels.csv)",
    )
    parser.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    parser.add_argument("--refinements", type=int, default=Schedule.refinements)
    parser.add_argument(
        "--timeout", type=float, default=Schedule.timeout_s, help="seconds per Evolver run"
    )
    parser.add_argument(
        "--set",
        choices=("reference", "quick", "free-height"),
        default="reference",
        help="case set: the reference set, 3 quick cases, or the free-height set",
    )
    parser.add_argument(
        "--crosscheck",
        type=float,
        default=None,
        metavar="STEP",
        help="instead: compare in-run derivatives with two-run differences at "
        "+-STEP*h (for twist: the angle moving the chip corners by STEP*h) on a few poses",
    )
    args = parser.parse_args(argv)

    try:
        find_evolver()
    except EvolverError as exc:
        print(f"evolver.py: {exc}", file=sys.stderr)
        return 2
    if args.jobs < 1:
        parser.error(f"--jobs must be >= 1, got {args.jobs}")

    schedule = Schedule(refinements=args.refinements, timeout_s=args.timeout)
    out = args.out
    if out is None:
        name = {
            "reference": "evolver_reference.csv",
            "quick": "evolver_quick.csv",
            "free-height": "evolver_free_height.csv",
        }[args.set]
        if args.crosscheck is not None:
            name = "evolver_crosscheck.csv"
        out = HERE / name
        if out.exists():
            print(f"evolver.py: {out} exists; pass --out {out} to overwrite it", file=sys.stderr)
            return 2

    t0 = time.perf_counter()
    if args.crosscheck is not None:
        rows = crosscheck(_crosscheck_cases(), schedule, args.crosscheck, args.jobs, sys.stderr)
        write_csv_atomic(
            out,
            ("label", "step", "in_run", "two_run", "rel_diff", "refinements"),
            ({**r, "refinements": str(schedule.refinements)} for r in rows),
        )
        print(f"wrote {out} ({len(rows)} rows, {time.perf_counter() - t0:.0f} s)")
        return 0

    cases = {
        "reference": reference_cases,
        "quick": _quick_cases,
        "free-height": _free_height_cases,
    }[args.set]()
    results = run_cases(cases, schedule, args.jobs, sys.stderr)
    failed = [r for r in results if "error" in r]
    good = [r for r in results if "error" not in r]
    levels_out = args.levels_out or out.with_name(out.stem + "_levels.csv")
    write_csv_atomic(out, COLUMNS, (result_row(r) for r in good))
    write_csv_atomic(levels_out, LEVEL_COLUMNS, (row for r in good for row in level_rows(r)))
    wall = time.perf_counter() - t0
    cpu = sum({id(r["levels"]): r["seconds"] for r in good}.values())  # duplicates share a run
    worst = max(
        (float(result_row(r)["energy_change_last_refine_rel"]) for r in good), default=np.nan
    )
    print(
        f"wrote {out} ({len(good)} rows) and {levels_out}; wall {wall:.0f} s, "
        f"sum of run times {cpu:.0f} s, worst last-refinement energy change {worst:.2e}"
    )
    for r in failed:
        print(f"FAILED {r['error']}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
