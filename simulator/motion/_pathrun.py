"""A greedy or gradient run at the cost of its path: small boxes of the landscape that
follow the chip, computed pose by pose (:class:`simulator.landscape.PathEnergy`), and the
choice between that and the FFT boxes (:func:`choose_engine`).

The steppers are today's, unchanged: each box is a landscape on the grid the FFT engine
would give, cut on its sides; the run stops at a cut side (status EDGE) and resumes in
the next box, centred on the chip (greedy and gradient are memoryless, so the path is the
path on the whole landscape). Poses that boxes share are computed once.
"""

from __future__ import annotations

from collections.abc import Generator, Sequence
from typing import TYPE_CHECKING, Any, overload

import numpy as np

from foundation import counter_bar
from simulator.landscape import (
    Landscape,
    PathEnergy,
    PoseGrid,
    consecutive_runs,
    path_engine_supported,
)
from simulator.scene import Scene

if TYPE_CHECKING:
    from simulator.landscape import FootprintPath
    from simulator.motion._field import Relay
    from simulator.motion._pinning import PinLines

ENGINES = ("auto", "fft", "path")
#: Half-width (px) and twist half-band (steps) of the boxes that follow the chip. Greedy
#: stops at a box's side, gradient 2 grid steps before it (its differences and interpolation
#: reach that far), so gradient needs wider boxes to move at all.
FOLLOW_BOX = {"greedy": (4, 1), "gradient": (6, 3)}
#: "auto" takes the path engine for chips of at least this many pixels (wettable bounding
#: box, width x height), per method. Measured on a 2-core CPU, four-pad under its own
#: square chip at 1 um/px from (0.3 L, -0.2 L, 10 deg), best of two, both engines warm:
#: greedy 400 px 1.0 s (path) vs 1.2 s (FFT), 730 px 1.5 vs 6.7 s, 1000 px 2.0 vs 16.6 s;
#: gradient 400 px 2.2 vs 1.0 s, 730 px 1.9 vs 1.5 s, 1000 px 3.4 vs 3.2 s, 2000 px 11.3 vs
#: 17.0 s. The thresholds sit above those crossovers with a margin (the engines' costs
#: also depend on the path and the pattern), so smaller chips keep the FFT engine.
AUTO_MIN_CHIP_PX = {"greedy": 1000 * 1000, "gradient": 2000 * 2000}
#: The same for the free contact lines' footprint (the default meniscus), whose FFT boxes
#: cost more (the footprint rotated onto the whole canvas at every twist, a wider canvas)
#: while the path engine reads the band's pixels once per twist: measured below.
AUTO_MIN_CHIP_PX_MENISCUS = {"greedy": 0, "gradient": 0}


def _chip_px(scene: Scene) -> int:
    """Pixels of the chip's wettable bounding box (width x height)."""
    from patterns.geometry import footprint_um

    w, h = footprint_um(scene.chip)
    return int(round(w / scene.um_per_px) * round(h / scene.um_per_px))


def choose_engine(
    scene: Scene,
    start: Sequence[float],
    method: str,
    engine: str,
    band_steps: int,
    band_px: int,
) -> str:
    """ "fft" or "path" for a greedy or gradient run without a landscape (``engine``: as asked;
    "auto": the path engine where it covers the scene, the run's outcome is classified the
    same, and the chip is large enough for it to be the faster, :data:`AUTO_MIN_CHIP_PX`)."""
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    ok, why = path_engine_supported(scene)
    if engine == "path" and not ok:
        from foundation import InputError

        raise InputError(f"the path-cost engine does not cover this scene: {why}")
    if engine != "auto":
        return engine
    if not ok or method not in AUTO_MIN_CHIP_PX:
        return "fft"
    least = AUTO_MIN_CHIP_PX_MENISCUS if scene.wall_profile is not None else AUTO_MIN_CHIP_PX
    return "path" if _chip_px(scene) >= least[method] else "fft"


class StateBoxes:
    """One footprint state's boxes for the path engine (docs/physics.md §3.5): what
    :func:`path_boxes` asks of a :class:`~simulator.landscape.PathEnergy`, from the pads'
    energies, relay flags and pairs' corrections of each box
    (:class:`~simulator.landscape.FootprintPath`), summed for the wet pads ``wet``; each box
    carries its relay flags (``stats["relay"]``, :meth:`relay`). ``plain``: the stateless
    engine of the scene, which the run's global minimum reads (the aligned pose, where every
    pad is covered and the all-wet state's energy is the stateless one)."""

    def __init__(
        self, footprint: FootprintPath, plain: PathEnergy, wet: Sequence[bool] | np.ndarray
    ) -> None:
        self.footprint, self.plain = footprint, plain
        self.wet = np.asarray(wet, bool)
        self.bits = np.packbits(self.wet, bitorder="little")
        self._lines_pattern = None  # the state's pinning pattern, made on the first box

    def box(
        self, twist_idx: Sequence[int], center_px: tuple[int, int], half_px: int | None
    ) -> Landscape:
        pl = self.footprint.box(twist_idx, center_px, half_px)
        ls = pl.landscape(self.wet)
        ls.stats["relay"] = (pl.reached_bits, pl.within_bits)
        return ls

    def relay(self, ls: Landscape, lines: PinLines | None = None) -> Relay:
        """The steppers' :class:`simulator.motion.Relay` of a box made here; with the run's
        pinning ``lines``, their pattern on this state made once for all its boxes
        (:attr:`Relay.lines_pattern`: a 4000 um chip's run sets the relay on hundreds of
        boxes, and the pattern is millions of pixels)."""
        import jax.numpy as jnp

        from simulator.motion._field import Relay, wet_pattern_jit

        reached, within = ls.stats["relay"]
        if lines is not None and self._lines_pattern is None:
            self._lines_pattern = wet_pattern_jit(lines.pattern, lines.labels, self.bits)
        return Relay(
            jnp.asarray(reached),
            jnp.asarray(within),
            jnp.asarray(self.bits),
            lines_pattern=None if lines is None else self._lines_pattern,
        )

    def drop_outlines(self, keep: set[int]) -> None:
        self.footprint.drop_outlines(keep)

    def prefetch(self, k: int) -> None:
        """Nothing ahead: a state's footprints are made as the boxes ask for them."""

    def close(self) -> None:
        self.footprint.close()

    @property
    def poses(self) -> int:
        return self.footprint.poses

    @property
    def rotations(self) -> int:
        return self.footprint.rotations

    @property
    def seconds(self) -> float:
        return self.footprint.seconds


#: What :func:`path_boxes` yields: sent the chip's pose (x_um, y_um, twist_deg), the box
#: around it, or None.
_BoxGenerator = Generator[Landscape | None, np.ndarray, None]


@overload
def path_boxes(
    scene: Scene, method: str, cost: object, source: None = None
) -> tuple[_BoxGenerator, PathEnergy]: ...
@overload
def path_boxes(
    scene: Scene, method: str, cost: object, source: StateBoxes
) -> tuple[_BoxGenerator, StateBoxes]: ...
def path_boxes(
    scene: Scene, method: str, cost: object, source: StateBoxes | None = None
) -> tuple[_BoxGenerator, PathEnergy | StateBoxes]:
    """(generator, engine): the generator is sent the chip's pose and yields the box around
    it (None when the box would be the last one again: the chip cannot move on), as
    :func:`simulator.motion._trajectory._box_landscapes` does. ``source``: a footprint
    state's boxes (:class:`StateBoxes`) instead of the scene's stateless energy; each box
    then carries the relay's flags of its twists (``stats["relay"]``)."""
    pe = PathEnergy(scene) if source is None else source
    half, band = FOLLOW_BOX.get(method, FOLLOW_BOX["gradient"])

    def gen() -> _BoxGenerator:
        # A counter of the boxes, shown once the run has taken a few seconds (a 4000 px
        # chip's meniscus run takes tens): where the chip is and how far the run has come.
        with counter_bar(f"{method} run (path engine)", "box") as bar:
            yield from boxes(bar)

    def boxes(bar: Any) -> _BoxGenerator:
        ta = scene.twist_axis
        n, s = ta.count, scene.um_per_px
        last = None
        k_last, turn = None, 0  # the last box's twist index and the way the twist last moved
        pose = yield
        while True:
            cx, cy = (int(v) for v in np.round(pose[:2] / s))
            k = int(round((pose[2] - float(ta.values_at(0))) / ta.step_deg)) if n > 1 else 0
            if k_last is not None and k != k_last:
                turn = 1 if k > k_last else -1
            k_last = k
            lo, hi = k - band, k + band
            if n == 1 or (ta.periodic and hi - lo + 1 >= n):
                lo, hi = 0, n - 1
            elif not ta.periodic:
                lo, hi = max(lo, 0), min(hi, n - 1)
            if (lo, hi, cx, cy) == last:
                pose = yield None
                continue
            last = (lo, hi, cx, cy)
            want = list(range(lo, hi + 1))
            # Only the band's outlines are kept (a meniscus footprint's are megabytes each).
            pe.drop_outlines({j % n for j in want})
            planes: dict[int, np.ndarray] = {}
            flags: dict[int, tuple] = {}
            template = None
            for run in consecutive_runs({j % n for j in want}):
                ls = pe.box(run, (cx, cy), half)
                template = ls
                planes.update({j: ls.energy[i] for i, j in enumerate(run)})
                if "relay" in ls.stats:
                    r, w = ls.stats["relay"]
                    flags.update({j: (r[i], w[i]) for i, j in enumerate(run)})
            assert template is not None  # want is never empty: one box at least
            # The twist the run turns to next, made meanwhile (a meniscus footprint: costly).
            ahead = hi + 1 if turn > 0 else lo - 1
            if turn and (ta.periodic or 0 <= ahead < n) and hi - lo + 1 < n:
                pe.prefetch(ahead % n)
            g = template.grid
            grid = PoseGrid(
                (len(want),) + g.shape[1:],
                g.um_per_px,
                ta,
                ta.periodic and len(want) == n,
                (ta.cut_of(lo, len(want)), g.cut[1], g.cut[2]),
                g.rg_px,
                g.x_first_px,
                g.y_first_px,
                lo,
            )
            bar.update(1)
            bar.set_postfix_str(
                f"chip at ({pose[0]:.0f}, {pose[1]:.0f}) um, {pose[2]:.1f} deg", refresh=False
            )
            stats = template.stats
            if flags:
                stats = stats | {
                    "relay": tuple(np.stack([flags[j % n][f] for j in want]) for f in (0, 1))
                }
            pose = yield Landscape(
                energy=np.stack([planes[j % n] for j in want]),
                grid=grid,
                delta_gamma=template.delta_gamma,
                energy_scale_J=template.energy_scale_J,
                stats=stats,
            )

    return gen(), pe


def nominal_box(scene: Scene, pe: PathEnergy) -> list[Landscape]:
    """The boxes :func:`simulator.landscape.global_minimum` looks in first, pose by pose."""
    return pe.nominal_boxes()
