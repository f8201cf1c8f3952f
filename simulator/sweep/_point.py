"""One point of a design sweep: its scene, its assessment, and the run that never raises.

Owns what a Dask task runs for one point: :func:`point_scene` (the point's scene, built
as ``selfalign evaluate`` builds it: the axis values onto the base scene, a generated
pattern rasterized, evaluate's default chip), :func:`assess_point` (the summary of
:func:`simulator.batch.assess`, the yield drawn with the point's ``point_seed``) and
:func:`run_point` (the point's failure as its one-line error row), with
``_cap_threads``, which keeps a worker's JAX and FFTs on one core. The scene, the engine
and JAX are imported only when a point runs.
"""

from __future__ import annotations

import copy
import os
import sys
import time
from dataclasses import replace

from foundation import InputError
from simulator.core import THREADS_ENV
from simulator.sweep._axes import AXES, _design_axes
from simulator.sweep._task import PointTask

__all__ = [
    "assess_point",
    "design_params",
    "point_bytes",
    "point_critical_volume_nl",
    "point_geometry",
    "point_scene",
    "price_point",
    "run_point",
]

#: XLA flag that keeps a worker's JAX on one thread (set before JAX is imported there).
XLA_ONE_THREAD = "--xla_cpu_multi_thread_eigen=false"


# ----------------------------------------------------------------------- one point
def _cap_threads() -> None:
    """In a Dask worker: JAX and the FFTs on one core (before JAX is imported there)."""
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return  # not in a worker: this process's own settings stand
    if "jax" not in sys.modules and XLA_ONE_THREAD not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {XLA_ONE_THREAD}".strip()
    # The correlator's FFTs and the batch threads: one per worker (simulator.core.threads).
    os.environ[THREADS_ENV] = "1"


def design_params(task: PointTask) -> dict:
    """The generated design's parameters at one point: the sweep's ``[design]`` values with
    the point's design axes on top and, for a seeded design, the realization's seed."""
    design = task.design
    assert design is not None, "a point of a sweep without a [design] has no design parameters"
    params = dict(design["params"])
    params.update({k: x for k, x in task.values.items() if k not in AXES})
    if "seed" in _design_axes(design["name"]):
        params["seed"] = task.design_seed(design)
    return params


def point_geometry(task: PointTask):
    """The exact geometry (um, shapely) of a point's generated design and its record (the
    parameters a pattern file keeps), as :func:`point_scene` rasterizes it."""
    from patterns.geometry import build, design_record

    design = task.design
    assert design is not None, "a point of a sweep without a [design] has no geometry"
    params = design_params(task)
    geometry = build(design["name"], **params)
    record = design_record(design["name"], **params)
    record.update(margin_um=design["margin_um"], area_um2=geometry.area)
    return geometry, record


def point_scene(task: PointTask):
    """The scene of one point, built as ``selfalign evaluate`` builds it; also whether to coarsen automatically.

    The point's scene axes go onto the base scene as the commands' flags go onto a scene
    file (:func:`simulator.scene.merge_values`, at the places :func:`simulator.scene.sweep_places`
    gives: a ``chip_size_um`` axis replaces the base scene's chip); a ``pattern`` axis's file
    is read relative to the sweep file (docs/guide/sweeps.md)."""
    from patterns.geometry import default_chip_um, mask_from_geometry
    from simulator.scene import CHIP_KEYS, Scene, merge_values, sweep_places

    doc = copy.deepcopy(dict(task.scene))
    v = task.values
    design = task.design
    places = {place: v[axis] for axis, place in sweep_places().items() if axis in v}
    if "pattern" in v:  # relative to the sweep file
        places[(None, "pattern")] = str((task.base / v["pattern"]).resolve())
    merge_values(doc, places)
    if design is not None:
        geometry, record = point_geometry(task)
        um = doc.get("resolution_um") or doc.get("um_per_px") or 1.0
        doc["pattern"] = mask_from_geometry(
            geometry,
            um,
            margin_um=design["margin_um"],
            params=record,
            budget_mb=doc.get("memory_budget_mb"),
            what="the pattern raster",
        )
        if not any(k in doc for k in CHIP_KEYS):
            doc["chip_size_um"] = list(default_chip_um(geometry))  # evaluate's default chip
    elif not any(k in doc for k in CHIP_KEYS):
        # evaluate's default chip (the pattern read once with a stand-in chip)
        probe = Scene.from_dict(
            doc | {"chip_size_um": [1.0, 1.0]}, base=task.base, check_scale=False
        )
        doc["chip_size_um"] = list(default_chip_um(probe.pattern))
    auto = "resolution_um" not in doc
    return Scene.from_dict(doc, base=task.base), auto


def point_critical_volume_nl(scene, task: PointTask) -> float | None:
    """The critical droplet volume (nl) of the point's pattern when it is a four-pad
    (docs/physics.md §8): from the generated design's exact size and gap, else from the four
    pads recognised in the raster; None for other patterns, or pads that do not wet better
    than the substrate (no drop prefers them), or angles that give no critical volume
    (:func:`simulator.liquid.scene_critical_volume`)."""
    from simulator.liquid import scene_critical_volume

    design = task.design
    fp = None
    if design is not None and design["name"] == "four-pad":
        params = design_params(task)
        fp = (float(params["size"]), float(params["gap"]))
    try:
        cv = scene_critical_volume(scene, fp)
    except InputError:  # no crossing found: the angles give no critical volume
        return None
    return None if cv is None else cv.critical_volume_nl


def assess_point(task: PointTask) -> dict:
    """The summary of one point: :func:`simulator.batch.assess` on its scene, as ``evaluate``
    runs it (the :class:`simulator.batch.Assessment`'s dict).

    The yield's placement noise is drawn with the point's ``point_seed``; ``settings`` also
    records ``source_um_per_px``, ``resolution_auto`` (as evaluate) and ``volume_nl``; a
    four-pad pattern's ``critical_volume_nl`` (:func:`point_critical_volume_nl`) is added, to set
    beside the droplet's volume.
    """
    from foundation import require_finite
    from simulator.batch import NOISE_FRACTION, NOISE_TWIST_DEG, assess, auto_resolution, chip_size

    scene, auto = point_scene(task)
    native = scene.um_per_px
    if auto:
        scene = auto_resolution(scene)
    v = task.values
    sigma = None
    if "placement_sigma_um" in v or "placement_sigma_deg" in v:
        w, h = chip_size(scene)
        sx, sy = (
            (v["placement_sigma_um"],) * 2
            if "placement_sigma_um" in v
            else (NOISE_FRACTION * w, NOISE_FRACTION * h)
        )
        sigma = (sx, sy, v.get("placement_sigma_deg", NOISE_TWIST_DEG))
    a = assess(
        scene,
        quiet=True,
        method=v.get("method", "greedy"),
        seed=task.point_seed,
        placement_sigma=sigma,
        yield_starts=task.yield_starts,
        grid_cells=task.capture_grid,
    )
    a = replace(
        a,
        settings=replace(
            a.settings,
            source_um_per_px=native,
            resolution_auto=bool(auto and scene.um_per_px != native),
            volume_nl=scene.liquid.volume_nl,
        ),
        critical_volume_nl=point_critical_volume_nl(scene, task),
        layout=scene.pattern.params.get("layout"),
    )
    summary = a.to_dict()
    return require_finite(summary, f"point {task.point}")


def price_point(task: PointTask) -> None:
    """Refuse (InputError, one line) a point whose landscape would not fit the memory budget:
    its scene built as :func:`assess_point` builds it (the pattern rasterized, coarsened as
    evaluate coarsens) and priced by :func:`simulator.landscape.require_landscape_fits`,
    without allocating the landscape: what a command checks before it starts any work."""
    from simulator.batch import auto_resolution
    from simulator.landscape import require_landscape_fits

    scene, auto = point_scene(task)
    scene = auto_resolution(scene) if auto else scene
    require_landscape_fits(scene)
    if scene.dispense is not None:  # the pads' planes of the two protocols
        from simulator.motion import require_footprint_fits

        require_footprint_fits(scene)


#: A point's assessment holds this many times its landscape array (the array and the
#: transforms' work space while it is built, the landscape kept while the global minimum is
#: proven, the restoring forces and biases are measured and the yield's starts run, each
#: with its own buffers); see :func:`point_bytes`. Measured: a 600 um chip's four-pad at
#: 2 um/px (a 264 MB landscape) peaked at 1.64 GB resident in one process, 4.5 x its
#: landscape above the imports.
ASSESS_LANDSCAPES = 5.0
#: What a process holds before its first point: the imports of the engine, JAX and Dask's
#: worker (about 0.4 GB measured; 0.45 GB priced).
WORKER_BASE_BYTES = 460 * 2**20


def point_bytes(task: PointTask) -> int:
    """The peak bytes one point's run holds in its process (priced, nothing allocated): the
    imports (:data:`WORKER_BASE_BYTES`) and :data:`ASSESS_LANDSCAPES` times its landscape
    array (:func:`simulator.landscape.estimate_bytes` of the scene :func:`price_point`
    prices). InputError when the point's own landscape is over its budget
    (:func:`price_point`'s line)."""
    from simulator.batch import auto_resolution
    from simulator.landscape import estimate_bytes, require_landscape_fits

    scene, auto = point_scene(task)
    scene = auto_resolution(scene) if auto else scene
    require_landscape_fits(scene)
    if scene.dispense is not None:  # the pads' planes, built after the landscape is freed
        from patterns.geometry import pad_labels
        from simulator.motion import footprint_budget_bytes, require_footprint_fits

        require_footprint_fits(scene)
        planes = footprint_budget_bytes(scene, pad_labels(scene.pattern)[1])  # with its process
        return int(max(WORKER_BASE_BYTES + ASSESS_LANDSCAPES * estimate_bytes(scene), planes))
    return int(WORKER_BASE_BYTES + ASSESS_LANDSCAPES * estimate_bytes(scene))


def _one_line(err: BaseException) -> str:
    text = " ".join(str(err).split()) or "(no message)"
    return (text if isinstance(err, InputError) else f"{type(err).__name__}: {text}")[:500]


def run_point(task: PointTask) -> dict:
    """Run one point; never raises for the point's own failure: ``status`` "ok" with the
    ``summary``, or "error" with the one-line ``error``. What each Dask task runs."""
    _cap_threads()
    from foundation import quiet_waits

    t0 = time.perf_counter()
    try:
        with quiet_waits():  # the sweep's own bar says how the points go
            summary = assess_point(task)
    except Exception as err:  # the point's failure is its row; the sweep goes on
        return {
            "point": task.point,
            "status": "error",
            "error": _one_line(err),
            "seconds": round(time.perf_counter() - t0, 3),
            "summary": None,
        }
    return {
        "point": task.point,
        "status": "ok",
        "error": None,
        "seconds": round(time.perf_counter() - t0, 3),
        "summary": summary,
    }
