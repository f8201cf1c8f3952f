"""The plan of a design search: a sweep file whose axes are ranges to search, and its ``[search]``.

A search file is a sweep file (:func:`simulator.sweep.load_sweep`: ``[scene]``, ``[design]``,
``[axes]``, ``[sweep]``) with a ``[search]`` table::

    [search]
    trials = 40                        # trials of the optimiser (--trials overrides)
    sampler = "tpe"                    # "tpe", "cmaes", "random", "nsga2" (Optuna's samplers)
    seed = 0                           # the sampler's seed
    maximize = "min(max_bias_x_um, max_bias_y_um)"     # or minimize = ..., or lists of both
    constraints = ["capture_fraction >= 0.99", "volume_nl >= critical_volume_nl"]

Objectives and the two sides of a constraint are expressions over the columns of a trial's
row (:func:`simulator.sweep.expected_columns`): column names, numbers, ``+ - * /``,
``abs(x)``, ``min``/``max`` of several expressions (the smaller / larger), and over the
realizations of a trial ``mean(x)``, ``min(x)`` and ``max(x)`` of one expression (the
average, the worst and the best realization). An expression that still varies over the
realizations is averaged. They are parsed with :mod:`ast` against a whitelist
(:func:`parse_expression`); nothing is ever evaluated by Python.

Axes: a range ``{from, to}`` is searched continuously (a whole-number parameter as whole
numbers), a stepped range ``{from, to, step}`` (or ``num``) or a list of numbers as its
values in order, a list of names (``method``, ``pattern``) as categories, and one value is
fixed. Nothing heavy is imported here.
"""

from __future__ import annotations

import ast
import copy
import hashlib
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from foundation import InputError, require
from patterns import show_value

__all__ = [
    "SAMPLERS",
    "Constraint",
    "Expression",
    "SearchSpec",
    "load_search",
    "parse_constraints",
    "parse_expression",
]

#: Optuna's samplers a search may use, by their name in ``[search] sampler``.
SAMPLERS = ("tpe", "cmaes", "random", "nsga2")
#: The keys of ``[search]``.
SEARCH_KEYS = ("trials", "sampler", "seed", "maximize", "minimize", "constraints")
#: The most trials a search may have.
MAX_TRIALS = 100_000
#: The longest expression (characters).
MAX_EXPRESSION = 500
#: The deepest an expression may nest (operators, calls and signs inside each other).
MAX_DEPTH = 100
#: The functions an expression may call.
FUNCTIONS = ("abs", "min", "max", "mean")
#: Version of the search plan: part of the hash.
SEARCH_VERSION = 1
#: Columns a search row has besides the sweep's: the droplet's volume as ``volume_nl`` also
#: when the volume is not an axis (the scene's, ``settings_volume_nl``).
EXTRA_COLUMNS = ("volume_nl",)

_OPS = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide}
_COMPARE = {ast.GtE: ">=", ast.LtE: "<=", ast.Gt: ">", ast.Lt: "<"}


# ----------------------------------------------------------------------- expressions
def _walk_check(node: ast.AST, where: str, known: tuple[str, ...]) -> None:
    """Raise InputError unless ``node`` is made of whitelisted pieces over ``known`` columns."""
    if isinstance(node, ast.Constant):
        ok = isinstance(node.value, int | float) and not isinstance(node.value, bool)
        require(ok, f"{where}: {show_value(node.value)} is not a number")
        try:
            finite = math.isfinite(cast(float, node.value))  # a number (required above)
        except OverflowError:  # an integer literal beyond a float's range
            finite = False
        require(finite, f"{where}: {show_value(node.value)} is not a finite number")
    elif isinstance(node, ast.Name):
        if node.id not in known:
            raise InputError(
                f"{where}: unknown column {node.id}; the columns of this search's trials are "
                + ", ".join(known)
            )
    elif isinstance(node, ast.BinOp) and type(node.op) in _OPS:
        _walk_check(node.left, where, known)
        _walk_check(node.right, where, known)
    elif isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.UAdd | ast.USub):
        _walk_check(node.operand, where, known)
    elif isinstance(node, ast.Call):
        name = node.func.id if isinstance(node.func, ast.Name) else None
        require(
            name in FUNCTIONS,
            f"{where}: {ast.unparse(node.func)}() is not a function of an expression; "
            f"use {', '.join(FUNCTIONS)}",
        )
        require(not node.keywords, f"{where}: {name}() takes no keyword arguments")
        require(
            bool(node.args) and not any(isinstance(a, ast.Starred) for a in node.args),
            f"{where}: {name}() needs an expression to work on",
        )
        require(
            name not in ("abs", "mean") or len(node.args) == 1,
            f"{where}: {name}() takes one expression",
        )
        for a in node.args:
            _walk_check(a, where, known)
    else:
        what = ast.unparse(node) if hasattr(ast, "unparse") else type(node).__name__
        raise InputError(
            f"{where}: {what!r} is not allowed in an expression; use column names, numbers, "
            f"+ - * /, and {', '.join(FUNCTIONS)}"
        )


def _value(node: ast.AST, data: Mapping[str, Any]) -> np.ndarray:
    """The node's value: a number, or an array over the realizations."""
    if isinstance(node, ast.Constant):
        return np.asarray(float(cast(float, node.value)))  # a number (checked when parsed)
    if isinstance(node, ast.Name):
        return np.asarray(data[node.id], dtype=float)
    if isinstance(node, ast.BinOp):
        return _OPS[type(node.op)](_value(node.left, data), _value(node.right, data))
    if isinstance(node, ast.UnaryOp):
        v = _value(node.operand, data)
        return -v if isinstance(node.op, ast.USub) else v
    assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
    args = [_value(a, data) for a in node.args]
    name = node.func.id
    if name == "abs":
        return np.abs(args[0])
    if name == "mean":
        return np.asarray(np.mean(args[0]))
    if len(args) == 1:  # over the realizations: the worst or best one
        return np.asarray(np.min(args[0]) if name == "min" else np.max(args[0]))
    return (np.minimum if name == "min" else np.maximum).reduce(np.broadcast_arrays(*args))


@dataclass(frozen=True)
class Expression:
    """A parsed expression over a trial's columns (:func:`parse_expression`)."""

    text: str
    tree: ast.expr
    columns: tuple[str, ...]

    def __call__(self, data: Mapping[str, Any]) -> float:
        """The value for ``data`` (column -> a number or one per realization), averaged over
        the realizations when it still varies over them. Raises KeyError for a column the
        data lacks."""
        with np.errstate(all="ignore"):
            v = _value(self.tree, data)
            return float(np.mean(v)) if v.size else math.nan


def _parse(text: Any, where: str) -> ast.expr:
    require(
        isinstance(text, str) and bool(text.strip()),
        f"{where}: {show_value(text)}: must be an expression in quotes",
    )
    require(len(text) <= MAX_EXPRESSION, f"{where}: longer than {MAX_EXPRESSION} characters")
    try:
        tree = ast.parse(text.strip(), mode="eval").body
    except (SyntaxError, ValueError, RecursionError, MemoryError) as err:
        msg = getattr(err, "msg", None) or type(err).__name__
        raise InputError(f"{where}: {show_value(text, 80)} is not an expression ({msg})") from None
    _check_depth(tree, where)
    return tree


def _check_depth(tree: ast.AST, where: str) -> None:
    """InputError (naming ``where``) when ``tree`` nests deeper than :data:`MAX_DEPTH`; iterative,
    so the check itself never recurses (everything after it walks the tree recursively)."""
    stack = [(tree, 1)]
    while stack:
        node, depth = stack.pop()
        require(
            depth <= MAX_DEPTH,
            f"{where}: the expression nests more than {MAX_DEPTH} levels deep (signs, operators "
            "and calls inside each other); simplify it",
        )
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))


def _names(node: ast.AST) -> tuple[str, ...]:
    return tuple(dict.fromkeys(n.id for n in ast.walk(node) if isinstance(n, ast.Name)))


def _expression(tree: ast.expr, where: str, known: tuple[str, ...]) -> Expression:
    _walk_check(tree, where, known)
    return Expression(ast.unparse(tree), tree, tuple(c for c in _names(tree) if c in known))


def parse_expression(text: str, known, where: str = "expression") -> Expression:
    """``text`` parsed into an :class:`Expression` over the columns ``known``; InputError (one
    line naming ``where``) for a comparison, an unknown column (the known ones listed), a
    function other than abs, min, max, mean, or anything else Python would do."""
    known = tuple(known)
    tree = _parse(text, where)
    require(
        not isinstance(tree, ast.Compare),
        f"{where}: {show_value(text, 80)} is a comparison; an objective is an expression to "
        "maximize or minimize (comparisons go into constraints)",
    )
    return _expression(tree, where, known)


@dataclass(frozen=True)
class Constraint:
    """``lhs op rhs`` (op one of >=, <=, >, <): the trial is feasible when :meth:`violation` <= 0."""

    text: str
    lhs: Expression
    op: str
    rhs: Expression

    def violation(self, data: Mapping[str, Any]) -> float:
        """How far the trial is from meeting the constraint (<= 0: met), in the sides' units:
        ``rhs - lhs`` for >=, ``lhs - rhs`` for <= (a strict one is not met on equality)."""
        a, b = self.lhs(data), self.rhs(data)
        v = b - a if self.op in (">=", ">") else a - b
        if self.op in (">", "<") and v == 0:
            return float(np.finfo(float).tiny)
        return float(v)


def parse_constraints(text: Any, known, where: str = "constraint") -> list[Constraint]:
    """The :class:`Constraint` of a comparison over the columns ``known`` (``0.5 <= x <= 0.9``
    gives two); InputError (one line naming ``where``) for anything but >=, <=, > or < between
    two expressions (:func:`parse_expression`)."""
    known = tuple(known)
    tree = _parse(text, where)
    require(
        isinstance(tree, ast.Compare),
        f"{where}: {show_value(text, 80)} is not a comparison; write e.g. "
        '"capture_fraction >= 0.99" (with >=, <=, > or <)',
    )
    assert isinstance(tree, ast.Compare)  # required above
    sides = [tree.left, *tree.comparators]
    out = []
    for k, op in enumerate(tree.ops):
        require(
            type(op) in _COMPARE,
            f"{where}: {show_value(text, 80)}: compare with >=, <=, > or <, not {type(op).__name__}",
        )
        lhs = _expression(sides[k], where, known)
        rhs = _expression(sides[k + 1], where, known)
        out.append(
            Constraint(f"{lhs.text} {_COMPARE[type(op)]} {rhs.text}", lhs, _COMPARE[type(op)], rhs)
        )
    return out


# ----------------------------------------------------------------------- the spec
@dataclass(frozen=True)
class Objective:
    """One objective: ``direction`` "maximize" or "minimize" of ``expression``."""

    direction: str
    expression: Expression

    @property
    def text(self) -> str:
        return f"{self.direction} {self.expression.text}"


@dataclass(frozen=True)
class SearchSpec:
    """A validated search: the sweep it searches (:class:`simulator.sweep.SweepSpec`, its
    axes the search space), the trials, the sampler and its seed, the objectives and the
    constraints. Build it with :func:`load_search`. ``digest`` identifies it (everything but
    the number of trials, so a rerun with more trials goes on with the same search)."""

    sweep: Any
    trials: int
    sampler: str
    seed: int
    objectives: tuple[Objective, ...]
    constraints: tuple[Constraint, ...]
    columns: tuple[str, ...]

    @property
    def columns_used(self) -> tuple[str, ...]:
        """The columns the objectives and constraints read."""
        exprs = [o.expression for o in self.objectives]
        exprs += [e for c in self.constraints for e in (c.lhs, c.rhs)]
        return tuple(dict.fromkeys(c for e in exprs for c in e.columns))

    @property
    def source(self) -> str:
        return self.sweep.source

    @property
    def searched(self) -> tuple:
        """The axes searched: a range, or more than one value."""
        return self.sweep.swept

    @property
    def fixed(self) -> dict:
        """The axes of one value, by name."""
        return {
            a.name: a.values[0] for a in self.sweep.axes if a.values is not None and a.size == 1
        }

    @property
    def space_size(self) -> int | None:
        """Designs in the search space when every searched axis is discrete, else None."""
        if any(a.values is None for a in self.searched):
            return None
        return math.prod(a.size for a in self.searched)

    @property
    def digest(self) -> str:
        doc = {
            "version": SEARCH_VERSION,
            "sweep": self.sweep.digest,
            "sampler": self.sampler,
            "seed": self.seed,
            "objectives": [o.text for o in self.objectives],
            "constraints": [c.text for c in self.constraints],
        }
        return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()

    def distributions(self) -> dict:
        """The Optuna distribution of every searched axis: a range as itself (whole numbers for
        an integer parameter), numbers as the index of their value in order (ordered, so TPE
        and CMA-ES see neighbours), names as categories."""
        from optuna.distributions import (
            CategoricalDistribution,
            FloatDistribution,
            IntDistribution,
        )

        out = {}
        for a in self.searched:
            if a.values is None:
                out[a.name] = (
                    IntDistribution(int(a.lo), int(a.hi))
                    if a.kind == "int"
                    else FloatDistribution(float(a.lo), float(a.hi))
                )
            elif a.kind in ("number", "int"):
                out[a.name] = IntDistribution(0, a.size - 1)
            else:
                out[a.name] = CategoricalDistribution(list(a.values))
        return out

    def values(self, params: Mapping[str, Any]) -> dict:
        """A trial's axis values (by axis name) from the optimiser's ``params``, the fixed axes too."""
        out = {}
        for a in self.sweep.axes:
            if a.values is not None and a.size == 1:
                out[a.name] = a.values[0]
            elif a.values is None:
                v = params[a.name]
                out[a.name] = int(v) if a.kind == "int" else float(v)
            elif a.kind in ("number", "int"):
                out[a.name] = sorted(a.values)[int(params[a.name])]
            else:
                out[a.name] = params[a.name]
        return out

    def params(self, values: Mapping[str, Any]) -> dict | None:
        """The optimiser's params of axis ``values`` (the inverse of :meth:`values`), or None
        when a searched axis has no value or one outside its range."""
        out = {}
        for a in self.searched:
            v = values.get(a.name)
            if v is None:
                return None
            if a.values is None:
                if not (a.lo <= v <= a.hi):
                    return None
                out[a.name] = v
            elif a.kind in ("number", "int"):
                order = sorted(a.values)
                if v not in order:
                    return None
                out[a.name] = order.index(v)
            else:
                if v not in a.values:
                    return None
                out[a.name] = v
        return out

    def baseline_values(self) -> dict | None:
        """The baseline's axis values: the fixed axes; a searched axis takes the file's
        ``[design]`` or ``[scene]`` value, so it is left out. None when a searched design
        parameter has no ``[design]`` value (there is no baseline design)."""
        design = self.sweep.design
        keys = _design_keys(design) if design is not None else ()
        for a in self.searched:
            if a.name == "pattern" or (
                design is not None and a.name in keys and a.name not in design["params"]
            ):
                return None
        return dict(self.fixed)

    def baseline_settings(self) -> dict:
        """The baseline's value of each searched axis where the file gives one (by axis name)."""
        from simulator.scene import sweep_places

        design, scene = self.sweep.design, self.sweep.scene
        places = sweep_places()  # where the scene file keeps a scene axis's value
        out = {}
        for a in self.searched:
            if design is not None and a.name in design["params"]:
                out[a.name] = design["params"][a.name]
            elif a.name in places:
                table, key = places[a.name]
                v = (scene.get(table) or {}).get(key) if table else scene.get(key)
                if isinstance(v, int | float) and not isinstance(v, bool):
                    out[a.name] = v
        return out

    def describe(self) -> dict:
        """JSON-ready description for search.json and the report."""
        return {
            "source": self.source,
            "sampler": self.sampler,
            "seed": self.seed,
            "objectives": [
                {"direction": o.direction, "expression": o.expression.text} for o in self.objectives
            ],
            "constraints": [c.text for c in self.constraints],
            "searched": [a.record() | {"column": a.column} for a in self.searched],
            "sweep": self.sweep.describe() | {"hash": self.sweep.digest},
        }


def _design_keys(design: dict) -> tuple[str, ...]:
    from simulator.sweep import AXES, axis_kinds

    return tuple(k for k in axis_kinds(design["name"]) if k not in AXES)


def _numeric_columns(sw, columns: list[str]) -> tuple[str, ...]:
    """The columns an expression may read: a trial's numbers (not the sweep's point identity,
    the status and error, or a parameter that takes names)."""
    from simulator.sweep import axis_kinds

    kinds = axis_kinds(sw.design["name"] if sw.design else None)
    words = {k.column for k in kinds.values() if k.kind in ("choice", "path")}
    words |= {"point", "realization", "point_seed", "design", "status", "error"}
    return tuple(dict.fromkeys(c for c in [*columns, *EXTRA_COLUMNS] if c not in words))


def _texts(v: Any, where: str) -> list:
    if isinstance(v, str):
        return [v]
    require(
        isinstance(v, list) and bool(v) and all(isinstance(t, str) for t in v),
        f"{where} = {show_value(v, 60)}: must be an expression in quotes or a list of them",
    )
    return list(v)


def load_search(
    spec: str | os.PathLike | dict,
    base: str | os.PathLike | None = None,
    *,
    source: str | None = None,
) -> SearchSpec:
    """A :class:`SearchSpec` from a search file (TOML) or the same structure as a dict.

    ``base``: the directory relative paths are read from (default: the file's, or the working
    directory for a dict); ``source``: the name errors give a dict. Every problem is one
    :class:`~foundation.InputError` line, before any work.
    """
    from simulator.sweep import expected_columns, load_sweep, read_toml_file

    if isinstance(spec, dict):
        doc, src = copy.deepcopy(spec), source or "search"
        base_dir = Path(base or ".").resolve()
    else:
        path = Path(spec)
        doc, src = read_toml_file(path, "design file"), source or str(path)
        base_dir = Path(base).resolve() if base is not None else path.resolve().parent
    require(isinstance(doc, dict), f"{src}: a search must be a table of sections")
    sections = ("scene", "design", "axes", "sweep", "search")
    unknown = [k for k in doc if k not in sections]
    require(
        not unknown,
        f"{src}: unknown section or key {show_value(unknown[0]) if unknown else ''}; a search file "
        "has the tables " + ", ".join(f"[{s}]" for s in sections),
    )
    table = doc.pop("search", None)
    require(isinstance(table, dict), f"{src}: a search file needs a [search] table")
    require(
        "samples" not in (doc.get("sweep") or {}),
        f"{src}: [sweep] samples is not used by a search: its trials are drawn by the optimiser "
        "([search] trials)",
    )
    sw = load_sweep(doc, base_dir, source=src, continuous=True)
    bad = [k for k in table if k not in SEARCH_KEYS]
    require(
        not bad,
        f"{src}: [search] {bad[0] if bad else ''}: unknown key; [search] takes {', '.join(SEARCH_KEYS)}",
    )
    require(
        bool(sw.swept),
        f"{src}: [axes] gives nothing to search; give an axis a range {{from = A, to = B}} or a list",
    )

    def whole(key: str, default: Any, lo: int, hi: int) -> int:
        v = table.get(key, default)
        require(
            isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi,
            f"{src}: [search] {key} = {show_value(v)}: must be a whole number from {lo:,} to {hi:,}",
        )
        return v

    require("trials" in table, f"{src}: [search] needs trials = N (the optimiser's trials)")
    trials = whole("trials", None, 1, MAX_TRIALS)
    seed = whole("seed", 0, 0, 2**32 - 1)
    sampler = table.get("sampler", "tpe")
    require(
        sampler in SAMPLERS,
        f"{src}: [search] sampler = {show_value(sampler)}: must be one of {', '.join(SAMPLERS)}",
    )
    known = _numeric_columns(sw, expected_columns(sw))
    objectives = []
    for direction in ("maximize", "minimize"):
        if direction in table:
            for k, text in enumerate(_texts(table[direction], f"{src}: [search] {direction}")):
                where = f"{src}: [search] {direction}" + (f"[{k}]" if k else "")
                objectives.append(Objective(direction, parse_expression(text, known, where)))
    require(
        bool(objectives),
        f'{src}: [search] needs an objective: maximize = "..." or minimize = "..." (an expression '
        'over the columns, e.g. maximize = "min(max_bias_x_um, max_bias_y_um)")',
    )
    if len(objectives) > 1:
        require(
            sampler != "cmaes",
            f'{src}: [search] sampler = "cmaes" optimises one objective; with {len(objectives)} '
            'use "tpe", "nsga2" or "random"',
        )
    constraints = []
    raw = table.get("constraints", [])
    require(
        isinstance(raw, list),
        f"{src}: [search] constraints = {show_value(raw, 60)}: must be a list of comparisons in quotes",
    )
    for k, text in enumerate(raw):
        constraints += parse_constraints(text, known, f"{src}: [search] constraints[{k}]")
    if sampler == "cmaes":
        require(
            any(a.kind in ("number", "int") for a in sw.swept),
            f'{src}: [search] sampler = "cmaes" needs a numeric axis to search',
        )
    return SearchSpec(sw, trials, sampler, seed, tuple(objectives), tuple(constraints), known)
