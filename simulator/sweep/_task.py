"""A point of a design sweep and the task that runs it: frozen, typed, picklable.

:meth:`simulator.sweep.SweepSpec.points` lists :class:`SweepPoint` s (a point's index, its
realization, the explicit seed of its placement noise and its axis values);
:meth:`simulator.sweep.SweepSpec.task` adds what a worker needs to run one
(:class:`PointTask`: the base scene document, the design, the directory relative paths are
read from, the yield's starts and the capture grid), which :func:`simulator.sweep.run_point`
runs. Dask ships a task to its worker pickled; a frozen dataclass of plain data pickles as
it is. The sweep file and its seeds: docs/guide/sweeps.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

__all__ = ["ID_COLUMNS", "PointTask", "SweepPoint"]


@dataclass(frozen=True)
class SweepPoint:
    """One point of a sweep (docs/guide/sweeps.md, "Seeds").

    Attributes:
        point: the point's index in the sweep's order (0, 1, ...; a design search's trial
            ``i`` of ``R`` realizations runs points ``i * R`` to ``i * R + R - 1``).
        realization: which realization of its design (0 to ``realizations - 1``).
        point_seed: the explicit seed (a 32-bit whole number) of the point's placement
            noise, drawn from the sweep seed and the realization (or, with
            ``independent_noise``, the point's index).
        values: the point's value of each axis, by axis name (in the axis's unit: ``gap``
            in um, ``volume_nl`` in nl, ``pattern`` a path relative to the sweep file, ...).
    """

    point: int
    realization: int
    point_seed: int
    values: Mapping[str, Any] = field(hash=False)

    def columns(self) -> dict[str, int]:
        """The point's own columns (:data:`ID_COLUMNS`), first in every table."""
        return {k: getattr(self, k) for k in ID_COLUMNS}

    def design_seed(self, design: Mapping[str, Any]) -> int:
        """A seeded design's (random-jagged) seed at this point: the ``seed`` axis's value,
        else the ``[design]``'s (default 0), plus the realization."""
        return int(self.values.get("seed", design["params"].get("seed", 0))) + self.realization


#: The point's own columns, first in every table of a sweep: its fields but the values.
ID_COLUMNS = tuple(f.name for f in fields(SweepPoint) if f.name != "values")


@dataclass(frozen=True)
class PointTask(SweepPoint):
    """A :class:`SweepPoint` with what a worker needs to run it (:func:`simulator.sweep.run_point`).

    Attributes:
        scene: the sweep's base scene document (the ``[scene]`` table, its ``pattern`` and
            ``chip`` files made absolute); the point's axis values go on top of it.
        design: the sweep's ``[design]``: ``name``, ``margin_um`` (um) and ``params`` (the
            generator's parameters, lengths in um); None without one.
        base: the directory the point's relative paths (a ``pattern`` axis's files) are
            read from: the sweep file's.
        yield_starts: the yield's placements under noise per point (``[sweep] yield_starts``).
        capture_grid: the capture map's starts per side (``[sweep] capture_grid``).
    """

    scene: Mapping[str, Any] = field(hash=False)
    design: Mapping[str, Any] | None = field(hash=False)
    base: Path
    yield_starts: int
    capture_grid: int
