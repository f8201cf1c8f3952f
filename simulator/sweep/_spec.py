"""The plan of a design sweep: the sweep file, its axes and its points (:mod:`simulator.sweep` runs them).

:func:`load_sweep` reads and checks a sweep file (TOML) or the same structure as a dict
into a :class:`SweepSpec`: the base scene, the design, the axes (:data:`AXES` and the
design's parameters, each an :class:`Axis`) and how points are drawn (a grid, or a Latin
hypercube of ``samples``; ``realizations``; the seeds). :meth:`SweepSpec.points` lists
every point (a :class:`SweepPoint`) with its explicit ``point_seed``, :meth:`SweepSpec.task`
the :class:`PointTask` a worker runs; :attr:`SweepSpec.digest` identifies the
sweep (what a results directory is checked against). The axes (:data:`AXES`, :class:`Axis`
and their parsing) are :mod:`simulator.sweep`, importable from here. Nothing heavy is
imported here.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import os
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from foundation import InputError, require, require_regular_file
from patterns import check_nesting, show_value
from simulator.sweep._axes import (
    AXES,
    HARD_MAX_POINTS,
    Axis,
    _design_axes,
    _parse_axis,
    axis_kinds,
)
from simulator.sweep._task import PointTask, SweepPoint

__all__ = ["DEFAULT_MAX_POINTS", "SweepSpec", "load_sweep", "read_toml_file"]

#: Version of the point plan: part of the hash, so a plan drawn differently is another sweep.
SPEC_VERSION = 1
#: Points a sweep may have without ``--max-points``.
DEFAULT_MAX_POINTS = 2000
#: Largest sweep file (bytes).
MAX_SWEEP_BYTES = 1 << 20

SECTIONS = ("scene", "design", "axes", "sweep")
SWEEP_KEYS = (
    "seed",
    "realizations",
    "samples",
    "yield_starts",
    "capture_grid",
    "independent_noise",
)


# ----------------------------------------------------------------------- the spec
def read_toml_file(path: Path, what: str = "sweep file") -> dict:
    """A TOML file (a sweep or design file, named ``what`` in errors) parsed safely: a regular
    file, at most MAX_SWEEP_BYTES, UTF-8, nested no deeper than a scene file may be."""
    from simulator.scene import MAX_ARRAY_ITEMS, MAX_DEPTH

    require_regular_file(path, what.removesuffix(" file"))
    size = path.stat().st_size
    require(
        size <= MAX_SWEEP_BYTES, f"{what} {path} is {size:,} bytes; at most {MAX_SWEEP_BYTES:,}"
    )
    try:
        text = path.read_bytes().decode("utf-8").removeprefix("\ufeff")
        doc = tomllib.loads(text)
    except UnicodeDecodeError:
        raise InputError(f"{what} {path} is not UTF-8 text; save it as UTF-8") from None
    except tomllib.TOMLDecodeError as err:
        raise InputError(f"{what} {path} is not valid TOML: {' '.join(str(err).split())}") from None
    except (RecursionError, ValueError) as err:
        raise InputError(
            f"{what} {path} is not a usable TOML file: {' '.join(str(err).split())[:200]}"
        ) from None
    hit = check_nesting(doc, MAX_DEPTH, MAX_ARRAY_ITEMS)
    if hit:
        raise InputError(f"{what} {path}: {hit[0]} {hit[1]}")
    return doc


def _digest_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _point_seed(seed: int, realization: int, index: int, independent: bool) -> int:
    """The explicit seed of a point's placement noise: numpy's SeedSequence of the sweep seed and
    the realization (common random numbers: every design of one realization is judged on the same
    draws), or with ``independent`` of the point's index (a different draw for every point)."""
    key = (1, index) if independent else (0, realization)
    return int(np.random.SeedSequence(entropy=seed, spawn_key=key).generate_state(1, np.uint32)[0])


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep: base scene, design, axes and how points are drawn.

    Build it with :func:`load_sweep`. ``digest`` (sha256) identifies it: the base scene,
    design, axes, sampling and the contents of every file it reads.
    """

    source: str
    base_dir: Path
    scene: dict
    design: dict | None
    axes: tuple[Axis, ...]
    samples: int | None = None
    seed: int = 0
    realizations: int = 1
    yield_starts: int = 2000
    capture_grid: int = 25
    files: dict = field(default_factory=dict)
    independent_noise: bool = False

    @property
    def swept(self) -> tuple[Axis, ...]:
        """The axes that take more than one value."""
        return tuple(a for a in self.axes if a.values is None or a.size > 1)

    @property
    def designs(self) -> int:
        """Points before realizations."""
        if self.samples is not None:
            return self.samples
        return math.prod(a.size for a in self.axes) if self.axes else 1

    @property
    def n_points(self) -> int:
        return self.designs * self.realizations

    def shape_text(self) -> str:
        """'grid 7 x 4' or 'Latin hypercube of 64', with the realizations."""
        if self.samples is not None:
            text = f"Latin hypercube of {self.samples} over {', '.join(a.name for a in self.swept) or 'no axis'}"
        else:
            text = "grid " + (
                " x ".join(f"{a.size} {a.name}" for a in self.swept) or "of one point"
            )
        return text + (f", {self.realizations} realizations each" if self.realizations > 1 else "")

    @property
    def digest(self) -> str:
        doc = {
            "version": SPEC_VERSION,
            "scene": self.scene,
            "design": self.design,
            "axes": [a.record() for a in self.axes],
            "samples": self.samples,
            "seed": self.seed,
            "realizations": self.realizations,
            "yield_starts": self.yield_starts,
            "capture_grid": self.capture_grid,
            "files": self.files,
            "independent_noise": self.independent_noise,
        }
        return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()

    def _design_values(self) -> Iterator[dict]:
        if self.samples is None:
            # without samples every axis is discrete (its values given)
            for combo in itertools.product(*(cast(tuple, a.values) for a in self.axes)):
                yield {a.name: v for a, v in zip(self.axes, combo, strict=True)}
            return
        rng = np.random.default_rng(np.random.SeedSequence(entropy=self.seed, spawn_key=(2**31,)))
        n = self.samples
        cols = {}
        for a in (
            self.axes
        ):  # Latin hypercube: one point per stratum of every axis, strata shuffled per axis
            u = (rng.permutation(n) + rng.random(n)) / n
            if a.values is not None:
                cols[a.name] = [a.values[min(int(x * a.size), a.size - 1)] for x in u]
                continue
            assert a.lo is not None and a.hi is not None  # no values: a continuous range
            if a.kind == "int":
                span = int(a.hi) - int(a.lo) + 1
                cols[a.name] = [int(a.lo) + min(int(x * span), span - 1) for x in u]
            else:
                cols[a.name] = [float(a.lo + x * (a.hi - a.lo)) for x in u]
        for i in range(n):
            yield {k: v[i] for k, v in cols.items()}

    def point(self, values: dict, index: int, realization: int) -> SweepPoint:
        """The point of axis ``values`` (by axis name) as the ``index``-th point, realization
        ``realization``: its explicit ``point_seed`` drawn as :meth:`points` draws it."""
        return SweepPoint(
            point=index,
            realization=realization,
            point_seed=_point_seed(self.seed, realization, index, self.independent_noise),
            values=values,
        )

    def points(self) -> list[SweepPoint]:
        """Every point, in order: ``point`` (index), ``realization``, ``point_seed``, ``values`` by axis."""
        out = []
        for values in self._design_values():
            for r in range(self.realizations):
                out.append(self.point(values, len(out), r))
        return out

    def task(self, point: SweepPoint) -> PointTask:
        """What a worker needs to run ``point`` (:func:`run_point`): plain data, no paths relative to here."""
        return PointTask(
            point=point.point,
            realization=point.realization,
            point_seed=point.point_seed,
            values=point.values,
            scene=self.scene,
            design=self.design,
            base=self.base_dir,
            yield_starts=self.yield_starts,
            capture_grid=self.capture_grid,
        )

    def columns(self, point: SweepPoint) -> dict:
        """The point's identity and settings as table columns (units in the names)."""
        row: dict = point.columns()
        kinds = {a.name: a for a in self.axes}
        for name, v in point.values.items():
            row[kinds[name].column] = v
        if self.design is not None:
            row["design"] = self.design["name"]
            dk = _design_axes(self.design["name"])
            for k, v in self.design["params"].items():
                row.setdefault(dk[k].column if k in dk else k, v)
            if "seed" in dk:
                row["seed"] = point.design_seed(self.design)
        return row

    def describe(self) -> dict:
        """JSON-ready description for sweep.json and the report."""
        return {
            "source": self.source,
            "points": self.n_points,
            "shape": self.shape_text(),
            "samples": self.samples,
            "seed": self.seed,
            "realizations": self.realizations,
            "yield_starts": self.yield_starts,
            "capture_grid": self.capture_grid,
            "independent_noise": self.independent_noise,
            "design": self.design,
            "scene": self.scene,
            "axes": [a.record() | {"column": a.column} for a in self.axes],
            "files": self.files,
        }


def load_sweep(
    spec: str | os.PathLike | dict,
    base: str | os.PathLike | None = None,
    *,
    source: str | None = None,
    continuous: bool = False,
) -> SweepSpec:
    """A :class:`SweepSpec` from a sweep file (TOML) or the same structure as a dict.

    ``base``: the directory relative paths are read from (default: the file's, or the
    working directory for a dict). ``source``: the name errors give a dict (default
    "sweep"). ``continuous``: a range ``{from, to}`` stays a continuous range (as for
    ``samples``) and no grid is required: the axes of a search (:mod:`simulator.design`),
    whose points are drawn by its optimiser, not by :meth:`SweepSpec.points`. Every problem
    is one :class:`InputError` line.
    """
    from patterns.geometry import DESIGNS
    from simulator.scene import validate_scene

    if isinstance(spec, dict):
        doc, src = copy.deepcopy(spec), source or "sweep"
        base_dir = Path(base or ".").resolve()
    else:
        path = Path(spec)
        doc, src = read_toml_file(path), str(path)
        base_dir = Path(base).resolve() if base is not None else path.resolve().parent
    require(isinstance(doc, dict), f"{src}: a sweep must be a table of sections")
    unknown = [k for k in doc if k not in SECTIONS]
    require(
        not unknown,
        f"{src}: unknown section or key {show_value(unknown[0]) if unknown else ''}; a sweep file has the tables "
        + ", ".join(f"[{s}]" for s in SECTIONS),
    )
    for s in SECTIONS:
        require(isinstance(doc.get(s, {}), dict), f"{src}: {s} must be a table ([{s}])")
    scene = dict(doc.get("scene", {}))
    validate_scene(scene, source=f"{src} [scene]")
    # [sweep]
    sw = doc.get("sweep", {})
    bad = [k for k in sw if k not in SWEEP_KEYS]
    require(
        not bad,
        f"{src}: [sweep] {bad[0] if bad else ''}: unknown key; [sweep] takes {', '.join(SWEEP_KEYS)}",
    )

    def whole(key: str, default: Any, lo: int, hi: int) -> Any:
        v = sw.get(key, default)
        if v is None:
            return None
        require(
            isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi,
            f"{src}: [sweep] {key} = {show_value(v)}: must be a whole number from {lo:,} to {hi:,}",
        )
        return v

    samples = whole("samples", None, 1, HARD_MAX_POINTS)
    seed = whole("seed", 0, 0, 2**63 - 1)
    realizations = whole("realizations", 1, 1, HARD_MAX_POINTS)
    yield_starts = whole("yield_starts", 2000, 1, 10**7)
    capture_grid = whole("capture_grid", 25, 2, 1001)
    independent = sw.get("independent_noise", False)
    require(
        isinstance(independent, bool),
        f"{src}: [sweep] independent_noise = {show_value(independent)}: must be true or false",
    )
    # [design]
    design = None
    if "design" in doc:
        d = dict(doc["design"])
        name = d.pop("name", None)
        require(
            isinstance(name, str) and name in DESIGNS,
            f"{src}: [design] name = {show_value(name)}: must be one of {', '.join(DESIGNS)}",
        )
        margin = d.pop("margin_um", 10.0)
        require(
            isinstance(margin, int | float) and not isinstance(margin, bool) and 0 <= margin <= 1e6,
            f"{src}: [design] margin_um = {show_value(margin)}: must be a number from 0 to 1e6 um",
        )
        dk = _design_axes(name)
        for k, v in d.items():
            require(
                k in dk,
                f"{src}: [design] {k}: design {name} has no parameter {k}; it has {', '.join(dk)}",
            )
            problem = dk[k].check(v)
            require(problem is None, f"{src}: [design] {k} = {show_value(v)}: {problem}")
        design = {"name": name, "margin_um": float(margin), "params": d}
    # [axes]
    raw_axes = doc.get("axes", {})
    kinds = axis_kinds(design["name"] if design else None)
    axes = []
    for name, raw in raw_axes.items():
        key = name
        if (
            key not in kinds
            and design is not None
            and key.endswith("_um")
            and key[:-3] in kinds
            and kinds[key[:-3]].column == key
        ):
            key = key[:-3]  # gap_um: the design's gap
        if key not in kinds:
            has = (
                f"design {design['name']} has {', '.join(k for k in kinds if k not in AXES) or 'no parameters'}; "
                if design
                else "no [design] is given; "
            )
            raise InputError(
                f"{src}: [axes] {name}: not a parameter of this sweep: {has}the other axes are {', '.join(AXES)}"
            )
        require(all(a.name != key for a in axes), f"{src}: [axes] gives {key} twice")
        axes.append(_parse_axis(key, raw, kinds[key], continuous or samples is not None, src))
    names = [a.name for a in axes]
    # where the pattern comes from: exactly one of [design], a pattern axis, [scene] pattern
    sources = [
        s
        for s, given in (
            ("[design]", design is not None),
            ("the pattern axis", "pattern" in names),
            ("[scene] pattern", "pattern" in scene),
        )
        if given
    ]
    require(
        len(sources) == 1,
        f'{src}: give the pattern once: a [design], a pattern axis or [scene] pattern = "file"; '
        + (f"got {' and '.join(sources)}" if sources else "got none"),
    )
    if samples is None and not continuous:
        require(
            all(a.values is not None for a in axes),
            f"{src}: a grid needs every range with num or step",
        )
    # files: absolute paths, digests
    files = {}
    for key in ("pattern", "chip"):
        if isinstance(scene.get(key), str):
            p = (base_dir / scene[key]).resolve()
            require_regular_file(p, key)
            scene[key] = str(p)
            files[str(p)] = _digest_file(p)
    for a in axes:
        for v in a.values if a.name == "pattern" else ():
            p = (base_dir / v).resolve()
            require_regular_file(p, "pattern")
            files[str(p)] = _digest_file(p)
    return SweepSpec(
        src,
        base_dir,
        scene,
        design,
        tuple(axes),
        samples,
        seed,
        realizations,
        yield_starts,
        capture_grid,
        files,
        independent,
    )
