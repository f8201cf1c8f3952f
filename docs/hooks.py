"""Build hooks of the selfalign manual (``hooks:`` in mkdocs.yml).

* Benchmark tables. A page holds a marker ``<!-- table: NAME -->`` on a line of its own;
  the build replaces it by the table that :data:`TABLES` renders from the files in
  ``benchmarks/results/`` (``landscape.json``, ``sweep.json``, ``accuracy.json``,
  ``accuracy.md``, ``design_freeform.json``), so the site shows what the last recorded run measured and no number
  of those tables is copied by hand. ``python docs/hooks.py NAME`` prints one.
* Files outside ``docs/``. A page may link a file of the repository outside ``docs/``
  by its relative path (``../../patterns/library/overview.png``), which is right on
  GitHub. The build copies each such file into the site under ``repo/`` and points the
  link there; a link to a file that does not exist is a warning, so ``mkdocs build
  --strict`` fails on it as on any broken link between pages.
* The API reference. A package's face loads its names lazily from its ``__init__.pyi``
  stub, so a page's ``::: PACKAGE`` (of simulator, patterns or foundation; no options of its own) gets the names
  of that stub, its ``__all__``, as the members to show. The docstrings render as
  Markdown; their Sphinx roles (``:func:`name```, ``:class:`~pkg.Name```) are shown as
  the plain code they name.
"""

from __future__ import annotations

import ast
import json
import logging
import posixpath
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
MARKER = re.compile(r"^<!-- table: ([\w-]+) -->$", re.M)
LINK = re.compile(r"(\]\()([^)\s#]+)(#[^)\s]*)?(\))")
REPO_PREFIX = "repo"
API_BLOCK = re.compile(r"^::: ((?:simulator|patterns|foundation)(?:\.\w+)*)[ \t]*$(?!\n    )", re.M)
ROLE = re.compile(r":(?:py:)?(?:func|mod|class|meth|data|attr|exc|obj):<code>(~?)([^<]*)</code>")

log = logging.getLogger("mkdocs.hooks.selfalign")


# ------------------------------------------------------------------------------- tables
def _load(name: str) -> dict:
    return json.loads((RESULTS / name).read_text(encoding="utf-8"))


def _g(v: float, digits: int = 3) -> str:
    """``digits`` significant digits, whole numbers from 10**digits up (as the benchmarks print)."""
    if v == 0:
        return "0"
    return f"{v:.{digits}g}" if abs(v) < 10**digits else f"{v:,.0f}"


LANDSCAPE_METHODS = {
    "selfalign": "**selfalign** (CPU: OpenCV's IPP transforms)",
    "selfalign-jax": "selfalign, JAX backend (XLA FFT)",
    "scipy-rfft2": "scipy.fft rfft2, precomputed pattern spectrum, all cores",
    "opencv-dft": "OpenCV dft + mulSpectrums",
    "opencv-matchTemplate": "OpenCV matchTemplate TM_CCORR",
    "scipy-fftconvolve": "scipy.signal.fftconvolve",
    "naive-per-pose": "naive per-pose loop (2014 MATLAB style)",
    "scipy-rfft2-f64": "scipy.fft rfft2 in float64 (the error reference)",
}
#: The kinds of chip raster (benchmarks/landscape.py: --chips).
LANDSCAPE_CHIPS = {
    "exact": "Exact chips: area-coverage rasters, as selfalign makes them (a square repeats every 90°)",
    "opencv": "OpenCV-rotated chips: cv2.warpAffine bilinear rasters (hardly two alike)",
}
#: The peers a user would otherwise use (benchmarks/landscape.py: PEERS).
LANDSCAPE_PEERS = ("opencv-matchTemplate", "opencv-dft", "scipy-fftconvolve", "scipy-rfft2")


def landscape_table() -> str:
    """benchmarks/results/landscape.json: seconds, ms per twist, memory and error per method,
    one table per kind of chip raster (rows without a kind are the run's ``--chips``)."""
    doc = _load("landscape.json")
    full = doc["args"]["twists"]
    m = doc["machine"]
    kinds = doc["args"]["chips"]
    kinds = [kinds] if isinstance(kinds, str) else list(kinds)
    order = ["selfalign"] + [k for k in LANDSCAPE_METHODS if k != "selfalign"]
    lines = []
    for kind in kinds:
        mine = [r for r in doc["rows"] if r.get("chips", kinds[0]) == kind]
        rows = sorted(
            (r for r in mine if "skipped" not in r),
            key=lambda r: (
                r["N"],
                order.index(r["method"]) if r["method"] in order else len(order),
            ),
        )
        lines += [
            f"**{LANDSCAPE_CHIPS.get(kind, kind)}** (`--chips {kind}`):",
            "",
            f"| N | method | twists | total s | ms/twist | s for {full} twists | peak MB (output MB) | max error / chip area |",
            "|---|---|---:|---:|---:|---:|---:|---:|",
        ]
        for r in rows:
            per = r["seconds"] / r["twists"]
            extrap = r["extrapolated"] or r["twists"] != full
            lines.append(
                f"| {r['N']} | {LANDSCAPE_METHODS.get(r['method'], r['method'])} | {r['twists']} "
                f"| {_g(r['seconds'])}{' (extrapolated)' if r['extrapolated'] else ''} | {_g(per * 1e3)} "
                f"| {_g(per * full)}{' (extrap.)' if extrap else ''} | {r['peak_mb']:.0f} ({r['out_mb']:.0f}) "
                f"| {r['max_err_per_area']:.1e} |"
            )
        lines += ["", _landscape_ratios(mine), ""]
    lines.append(
        f"Recorded with `python benchmarks/landscape.py --json benchmarks/results/landscape.json` "
        f"(sizes {', '.join(map(str, doc['args']['sizes']))} px, chips {' and '.join(f'`{k}`' for k in kinds)}"
        + (
            f"; the timed calls of all methods taken in turn, best of {doc['args'].get('repeats', 3)} each): "
            if any("times_s" in r for r in doc["rows"])
            else "): "
        )
        + f"{m['cpus']} CPUs ({m['processor']}), Python {m['python']}, numpy {m['numpy']}, scipy {m['scipy']}, "
        f"OpenCV {m['opencv']}" + (f", JAX {m['jax']}" if "jax" in m else "") + "."
    )
    return "\n".join(lines)


def _landscape_ratios(rows: list[dict]) -> str:
    out = []
    for n in sorted({r["N"] for r in rows}):
        done = {
            r["method"]: r
            for r in rows
            if r["N"] == n and "skipped" not in r and not r.get("extrapolated")
        }
        peers = [done[k] for k in LANDSCAPE_PEERS if k in done]
        if "selfalign" not in done or not peers:
            continue
        best, me = min(peers, key=lambda r: r["seconds"]), done["selfalign"]
        out.append(
            f"N = {n}: {best['seconds'] / me['seconds']:.2f}× ({_g(me['seconds'])} s against "
            f"{_g(best['seconds'])} s of {LANDSCAPE_METHODS.get(best['method'], best['method'])})"
        )
    return "selfalign against the fastest peer in this run: " + "; ".join(out) + "."


SWEEP_RUNS = {
    "loop": "plain loop, this process, all cores",
    "loop_one_core": "plain loop, one core (a child held to one core as a worker is)",
    "two_loops_one_core": "two one-core loops at once, no Dask (2 × {points} points)",
    "workers_1": "`sweep`, 1 worker (cluster start {cluster_s:.1f} s apart)",
    "workers_2": "`sweep`, 2 workers (cluster start {cluster_s:.1f} s apart)",
}


def sweep_table() -> str:
    """benchmarks/results/sweep.json: the same sweep as a plain loop and on 1 and 2 Dask workers."""
    doc = _load("sweep.json")
    n = doc["points"]
    lines = [
        f"| {n} points, cold (imports and compilation included) | seconds | points/s | median point |",
        "|---|---:|---:|---:|",
    ]
    for key, label in SWEEP_RUNS.items():
        r = doc.get(key)
        if r is None:
            continue
        rate = f"{r['points_per_s']:.2f}" + (" together" if key == "two_loops_one_core" else "")
        lines.append(
            f"| {label.format(points=n, cluster_s=r.get('cluster_s', 0.0))} | {r['seconds']:.1f} | {rate} "
            f"| {r['median_point_s']:.2g} s |"
        )
    w = [doc[k] for k in ("workers_1", "workers_2") if k in doc]
    outside = ", ".join(f"{r['outside_per_point_s'] * 1e3:.0f} ms" for r in w)
    lines += [
        "",
        f"In this run: 2 workers over 1, **{doc['speedup_2_over_1']:.2f}×**, when two plain processes side by side "
        f"got {doc['machine_speedup_two_processes']:.2f}× from the machine; a worker spent {outside} per point outside "
        f"the assessment (1 and 2 workers); the whole run with 1 worker against the one-core loop, "
        f"{doc['overhead_per_point_s'] * 1e3:.0f} ms per point. Best of {doc['repeats']} runs of each phase on "
        f"{doc['cpus']} CPUs, load average {doc['load_before'][0]:.1f} before and {doc['load_after'][0]:.1f} after.",
    ]
    return "\n".join(lines)


ACCURACY_KNOBS = {  # knob -> (row label, value format)
    "baseline": ("baseline", "1 µm/px, 1°, float32"),
    "um_per_px": ("pixel size", "{:g} µm/px"),
    "twist_step_deg": ("twist step", "{:g}°"),
    "dtype": ("dtype", "{}"),
    "raster": ("pattern raster", "{} (binary, threshold 0.5)"),
    "rotation": ("chip rotation", "{} a chip PNG (bilinear)"),
    "method": ("stepper", "{}"),
}


def _acc(v: float) -> str:
    return _g(v, 2)


def accuracy_table() -> str:
    """benchmarks/results/accuracy.json: energy RMS % / force p90 % / landscape s per knob and case."""
    doc = _load("accuracy.json")
    cases = list(doc["cases"])
    lines = [
        "| knob | value | " + " | ".join(doc["cases"][c]["title"] for c in cases) + " |",
        "|---|---|" + "---|" * len(cases),
    ]
    keys = list(
        dict.fromkeys((r["knob"], r["value"]) for r in doc["rows"] if r["knob"] in ACCURACY_KNOBS)
    )
    last = None
    for knob, value in keys:
        label, fmt = ACCURACY_KNOBS[knob]
        cells = []
        for c in cases:
            r = next(
                (
                    r
                    for r in doc["rows"]
                    if r["case"] == c and r["knob"] == knob and r["value"] == value
                ),
                None,
            )
            if r is None:
                cells.append("—")
                continue
            cell = f"{_acc(r['energy_rms_pct'])} / {_acc(r['force_p90_pct'])} / {_acc(r['landscape_s'])}"
            if r["pose_max_um"] > 0:
                cell += f" (pose {_acc(r['pose_max_um'])} µm, {_acc(r['twist_max_deg'])}°)"
            elif r["twist_max_deg"] > 0:
                cell += f" (twist off by {_acc(r['twist_max_deg'])}°)"
            cells.append(cell)
        shown = fmt if value is None else fmt.format(value)
        lines.append(f"| {label if label != last else ''} | {shown} | " + " | ".join(cells) + " |")
        last = label
    return "\n".join(lines)


def accuracy_details() -> str:
    """benchmarks/results/accuracy.md (written with accuracy.json by the same run), one heading level down."""
    text = (RESULTS / "accuracy.md").read_text(encoding="utf-8")
    out = []
    for line in text.splitlines():
        if line.startswith("# "):
            continue  # the page has its own title
        out.append("##" + line if line.startswith("#") else line)
    return "\n".join(out).strip()


def design_freeform_table() -> str:
    """benchmarks/results/design_freeform.json: seconds per gradient iteration of a free-form design."""
    doc = _load("design_freeform.json")
    m = doc["machine"]
    lines = [
        "| canvas | pixel | twist planes x perturbation samples | ms per iteration (best) | every run (ms) | compilation | load average |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in doc["rows"]:
        runs = ", ".join(_g(v * 1e3) for v in r["seconds_per_iteration_all"])
        lines.append(
            f"| {r['N']} x {r['N']} px | {r['um_per_px']:.3g} µm | {r['twists']} x {r['samples']} "
            f"| {_g(r['seconds_per_iteration'] * 1e3)} | {runs} | {r['compile_s']:.1f} s | {r['load_average']:.2f} |"
        )
    lines += [
        "",
        f"Recorded with `python benchmarks/design_freeform.py` (the problem of `{doc['example']}` on a "
        f"{doc['canvas_um']:g} µm canvas): {m['cpus']} CPUs ({m['processor']}), Python {m['python']}, "
        f"numpy {m['numpy']}, JAX {m['jax']} ({m['backend']}).",
    ]
    return "\n".join(lines)


TABLES = {
    "landscape": landscape_table,
    "sweep": sweep_table,
    "accuracy": accuracy_table,
    "accuracy-details": accuracy_details,
    "design-freeform": design_freeform_table,
}


def render(name: str) -> str:
    if name not in TABLES:
        raise KeyError(f"no benchmark table {name!r}; known: {', '.join(TABLES)}")
    return TABLES[name]()


# ------------------------------------------------------------------ files outside docs/
def _outside_targets(markdown: str, src_uri: str, docs_dir: Path) -> dict[str, str]:
    """{link target as written: path relative to the repository} for links that leave docs/."""
    out = {}
    for m in LINK.finditer(markdown):
        target = m.group(2)
        if "://" in target or target.startswith(("/", "mailto:")):
            continue
        resolved = posixpath.normpath(posixpath.join(posixpath.dirname(src_uri), target))
        if resolved.startswith("../"):
            rel = (docs_dir / resolved).resolve().relative_to(ROOT).as_posix()
            out[target] = rel
    return out


def on_files(files, config):
    from mkdocs.structure.files import File

    docs_dir = Path(config["docs_dir"])
    wanted = set()
    for f in files.documentation_pages():
        wanted |= set(
            _outside_targets(
                Path(f.abs_src_path).read_text(encoding="utf-8"), f.src_uri, docs_dir
            ).values()
        )
    for rel in sorted(wanted):
        path = ROOT / rel
        if path.is_file():
            files.append(File.generated(config, f"{REPO_PREFIX}/{rel}", abs_src_path=str(path)))
    return files


# ------------------------------------------------------------------------ API reference
def face_names(package: str) -> list[str]:
    """The public names of a package, as its ``__all__`` has them: those its ``__init__.pyi``
    re-exports (``from ._x import name as name``), else a literal ``__all__`` in ``__init__.py``."""
    folder = ROOT.joinpath(*package.split("."))
    stub = folder / "__init__.pyi"
    if stub.exists():
        tree = ast.parse(stub.read_text(encoding="utf-8"))
        return [
            a.asname or a.name
            for node in tree.body
            if isinstance(node, ast.ImportFrom)
            for a in node.names
            if a.asname in (None, a.name)
        ]
    tree = ast.parse((folder / "__init__.py").read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            getattr(t, "id", None) == "__all__" for t in node.targets
        ):
            return list(ast.literal_eval(node.value))
    return []


def _api_block(m: re.Match) -> str:
    names = face_names(m.group(1))
    if not names:
        return m.group(0)
    return f"::: {m.group(1)}\n    options:\n      members: [{', '.join(names)}]"


def on_page_markdown(markdown, page, config, files):
    if page.file.src_uri.startswith("api/"):
        markdown = API_BLOCK.sub(_api_block, markdown)

    def table(m):
        try:
            return render(m.group(1))
        except (KeyError, OSError, ValueError) as e:
            log.warning(f"{page.file.src_uri}: benchmark table {m.group(1)!r}: {e}")
            return m.group(0)

    markdown = MARKER.sub(table, markdown)
    targets = _outside_targets(markdown, page.file.src_uri, Path(config["docs_dir"]))

    def link(m):
        rel = targets.get(m.group(2))
        if rel is None:
            return m.group(0)
        if not (ROOT / rel).is_file():
            log.warning(
                f"{page.file.src_uri}: link to {m.group(2)!r}: no file {rel} in the repository"
            )
            return m.group(0)
        new = posixpath.relpath(f"{REPO_PREFIX}/{rel}", posixpath.dirname(page.file.src_uri) or ".")
        return f"{m.group(1)}{new}{m.group(3) or ''}{m.group(4)}"

    return LINK.sub(link, markdown)


def on_page_content(html, page, config, files):
    return ROLE.sub(
        lambda m: f"<code>{m.group(2).split('.')[-1] if m.group(1) else m.group(2)}</code>", html
    )


if __name__ == "__main__":
    for name in sys.argv[1:] or TABLES:
        print(render(name), end="\n\n")
