"""A sweep's point and task: frozen, picklable (Dask ships a task to its worker), drawn by the
spec's rule (docs/guide/sweeps.md, "Seeds"), and a point's scene merged as the flags merge."""

from __future__ import annotations

import dataclasses
import itertools
import pickle

import numpy as np
import pytest

from patterns.library import library_path
from simulator.scene import CHIP_KEYS, merge_values
from simulator.sweep import ID_COLUMNS, PointTask, SweepPoint, load_sweep

#: A grid of two axes (3 gaps x 2 volumes) of a small four-pad, two realizations each.
SPEC = {
    "scene": {"resolution_um": 5, "effects": {"twist": False}},
    "design": {"name": "four-pad", "size": 200, "gap": 20},
    "axes": {"gap": [10, 20, 40], "volume_nl": [1, 2]},
    "sweep": {"seed": 7, "realizations": 2, "yield_starts": 50, "capture_grid": 5},
}


def _seed(entropy: int, key: tuple[int, int]) -> int:
    """numpy's SeedSequence of the sweep seed spawned at ``key``: the spec's rule of a point's seed."""
    seq = np.random.SeedSequence(entropy=entropy, spawn_key=key)
    return int(seq.generate_state(1, np.uint32)[0])


def test_a_point_and_its_task_are_frozen_and_pickle_to_equals():
    spec = load_sweep(SPEC)
    point = spec.points()[3]
    task = spec.task(point)
    assert isinstance(point, SweepPoint) and isinstance(task, PointTask)
    for obj in (point, task):
        with pytest.raises(dataclasses.FrozenInstanceError):
            obj.point = 99  # type: ignore[misc]  # frozen: the assignment is what is tested
        again = pickle.loads(pickle.dumps(obj))
        assert again == obj and type(again) is type(obj)
    assert task.values == point.values and task.columns() == point.columns()
    assert (task.scene, task.design, task.base) == (spec.scene, spec.design, spec.base_dir)
    assert (task.yield_starts, task.capture_grid) == (50, 5)
    assert tuple(point.columns()) == ID_COLUMNS == ("point", "realization", "point_seed")


@pytest.mark.parametrize("independent", [False, True])
def test_points_are_the_grid_in_order_with_the_specs_seeds(independent):
    spec = load_sweep(SPEC | {"sweep": SPEC["sweep"] | {"independent_noise": independent}})
    designs = [
        {"gap": g, "volume_nl": v}
        for g, v in itertools.product(SPEC["axes"]["gap"], SPEC["axes"]["volume_nl"])
    ]
    expected = [
        (i, r, d, _seed(7, (1, i) if independent else (0, r)))
        for i, (d, r) in enumerate(itertools.product(designs, range(2)))
    ]
    got = [(p.point, p.realization, dict(p.values), p.point_seed) for p in spec.points()]
    assert got == expected
    seeds = {p.point_seed for p in spec.points()}
    assert len(seeds) == (12 if independent else 2)  # common random numbers: one per realization
    # a point made alone is the one points() lists
    assert spec.point(designs[2], 4, 0) == spec.points()[4]


def test_a_chip_axis_replaces_the_base_scenes_chip_as_a_flag_does(tmp_path):
    """merge_values: a chip among the values removes every chip key of the document."""
    doc = {"chip": "c.png", "chip_layer": "2/0", "materials": {"pad_angle_deg": 10}}
    merge_values(doc, {(None, "chip_size_um"): [300.0, 300.0], ("materials", "pad_angle_deg"): 20})
    assert doc == {"materials": {"pad_angle_deg": 20}, "chip_size_um": [300.0, 300.0]}
    doc = {"chip": "c.png", "pattern": "p.png"}
    merge_values(doc, {("liquid", "volume_nl"): 2.0})  # no chip given: the document's stays
    assert doc == {"chip": "c.png", "pattern": "p.png", "liquid": {"volume_nl": 2.0}}
    assert set(CHIP_KEYS) == {"chip", "chip_size_um", "chip_layer"}
    # a sweep point: a base scene's chip image replaced by the point's chip_size_um
    chip = str(library_path("four_pad_730_50"))
    spec = load_sweep(
        {
            "scene": {"chip": chip, "resolution_um": 5, "effects": {"twist": False}},
            "design": {"name": "four-pad", "size": 200, "gap": 20},
            "axes": {"chip_size_um": [150, 250]},
        },
        base=tmp_path,
    )
    from simulator.sweep import point_scene

    for p, size in zip(spec.points(), (150, 250), strict=True):
        x0, y0, x1, y1 = point_scene(spec.task(p))[0].chip.geometry.bounds
        assert (x1 - x0, y1 - y0) == pytest.approx((size, size))
