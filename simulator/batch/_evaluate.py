"""A complete assessment of one pattern: numbers, pictures and a one-page report.

:func:`evaluate` computes, for a scene:

* the global minimum pose of the energy;
* the restoring force (N) and torque (N m) near alignment: at a bias of
  ``near_um`` along +-x and +-y, and at +-``near_deg`` of twist;
* the energy curves along x and y through the minimum, their plateaus and the
  maximum bias per direction: the largest |bias| up to which the force points back
  to the minimum everywhere (docs/physics.md §6.3);
* the capture fraction over a default grid of starts around the global minimum (at its
  twist): the fraction that ends aligned, and the capture map;
* the yield under default placement noise: normal around the aligned pose (the global
  minimum) with standard deviations of 10 % of the chip size in x and y and 2 degrees of
  twist;

and writes ``summary.json``, ``landscape.png``, ``force.png``, ``capture.png``,
``pattern.png`` (the input as used) and ``report.html`` into a directory. The capture
and yield runs use greedy steps by default; ``method`` chooses gradient or the dynamics
(overdamped, inertial: batched, with the chip's mass and damping from the scene), which
also report the time each start takes to align (``time_to_align_s``: median, 90th
percentile, ...) and draw its histogram (``time_to_align.png``). Everything
is written into a temporary directory beside it and renamed into place at the end,
so a failure leaves no partial directory; an existing directory is never replaced
unless asked (``force``) and only when it holds a previous selfalign output.

:func:`assess` computes the same numbers without writing anything (pictures only when
asked): one point of a design sweep (:mod:`simulator.sweep`). Both return a typed
:class:`simulator.batch.Assessment` (its parts in ``_assessment``), whose ``to_dict()`` is the
summary.
"""

from __future__ import annotations

import html
import math
import os
import time
from dataclasses import replace
from typing import Literal

import numpy as np

from foundation import check_output_dir, json_text, output_directory, require_finite, wait_line
from patterns.geometry import footprint_um
from simulator.batch._assessment import (
    ABSENT,
    Absent,
    AssessedMinimum,
    Assessment,
    AssessmentSettings,
    AxisErrors,
    CaptureCentre,
    CaptureGrid,
    CaptureSummary,
    CentreOffset,
    ContactLineReach,
    ErrorLimit,
    ErrorStats,
    FloatingRange,
    MaxBias,
    MeniscusSummary,
    PlacementSigma,
    Plateaus,
    Protocols,
    ProtocolSummary,
    RestoringForce,
    RestoringTorque,
    Stiffness,
    TimeStats,
    TwistErrors,
    YieldSummary,
)
from simulator.batch._montecarlo import run_batch
from simulator.batch._starts import StartGrid, random_starts
from simulator.batch._stats import capture_map, summarize, time_histogram, time_stats
from simulator.core import AUTO_LANDSCAPE_MB, METHODS
from simulator.landscape import build_landscape, estimate_bytes, require_landscape_fits
from simulator.physics import regime_warning
from simulator.render import (
    plot_capture_map,
    plot_forces,
    plot_landscape,
    plot_pattern,
    plot_time_to_align,
)
from simulator.scene import Scene

#: Placement noise (fractions of the chip size, and degrees) for the default yield.
NOISE_FRACTION, NOISE_TWIST_DEG = 0.10, 2.0
YIELD_STARTS = 2000
GRID_CELLS = 25
#: Seconds one report figure takes to draw (matplotlib; 0.9 s each measured for the four of
#: the 730 um four-pad on a 2-core machine): the figures' waiting line is priced with it.
FIGURE_S = 1.0


#: The coarsest whole multiple of its pixel size :func:`auto_resolution` takes a scene to.
AUTO_MAX_FACTOR = 16


def auto_resolution(scene: Scene, budget_mb: float = AUTO_LANDSCAPE_MB) -> Scene:
    """The scene at the finest whole multiple of its pixel size whose landscape fits
    ``budget_mb`` (at most :data:`AUTO_MAX_FACTOR` times it, that one when none fits).

    The landscape's size at each multiple is computed from the scene as it is
    (:func:`simulator.landscape.estimate_bytes` with ``um_per_px``); the scene is resampled
    once, to the pixel size chosen.
    """
    s = scene.um_per_px
    k = next(
        (
            k
            for k in range(1, AUTO_MAX_FACTOR + 1)
            if estimate_bytes(scene, um_per_px=s * k) / 2**20 <= budget_mb
        ),
        AUTO_MAX_FACTOR,
    )
    return scene if k == 1 else scene.at_resolution(s * k)


def chip_size(scene: Scene) -> tuple[float, float]:
    """Width and height (um) of the chip's wettable footprint."""
    return footprint_um(scene.chip)


def _outward(values: np.ndarray, x0: float, floor) -> tuple[np.ndarray, list[np.ndarray]]:
    """(arrived, [+ side, - side]) of a curve's samples ``values`` about ``x0``: which count as
    arrived (within a hundredth of a step of x0, a refined minimum sitting a round-off away
    from the samples through it, or on the flat ``floor`` [first, last] around it), and per
    side the indices of that side's samples and the arrived ones, ordered outward (the
    arrived first)."""
    tiny = 0.01 * float(np.min(np.diff(values))) if len(values) > 1 else 0.0
    arrived = np.abs(values - x0) <= tiny
    if floor is not None:
        arrived |= (values >= floor[0] - 1e-9) & (values <= floor[1] + 1e-9)
    sides = []
    for sign in (1, -1):
        d = (values - x0) * sign
        side = np.flatnonzero((d > tiny) | arrived)
        sides.append(side[np.argsort(d[side], kind="stable")])
    return arrived, sides


def _stops(force: float, sign: int, energy: float, inner: float | None, floor_J: float) -> bool:
    """Whether a chip at a sample stops there, moving towards the minimum on side ``sign``: its
    force is zero or pushes away, or the next sample in (energy ``inner``, J; None: not
    known) is not lower by more than the noise floor ``floor_J``, as the steppers see a flat
    stretch one sample long, which the central-difference force straddles."""
    return bool(force * sign >= 0 or (inner is not None and inner >= energy - floor_J))


def max_bias_along(
    values: np.ndarray,
    force: np.ndarray,
    x0: float,
    floor: list[float] | None = None,
    energy: np.ndarray | None = None,
    floor_J: float = 0.0,
) -> tuple[float, float]:
    """(+, -) largest |v - x0| with the force pointing back to x0 at every sample in between.

    ``floor``: [first, last] of a flat floor around x0 (a chip floating within free contact
    lines' reach): its samples count as arrived, whatever their force. ``energy`` (J, with
    the landscape's noise floor ``floor_J``): a sample also stops the chip where its
    neighbour towards x0 is not lower by more than the noise floor (:func:`_stops`; 730/50
    at 5 um/px, free lines: the flat part's 405-410 um, where a greedy run released beyond
    stops, read as a bias of 795 um without it).
    """
    values = np.asarray(values, float)
    force = np.asarray(force, float)
    arrived, sides = _outward(values, x0, floor)
    out = []
    for sign, side in zip((1, -1), sides, strict=True):
        best = 0.0
        for p, i in enumerate(side):
            if arrived[i]:
                continue
            inner = None if energy is None or p == 0 else float(energy[side[p - 1]])
            if _stops(
                float(force[i]), sign, 0.0 if energy is None else float(energy[i]), inner, floor_J
            ):
                break
            best = float((values[i] - x0) * sign)
        out.append(best)
    return out[0], out[1]


def released_max_bias(
    planes, dispensed, axis: str, through, start: float, stop: float, floor=None
) -> tuple[float, float]:
    """(+, -) largest |v - v0| along ``axis`` through ``through`` (v0 its value there) from
    which a chip released onto the footprint ``dispensed`` comes back: released at a sample,
    it takes its state there (:meth:`simulator.landscape.FootprintPlanes.next_state`) and
    walks the samples back to v0, its state passed on through each (a dry pad wets where it
    is reached, a wet one dries out of reach), moving on at every sample as
    :func:`max_bias_along` asks of its state's landscape (:func:`_stops`); every sample
    between v0 and the bias must come back so. ``floor``: [first, last] of a flat floor
    around v0, whose samples count as arrived.

    Not :func:`max_bias_along` on :meth:`~simulator.landscape.FootprintPlanes.released_curve`,
    whose samples are each a fresh release: a chip released just beyond where the far pads
    dry pulls back on the dry pads' state, which is flat short of that point (on 730/50 at
    5 um/px, released at 410 um it stops there, where the curve's force points back at
    every sample: a bias of 795 um read off it)."""
    # the curve's samples (as released_curve's); each state's curve is made once, below
    v = np.asarray(planes.template.curve(axis, through, start, stop)["values"], float)
    k = {"x": 0, "y": 1, "twist": 2}[axis]
    v0 = float(through[k])
    poses = np.tile(np.asarray(through, float), (len(v), 1))
    poses[:, k] = v
    arrived, sides = _outward(v, v0, floor)
    curves: dict[bytes, tuple] = {}  # each state's (energy, force, noise floor) along the curve

    def curve(state: np.ndarray) -> tuple:
        key = state.tobytes()
        if key not in curves:
            ls = planes.landscape(state)
            cs = ls.curve(axis, through, start, stop)
            curves[key] = (cs["energy_J"], cs["force"], ls.noise_floor_J)
        return curves[key]

    out = []
    for sign, side in zip((1, -1), sides, strict=True):
        first = int(np.argmin(arrived[side])) if not arrived[side].all() else len(side)
        ahead = side[first:]
        inner = side[first - 1] if first > 0 else None  # where a walk back arrives
        back: dict[tuple[int, bytes], bool] = {}  # (step outward, state): comes back from there
        best = 0.0
        for j, i in enumerate(ahead):
            state = planes.next_state(dispensed, poses[i])
            m, seen = j, []
            while True:
                key = (m, state.tobytes())
                if key in back:
                    ok = back[key]
                    break
                seen.append(key)
                e, f, noise = curve(state)
                at, nxt = ahead[m], ahead[m - 1] if m > 0 else inner
                if _stops(f[at], sign, e[at], None if nxt is None else e[nxt], noise):
                    ok = False
                    break
                if m == 0:  # the next sample is v0 or the floor
                    ok = True
                    break
                m -= 1
                state = planes.next_state(state, poses[ahead[m]])
            back.update(dict.fromkeys(seen, ok))
            if not ok:
                break
            best = float((v[i] - v0) * sign)
        out.append(best)
    return out[0], out[1]


def probe_distances(ls, chip_um, at, floating: dict | None) -> tuple[float, float]:
    """(bias um, twist deg) at which the restoring force and torque are probed: 2 % of the
    chip's smaller side (at least two grid steps) and one twist step (at least 1 deg; 0
    without twist), or, when the chip floats, one grid step (twist step) beyond the floor's
    farthest edge from the minimum ``at`` (on the floor the force is zero: a probe there
    says nothing of the well)."""
    s = ls.um_per_px
    near = max(2 * s, 0.02 * min(chip_um))
    twist = len(ls.twist_deg) > 1
    near_deg = max(ls.twist_step_deg, 1.0) if twist else 0.0
    if floating:
        x, y, t = at
        reach = max(
            x - floating["x_from_um"],
            floating["x_to_um"] - x,
            y - floating["y_from_um"],
            floating["y_to_um"] - y,
        )
        near = max(near, reach + s)
        if twist:
            turn = max(t - floating["twist_from_deg"], floating["twist_to_deg"] - t)
            near_deg = max(near_deg, turn + ls.twist_step_deg)
    return float(near), float(near_deg)


def evaluate(
    scene: Scene,
    out_dir: str | os.PathLike,
    quiet: bool = False,
    source: str = "",
    auto: bool = True,
    force: bool = False,
    inputs: tuple = (),
    liquid_warnings: list[str] | None = None,
    method: str = "greedy",
) -> Assessment:
    """Assess ``scene``, write the report into ``out_dir`` and return the :class:`Assessment`
    (with evaluate's additions: the pixel size read and whether it was coarsened, a layout's
    record, the droplet's warnings and volume window, the seconds); ``summary.json`` is its
    :meth:`~simulator.batch.Assessment.to_dict`.

    ``method``: how the capture and yield starts run (:data:`simulator.batch.METHODS`;
    default greedy); the dynamics add ``time_to_align.png`` and the times to the report.

    ``liquid_warnings`` (:func:`simulator.liquid.scene_warnings`) go into the summary
    (``liquid_warnings``, a list of one-line strings) and the report.

    ``out_dir`` is created atomically (see :func:`foundation.output_directory`): it
    must not exist, or be an empty directory, or with ``force`` hold nothing but a
    previous selfalign output. ``inputs`` (files the scene was read from) are never
    inside it. A failure leaves ``out_dir`` as it was.
    """
    t_start = time.perf_counter()
    check_output_dir(out_dir, "--out", force, inputs)  # before any work
    native = scene.um_per_px
    given = scene  # the droplet window reads the pattern as given (liquid window's pixels)
    if auto:
        scene = auto_resolution(scene)
    require_landscape_fits(scene)  # the landscape and the chip's footprint priced before any work
    if scene.dispense is not None:  # and the pads' planes of the two protocols
        from simulator.motion import require_footprint_fits

        require_footprint_fits(scene)
    with output_directory(out_dir, "--out", force, inputs, command="evaluate") as tmp:
        a = assess(scene, quiet=quiet, pictures=tmp, method=method)
        a = replace(
            a,
            settings=replace(
                a.settings,
                source_um_per_px=native,
                resolution_auto=bool(auto and scene.um_per_px != native),
            ),
            # a layout pattern: file, cell, layers, units, and where the origin is
            layout=scene.pattern.params.get("layout"),
            liquid_warnings=list(liquid_warnings or []),
            volume_window=_volume_window(given, a),  # from the yield's noise, unchanged here
            seconds=round(time.perf_counter() - t_start, 2),
        )
        summary = a.to_dict()
        require_finite(summary, "evaluate summary")
        (tmp / "summary.json").write_text(json_text(summary))
        (tmp / "report.html").write_text(_html(summary, source))
    return a


#: The placement bias the report's overflow limit is computed for, in placement-noise
#: standard deviations (the larger of x and y): 95 % of placements fall within it per axis.
OVERFLOW_BIAS_SIGMAS = 2.0


def _volume_window(scene: Scene, assessment: Assessment) -> dict:
    """The droplet's volume window (:func:`simulator.liquid.volume_window`) for the report, the
    overflow limit at :data:`OVERFLOW_BIAS_SIGMAS` of the placement noise; ``volume_given``
    says whether the volume was typed or derived from the chip. ``scene`` is the one given,
    before the automatic coarsening: a four-pad's L and gap are read at the pattern's own
    pixels, as ``selfalign liquid window`` reads them (the 730 um four-pad coarsened to
    3 um/px read as L 732, gap 48 um: a critical volume of 8.89 nl against 9)."""
    from simulator.liquid import volume_window

    ps = assessment.yield_.placement_sigma
    bias = OVERFLOW_BIAS_SIGMAS * max(ps.x_um, ps.y_um)
    win = volume_window(
        scene, bias, f"a placement at {OVERFLOW_BIAS_SIGMAS:g} sigma of the placement noise"
    )
    return win | {"volume_given": not scene.liquid.volume_derived}


def assess(
    scene: Scene,
    *,
    quiet: bool = True,
    pictures=None,
    method: str = "greedy",
    seed: int = 0,
    placement_sigma: tuple[float, float, float] | None = None,
    yield_starts: int = YIELD_STARTS,
    grid_cells: int = GRID_CELLS,
) -> Assessment:
    """The numbers of :func:`evaluate` for ``scene`` as an :class:`Assessment` (no resolution
    change, nothing written unless ``pictures`` names a directory for the four pictures).

    The defaults are evaluate's: greedy steps, the yield's placement noise (sigma x, y in um
    and twist in degrees; default 10 % of the chip size and 2 degrees) drawn with ``seed``
    0, ``yield_starts`` starts, and a capture grid of about ``grid_cells`` starts per side.
    ``method`` "overdamped" or "inertial" runs the starts through the dynamics
    (:func:`simulator.batch.run_batch`, parameters from the scene) and adds
    ``time_to_align_s`` (:func:`simulator.batch.time_stats`, seconds of simulated
    time; None when no start aligned) to ``capture`` and ``yield``, and
    ``time_to_align.png`` (the yield starts' histogram) to ``pictures``.
    """
    from foundation import require

    require(method in METHODS, f"method must be one of {', '.join(METHODS)}, got {method!r}")
    s = scene.um_per_px
    ls = build_landscape(scene, progress=not quiet)
    xm, ym, tm, em = ls.global_minimum()
    gx, gy, gt = (
        xm,
        ym,
        tm,
    )  # the grid's global minimum: centre of the capture grid and of the placement noise
    meniscus = None
    floating = None
    if ls.meniscus_height_um is not None:
        # A smooth well: its minimum below the grid, and its stiffness there. With free contact
        # lines the well can have a flat floor (the chip floats within the lines' reach): then
        # the floor is what is reported, and its pose nearest the nominal one (the grid's).
        from simulator.landscape import refine_minimum, stiffness

        if scene.wall_profile is not None and any(b > a for a, b in ls.floor_extent()):
            fr = ls.floor_range()
            floating = {
                f"{k.split('_')[0]}_{end}_{k.split('_')[1]}": v[i]
                for k, v in fr.items()
                for i, end in enumerate(("from", "to"))
            }
        else:
            r = refine_minimum(ls, xm, ym, tm)
            xm, ym, tm, em = r["x_um"], r["y_um"], r["twist_deg"], r["energy_J"]
        meniscus = {
            "stiffness": stiffness(ls, xm, ym, tm),
            "overlap": build_landscape(
                scene.replace(
                    effects=replace(scene.effects, meniscus=False),
                    liquid=replace(scene.liquid, dispense="none", dispense_at_um=None),
                ),
                twists=np.array([ls.twist_deg[int(np.argmin(np.abs(ls.twist_deg - tm)))]]),
            ),
        }
        if (
            floating
        ):  # on the floor the well is flat: no curvature where it spans the minimum (not round-off)
            k = meniscus["stiffness"]
            for key, axis, v in (
                ("x_N_per_m", "x", xm),
                ("y_N_per_m", "y", ym),
                ("twist_Nm_per_rad", "twist", tm),
            ):
                unit = "deg" if axis == "twist" else "um"
                if (
                    k.get(key) is not None
                    and floating[f"{axis}_from_{unit}"] < v < floating[f"{axis}_to_{unit}"]
                ):
                    k[key] = 0.0
    w, h = chip_size(scene)
    near, near_deg = probe_distances(ls, (w, h), (xm, ym, tm), floating)
    forces = {}
    for label, dx, dy in (("+x", near, 0), ("-x", -near, 0), ("+y", 0, near), ("-y", 0, -near)):
        fx, fy = ls.force_at(xm + dx, ym + dy, tm)
        forces[label] = (float(fx) + 0.0, float(fy) + 0.0)  # no -0.0
    torques = {}
    if near_deg:
        for label, d in (("+", near_deg), ("-", -near_deg)):
            torques[label] = float(ls.torque_at(xm, ym, tm + d)) + 0.0
    curves, biases = {}, {}
    reach_x, reach_y = float(ls.x_um[-1]), float(ls.y_um[-1])
    for axis, lo, hi in (("x", -reach_x, reach_x), ("y", -reach_y, reach_y)):
        c = ls.curve(axis, (xm, ym, tm), lo, hi)
        x0 = xm if axis == "x" else ym
        floor = [floating[f"{axis}_from_um"], floating[f"{axis}_to_um"]] if floating else None
        plus, minus = max_bias_along(
            c["values"], c["force"], x0, floor, c["energy_J"], ls.noise_floor_J
        )
        curves[axis] = c
        biases[f"+{axis}"], biases[f"-{axis}"] = plus, minus
    # Capture fraction over a grid of starts around the global minimum (at its twist), and the
    # yield under placement noise around it: the target a gripper aims at.
    span = 0.6 * max(w, h)
    step = max(s, round(2 * span / (grid_cells - 1) / s) * s)
    n = int(span // step)
    grid = StartGrid.from_ranges(
        (gx - n * step, gx + n * step, step), (gy - n * step, gy + n * step, step), gt
    )
    # the stateless footprint (every pad counted by its distance from the chip) on the landscape;
    # a scene with --dispense adds each protocol's numbers below (footprint_protocols)
    stateless = scene.replace(liquid=replace(scene.liquid, dispense="none", dispense_at_um=None))
    # the capture grid and the yield starts padded to one lane count: one compiled batch
    lanes = max(grid.size, int(yield_starts))
    cap = run_batch(stateless, grid, method, landscape=ls, progress=not quiet, lanes=lanes)
    cap_sum = summarize(cap, grid)
    noise = (
        (NOISE_FRACTION * w, NOISE_FRACTION * h, NOISE_TWIST_DEG)
        if placement_sigma is None
        else tuple(float(v) for v in placement_sigma)
    )
    if len(ls.twist_deg) == 1:
        noise = (noise[0], noise[1], 0.0)
    starts = random_starts(yield_starts, noise, seed=seed, around=(gx, gy, gt))
    if len(ls.twist_deg) == 1:
        starts[:, 2] = 0.0
    yl = run_batch(stateless, starts, method, landscape=ls, progress=not quiet, lanes=lanes)
    yl_sum = summarize(yl)
    protocols = None
    if scene.dispense is not None:
        protocols = footprint_protocols(
            scene,
            (xm, ym, tm),
            {
                a: (lo, hi)
                for a, (lo, hi) in (("x", (-reach_x, reach_x)), ("y", (-reach_y, reach_y)))
            },
            floating,
            grid,
            starts,
            method,
            quiet,
        )
    if pictures is not None:
        out = pictures
        if not quiet:
            figures = ["pattern", "landscape", "force", "capture"] + (
                ["time to align"] if yl.time_s is not None else []
            )
            wait_line(
                f"drawing the report's figures ({', '.join(figures)})", FIGURE_S * len(figures)
            )
        plot_pattern(scene.pattern, out / "pattern.png")
        plot_landscape(ls, out / "landscape.png", pattern=scene.pattern)
        plot_forces(
            ls,
            out / "force.png",
            through=(xm, ym, tm),
            compare=meniscus["overlap"] if meniscus else None,
        )
        plot_capture_map(
            capture_map(cap, grid),
            grid,
            scene,
            out / "capture.png",
            title=f"capture map ({method}): capture fraction {100 * cap_sum['yield']:.1f} % of {cap_sum['n']} grid starts",
        )
        if yl.time_s is not None:
            plot_time_to_align(
                time_histogram(yl.time_to_align_s),
                time_stats(yl.time_to_align_s),
                out / "time_to_align.png",
                title=f"time to align ({method}): {yl_sum['outcomes']['aligned']:,} of {yl_sum['n']:,} placement-noise starts aligned",
            )
    m = scene.materials
    rows, cols = scene.pattern.shape
    men = None
    if meniscus and ls.meniscus_height_um is not None:  # (a meniscus landscape: both or neither)
        prof = scene.wall_profile
        men = MeniscusSummary(
            meniscus_height_um=ls.meniscus_height_um,
            pinned=scene.liquid.pinned,
            stiffness=Stiffness(**meniscus["stiffness"]),
            offset_from_centre=CentreOffset(
                x_um=round(xm, 1) + 0.0,
                y_um=round(ym, 1) + 0.0,
                twist_deg=round(tm, 1) + 0.0,
                distance_um=round(math.hypot(xm, ym), 1),
            ),
            meniscus_warning=regime_warning(ls.meniscus_height_um, scene.chip_min_side_um),
            contact_lines="pinned" if scene.liquid.pinned else "free",
            floating_range=None if floating is None else FloatingRange(**floating),
            contact_line_reach_um=None
            if prof is None
            else ContactLineReach(substrate=prof.substrate_reach_px * s, pad=prof.pad_reach_px * s),
        )
    return Assessment(
        meniscus=men,
        global_minimum=AssessedMinimum(
            x_um=xm,
            y_um=ym,
            twist_deg=tm,
            energy_J=em,
            overlap_um2=float(ls.overlap_um2(em)),
            refined=meniscus is not None and floating is None,
        ),
        error_limit=_error_limit(yl_sum["error_limit"]),
        restoring_force_N=RestoringForce(
            bias_um=near,
            plus_x=forces["+x"],
            minus_x=forces["-x"],
            plus_y=forces["+y"],
            minus_y=forces["-y"],
        ),
        restoring_torque_Nm=RestoringTorque(
            twist_deg=near_deg, plus=torques["+"], minus=torques["-"]
        )
        if torques
        else None,
        plateaus_um=Plateaus(x=curves["x"]["plateaus"], y=curves["y"]["plateaus"]),
        max_bias_um=_max_bias(biases),
        protocols=protocols,
        capture=CaptureSummary(
            fraction=cap_sum["yield"],
            n=cap_sum["n"],
            outcomes=cap_sum["outcomes"],
            grid_um=CaptureGrid(from_=-n * step, to=n * step, step=step),  # about the centre
            center=CaptureCentre(x_um=gx, y_um=gy),
            twist_deg=gt,
            time_to_align_s=_time_stats(cap_sum),
        ),
        yield_=YieldSummary(
            fraction=yl_sum["yield"],
            n=yl_sum["n"],
            outcomes=yl_sum["outcomes"],
            placement_sigma=PlacementSigma(x_um=noise[0], y_um=noise[1], twist_deg=noise[2]),
            seed=seed,
            error_um=AxisErrors(
                **{k: _error_stats(v) for k, v in yl_sum["aligned_error_um"].items()}
            ),
            error_deg=TwistErrors(twist=_error_stats(yl_sum["aligned_error_deg"]["twist"])),
            time_to_align_s=_time_stats(yl_sum),
        ),
        settings=AssessmentSettings(
            um_per_px=s,
            pattern_px=(rows, cols),
            chip_um=(w, h),
            twist_step_deg=ls.twist_step_deg if len(ls.twist_deg) > 1 else None,
            twists=len(ls.twist_deg),
            dtype=scene.dtype,
            method=method,
            surface_tension_N_m=m.surface_tension_N_m,
            pad_angle_deg=m.pad_angle_deg,
            substrate_angle_deg=m.substrate_angle_deg,
            delta_gamma_N_m=scene.delta_gamma_N_m,
            landscape_MB=round(ls.energy.nbytes / 2**20, 1),
            landscape_s=round(ls.stats["seconds"], 2),
        ),
    )


def _error_limit(d: dict | None) -> ErrorLimit | None:
    return None if d is None else ErrorLimit(**d)


def _error_stats(d: dict | None) -> ErrorStats | None:
    return None if d is None else ErrorStats(**d)


def _max_bias(b: dict) -> MaxBias:
    return MaxBias(plus_x=b["+x"], minus_x=b["-x"], plus_y=b["+y"], minus_y=b["-y"])


def _time_stats(batch: dict) -> TimeStats | None | Literal[Absent.ABSENT]:
    """A batch summary's time to align (:func:`simulator.batch.summarize`): ABSENT for the
    steppers, None when no start aligned."""
    if "time_to_align_s" not in batch:
        return ABSENT
    t = batch["time_to_align_s"]
    return None if t is None else TimeStats(**t)


def footprint_protocols(
    scene: Scene, through, spans: dict, floating, grid, starts, method: str, quiet: bool
) -> Protocols:
    """The maximum bias, the capture fraction and the yield of ``scene`` under each protocol
    of ``--dispense`` (docs/physics.md §3.5), from one build of the pads' planes: ``pattern``
    (the droplet on the pattern first) and ``chip`` (the liquid comes in under the chip).

    The maximum bias is the farthest release from which the chip comes back along the axis,
    its state passed on as it goes (:func:`released_max_bias`); capture and yield run the same starts as the stateless
    ones (``grid``, ``starts``), each carrying its own footprint state."""
    from simulator.landscape import build_footprint_planes
    from simulator.liquid import dispensed_footprint
    from simulator.motion import require_footprint_fits
    from simulator.physics import DISPENSE

    assert scene.dispense is not None  # called for a scene with --dispense only
    require_footprint_fits(scene)
    planes = build_footprint_planes(scene, progress=not quiet)
    out: dict[str, ProtocolSummary] = {}
    for proto in DISPENSE:
        at = scene.liquid.dispense_at_um if proto == "pattern" else None
        sc = scene.replace(liquid=replace(scene.liquid, dispense=proto, dispense_at_um=at))
        dispensed, why = dispensed_footprint(sc, planes.labels, planes.n_pads)
        biases = {}
        for axis, (lo, hi) in spans.items():
            floor = [floating[f"{axis}_from_um"], floating[f"{axis}_to_um"]] if floating else None
            biases[f"+{axis}"], biases[f"-{axis}"] = released_max_bias(
                planes, dispensed, axis, through, lo, hi, floor=floor
            )
        lanes = max(grid.size, len(starts))  # one compiled batch, as above
        cap = summarize(
            run_batch(sc, grid, method, progress=not quiet, planes=planes, lanes=lanes), grid
        )
        yl = summarize(
            run_batch(sc, starts, method, progress=not quiet, planes=planes, lanes=lanes)
        )
        out[proto] = ProtocolSummary(
            why=why,
            wet_at_dispense=[int(k + 1) for k in np.flatnonzero(dispensed)],
            max_bias_um=_max_bias(biases),
            capture_fraction=cap["yield"],
            capture_outcomes=cap["outcomes"],
            yield_fraction=yl["yield"],
            yield_outcomes=yl["outcomes"],
            time_to_align_s=_time_stats(yl),
        )
    return Protocols(
        dispense=scene.dispense,
        substrate_reach_um=planes.rules.d_s * scene.um_per_px,
        wet_reach_um=planes.rules.d_r * scene.um_per_px,
        receding_deg=planes.rules.receding_deg,
        planes_s=planes.seconds,
        by_protocol=out,
    )


def _fmt(v, unit: str, digits: int = 4) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float) and (abs(v) < 1e-3 or abs(v) >= 1e4) and v != 0:
        return f"{v:.{digits - 1}e} {unit}"
    return f"{v:.{digits}g} {unit}"


def _layout_row(record: dict | None) -> str:
    """The report's row on a layout pattern's cell, layers, units and origin (empty for images)."""
    if not record:
        return ""
    from patterns.layout import frame_note

    return f"\n<tr><th>layout</th><td>{html.escape(frame_note(record).removeprefix('frame: '))}</td></tr>"


def _liquid_rows(warnings: list[str] | None) -> str:
    """The report's list of the droplet's warnings (empty when there are none)."""
    if not warnings:
        return ""
    items = "".join(f"<li>{html.escape(w)}</li>" for w in warnings)
    return f'\n<h2>The droplet</h2>\n<ul class="warn">{items}</ul>'


def _model_note(summary: dict) -> str:
    h = summary.get("meniscus_height_um")
    if h is None:
        return "Overlap model (energy = &Delta;&gamma; &times; overlap area)."
    if summary.get("pinned"):
        return (
            f"Finite meniscus, height {h:.4g} um, contact lines pinned at the pad edges (the overlap "
            "energy with every cusp rounded over h; dashed in the force plot: the overlap model)."
        )
    r = summary.get("contact_line_reach_um")
    reach = (
        f", reaching {r['substrate']:.3g} um beyond the chip on the substrate and {r['pad']:.3g} um on a pad"
        if r
        else ""
    )
    return (
        f"Finite meniscus, height {h:.4g} um, free contact lines{reach} (the overlap energy of the "
        "liquid's footprint: flat where the lines stand on one surface, rising where a pad edge holds a line; dashed in the "
        "force plot: the overlap model)."
    )


def _at(v: float) -> str:
    """A refined pose coordinate (um or degrees) as the page shows it: to 0.001, no -0
    (summary.json keeps every digit)."""
    return f"{round(float(v), 3) + 0.0:g}"


def _span(fl: dict, axis: str, unit: str) -> str:
    return f"{_at(fl[f'{axis}_from_{unit}'])} to {_at(fl[f'{axis}_to_{unit}'])} {unit}"


def _meniscus_rows(summary: dict) -> str:
    k = summary.get("stiffness")
    if not k:
        return ""
    o = summary["offset_from_centre"]
    tw = "n/a" if k.get("twist_Nm_per_rad") is None else _fmt(k["twist_Nm_per_rad"], "N m/rad")
    warn = summary.get("meniscus_warning")
    warn_html = f'<p class="warn">warning: {html.escape(warn)}</p>' if warn else ""
    fl = summary.get("floating_range")
    if fl:
        warn_html = (
            f"<p>The chip floats: the well's floor (no restoring force) spans x {_span(fl, 'x', 'um')}, "
            f"y {_span(fl, 'y', 'um')}, twist {_span(fl, 'twist', 'deg')}; a run that stops on it counts as "
            f"aligned. The stiffness is the floor's (zero where it is flat).</p>"
        ) + warn_html
    return (
        f"<h2>Stiffness at alignment (finite meniscus)</h2><table><tr><th>k<sub>x</sub></th><td>{_fmt(k['x_N_per_m'], 'N/m')}</td></tr>"
        f"<tr><th>k<sub>y</sub></th><td>{_fmt(k['y_N_per_m'], 'N/m')}</td></tr><tr><th>k<sub>twist</sub></th><td>{tw}</td></tr>"
        f"<tr><th>offset of the minimum from the pattern centre</th><td>({_at(o['x_um'])} um, {_at(o['y_um'])} um, {_at(o['twist_deg'])} deg), "
        f"{_at(o['distance_um'])} um</td></tr></table>{warn_html}\n"
    )


def _probe_words(summary: dict) -> str:
    """Where the report probes the restoring force and torque, and why there."""
    f, tq = summary["restoring_force_N"], summary.get("restoring_torque_Nm")
    where = f"Probed at a bias of {f['bias_um']:.3g} um from the minimum" + (
        f" and a twist of {tq['twist_deg']:.3g} deg" if tq else ""
    )
    fl = summary.get("floating_range")
    if fl:
        return (
            f"{where}: one grid step beyond the floor the chip floats on (x {_span(fl, 'x', 'um')}, "
            f"y {_span(fl, 'y', 'um')}), where the force is zero."
        )
    return f"{where} (2 % of the chip's smaller side, at least two grid steps)."


def _limit_words(limit: dict | None) -> str:
    from simulator.motion import error_limit_words

    return error_limit_words(limit) or "limit n/a"


def _window_rows(window: dict | None) -> str:
    """The report's section on the droplet's usable volume window (:func:`simulator.liquid.volume_window`)."""
    if not window:
        return ""
    from simulator.liquid import window_lines

    items = "".join(
        f"<li>{html.escape(line.strip())}</li>"
        for line in window_lines(window, window.get("volume_given"))
    )
    return f"\n<h2>The droplet's volume window</h2>\n<ul>{items}</ul>"


def _time_text(t: dict | None) -> str:
    if t is None:
        return "no start aligned"
    return (
        f"median <b>{1e3 * t['median']:.3g} ms</b>, 90th percentile <b>{1e3 * t['p90']:.3g} ms</b>, "
        f"range {1e3 * t['min']:.3g} to {1e3 * t['max']:.3g} ms over {t['n']:,} aligned starts"
    )


def _time_rows(cap: dict, yl: dict) -> str:
    """The report's section on the time to align (dynamics only; empty for the steppers)."""
    if "time_to_align_s" not in yl:
        return ""
    return (
        f"\n<h2>Time to align</h2>\n<p>Simulated time until an aligned run comes to rest (the solver's stop test), "
        f"placement-noise starts: {_time_text(yl['time_to_align_s'])}; capture grid: {_time_text(cap.get('time_to_align_s'))}.</p>\n"
        f'<img src="time_to_align.png" alt="histogram of the time to align">'
    )


def _protocol_rows(p: dict | None) -> str:
    """The report's table of the two dispense protocols (``--dispense``), or nothing."""
    if not p:
        return ""
    e = html.escape
    rows = "".join(
        f"<tr><th>{e(name)}{' (this scene)' if name == p['dispense'] else ''}</th>"
        f"<td>{', '.join(str(k) for k in r['wet_at_dispense']) or 'none'}</td>"
        f"<td>+x {r['max_bias_um']['+x']:g}, &minus;x {r['max_bias_um']['-x']:g}, +y {r['max_bias_um']['+y']:g}, &minus;y {r['max_bias_um']['-y']:g} um</td>"
        f"<td>{100 * r['capture_fraction']:.1f} %</td><td>{100 * r['yield_fraction']:.1f} %</td></tr>"
        for name, r in p.items()
        if isinstance(r, dict)
    )
    return f"""
<h2>By dispense protocol (the footprint as the run's state)</h2>
<p>Where the process puts the liquid decides which pads are wet when the chip is released
(<code>pattern</code>: the droplet on the pattern first; <code>chip</code>: the liquid comes in under the
chip). A dry pad wets when the liquid's foot reaches it (within {p["substrate_reach_um"]:.3g} um of the chip),
a wet pad dries beyond the reach of the chip's wall ({p["wet_reach_um"]:.3g} um, {p["receding_deg"]:.3g} deg receding).
The maximum bias is the farthest release along an axis from which the chip comes back, its wet pads carried as it goes; capture and yield run the starts above, each carrying its own wet pads.</p>
<table><tr><th>protocol</th><th>wet at release</th><th>maximum bias</th><th>capture</th><th>yield</th></tr>{rows}</table>"""


def _html(summary: dict, source: str) -> str:
    """The one-page report: inputs, numbers with units, the four pictures."""
    s, g = summary["settings"], summary["global_minimum"]
    f, b = summary["restoring_force_N"], summary["max_bias_um"]
    tq = summary["restoring_torque_Nm"]
    cap, yl = summary["capture"], summary["yield"]
    e = html.escape
    rows_force = "".join(
        f"<tr><td>{e(k)} {f['bias_um']:.3g} um</td><td>{_fmt(v[0] * 1e6, 'uN')}</td><td>{_fmt(v[1] * 1e6, 'uN')}</td></tr>"
        for k, v in f.items()
        if k != "bias_um"
    )
    rows_torque = (
        "".join(
            f"<tr><td>twist {k}{tq['twist_deg']:g} deg</td><td colspan=2>{_fmt(v * 1e9, 'nN m')}</td></tr>"
            for k, v in tq.items()
            if k != "twist_deg"
        )
        if tq
        else "<tr><td colspan=3>twist not simulated</td></tr>"
    )
    plateaus = "; ".join(
        f"{a}: " + (", ".join(f"[{p[0]:g}, {p[1]:g}] um" for p in pl) or "none")
        for a, pl in summary["plateaus_um"].items()
    )
    outcomes = ", ".join(f"{k} {v}" for k, v in yl["outcomes"].items() if v)
    cap_out = ", ".join(f"{k} {v}" for k, v in cap["outcomes"].items() if v)
    ps = yl["placement_sigma"]
    err = yl.get("error_um") or {}
    err_txt = (
        ", ".join(f"{k}: mean |error| {v['mean_abs']:.3g} um" for k, v in err.items() if v) or "n/a"
    )
    auto = (
        " (coarsened automatically to keep the landscape small; pass --resolution to choose)"
        if s.get("resolution_auto")
        else ""
    )
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>selfalign evaluation: {e(source)}</title>
<style>
body {{ font-family: system-ui, sans-serif; max-width: 1100px; margin: 2em auto; color: #222; line-height: 1.4; }}
h1 {{ font-size: 1.5em; }} h2 {{ font-size: 1.15em; margin-top: 1.6em; border-bottom: 1px solid #ccc; }}
table {{ border-collapse: collapse; margin: .5em 0; }} td, th {{ border: 1px solid #ccc; padding: 3px 10px; text-align: left; }}
img {{ max-width: 100%; border: 1px solid #ddd; }} .grid {{ display: grid; grid-template-columns: 1fr 1fr; gap: 1em; }}
.note {{ color: #555; font-size: .9em; }}
</style></head><body>
<h1>selfalign evaluation of <code>{e(source)}</code></h1>
<p class="note">{_model_note(summary)} Positions in um of the chip centre from the
pattern centre, x right, y up; twist in degrees, counter-clockwise positive. Computed in {summary["seconds"]:.1f} s.</p>
<h2>Inputs</h2>
<div class="grid"><div><img src="pattern.png" alt="pattern as used"></div><div><table>
<tr><th>pattern</th><td>{e(source)}, {s["pattern_px"][1]} x {s["pattern_px"][0]} px at {s["um_per_px"]:g} um/px{e(auto)} (file scale {s["source_um_per_px"]:g} um/px)</td></tr>
<tr><th>chip</th><td>{s["chip_um"][0]:g} x {s["chip_um"][1]:g} um wettable footprint</td></tr>{_layout_row(summary.get("layout"))}
<tr><th>liquid / wetting</th><td>surface tension {s["surface_tension_N_m"] * 1e3:g} mN/m, pad {s["pad_angle_deg"]:g} deg, substrate {s["substrate_angle_deg"]:g} deg: &Delta;&gamma; = {s["delta_gamma_N_m"] * 1e3:.4g} mN/m</td></tr>
<tr><th>pose grid</th><td>{s["twists"]} twists{f", step {s['twist_step_deg']:g} deg" if s["twist_step_deg"] else ""}; {s["dtype"]}; landscape {s["landscape_MB"]:g} MB in {s["landscape_s"]:g} s</td></tr>
</table></div></div>{_liquid_rows(summary.get("liquid_warnings"))}
<h2>Where the chip ends up</h2>
<p>Global minimum of the energy at <b>({_at(g["x_um"])} um, {_at(g["y_um"])} um, {_at(g["twist_deg"])} deg)</b>,
overlap {g["overlap_um2"]:,.0f} um&sup2;, energy {_fmt(g["energy_J"], "J")}.</p>
{_meniscus_rows(summary)}<h2>Restoring force and torque near alignment</h2>
<table><tr><th>chip displaced by</th><th>F<sub>x</sub></th><th>F<sub>y</sub></th></tr>{rows_force}{rows_torque}</table>
<p class="note">{e(_probe_words(summary))}</p>
<p>Maximum bias from which the force points back to the minimum all the way:
+x {b["+x"]:g} um, &minus;x {b["-x"]:g} um, +y {b["+y"]:g} um, &minus;y {b["-y"]:g} um (twist held at the minimum's).
Plateaus (zero force): {e(plateaus)}.</p>
<img src="force.png" alt="energy, force and torque curves">
<h2>Energy landscape</h2>
<img src="landscape.png" alt="energy over x and y">
<h2>Capture region and yield</h2>
<p>Capture fraction: <b>{100 * cap["fraction"]:.1f} %</b> of {cap["n"]} {e(s["method"])} starts on a grid from {cap["grid_um"]["from"]:g} to {cap["grid_um"]["to"]:g} um
in steps of {cap["grid_um"]["step"]:g} um in x and y around the global minimum, twist {cap["twist_deg"]:g} deg ({e(cap_out)}).</p>
<p>Yield under placement noise: <b>{100 * yl["fraction"]:.1f} %</b> of {yl["n"]} starts drawn normally around the aligned pose (the global minimum) with
&sigma; = {ps["x_um"]:.3g} um, {ps["y_um"]:.3g} um, {ps["twist_deg"]:g} deg (seed {yl["seed"]}): {e(outcomes)}; aligned runs, final-pose error from the global minimum: {e(err_txt)}; {e(_limit_words(summary.get("error_limit")))}.</p>{_window_rows(summary.get("volume_window"))}
<img src="capture.png" alt="capture map">{_time_rows(cap, yl)}{_protocol_rows(summary.get("protocols"))}
<p class="note">Written by selfalign. The numbers are in summary.json (units in the key names).</p>
</body></html>
"""
