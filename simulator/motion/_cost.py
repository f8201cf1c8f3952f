"""What one run cost: the landscape it computed against the full one, and the seconds.

Owns :class:`RunCost`, a :class:`~simulator.motion.Trajectory`'s ``cost``, measured after
the run (the price before it is :class:`~simulator.motion.RunPlan`'s). Its fields carry
their units as the trajectory JSON's ``cost`` keys do (``landscape_s``, ``total_s``);
:meth:`RunCost.to_dict` is that JSON object, key for key.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

__all__ = ["RunCost"]


@dataclass(frozen=True, kw_only=True)
class RunCost:
    """The landscape a run computed and the time it took (wall clock, s)."""

    #: the engine that ran: "fft" or "path" (the boxes of a greedy or gradient run), the
    #: engine of a dynamic run's whole landscape, "footprint planes" or "footprint path"
    #: (a run carrying its footprint, docs/physics.md §3.5)
    engine: str
    #: landscape poses computed, and those of the scene's full landscape
    poses_computed: int
    poses_full: int
    #: ``poses_computed / poses_full``
    fraction_of_full: float
    #: twist planes computed
    planes: int
    #: seconds spent on the landscape, and on the whole run (planning to packaging)
    landscape_s: float
    total_s: float
    #: poses evaluated and seconds spent finding the global minimum, and how it was found
    #: (:func:`simulator.landscape.global_minimum`)
    minimum_poses: int
    minimum_s: float
    minimum_how: str
    #: a footprint run's: the seconds of the pads' planes and the runs it was made of
    #: (None, and left out of :meth:`to_dict`, for any other run)
    footprint_planes_s: float | None = None
    footprint_pieces: int | None = None
    #: a footprint run on the FFT planes: the twists its planes were made over (a window
    #: around its start and the aligned pose, docs/physics.md §3.5)
    footprint_twists: int | None = None

    def to_dict(self) -> dict[str, Any]:
        """The trajectory JSON's ``cost``: every field in order, a footprint run's own only
        for a footprint run."""
        out = dataclasses.asdict(self)
        for k in ("footprint_planes_s", "footprint_pieces", "footprint_twists"):
            if out[k] is None:
                del out[k]
        return out
