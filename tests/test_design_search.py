"""``selfalign design`` in search mode: Optuna trials evaluated as sweep points are.

The search over the four-pad's gap finds what the exhaustive sweep of the same points finds;
expressions parse safely; constraints keep infeasible trials from being best; a rerun resumes;
bad specs are one line; the outputs hold the best design (its GDSII polygons are the design's);
a two-objective front is non-dominated.
"""

from __future__ import annotations

import copy
import json
import math
from typing import Any

import gdstk
import numpy as np
import pandas as pd
import pytest
import shapely
from cli_helpers import one_line_error  # tests/cli_helpers.py
from shapely.geometry import Polygon

from patterns.geometry import four_pad
from simulator.design import (
    best_trials,
    load_search,
    parse_constraints,
    parse_expression,
    search,
)
from simulator.sweep import expected_columns, run_sweep

# pandas' own annotations make a frame's selections unions of frames, series and arrays:
# the tables whose selections the tests read are typed Any.
#
# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("design_search")

#: The gaps of the 200 um four-pad; 5 um pixels, no twist, a coarse capture grid.
GAPS = [10, 20, 40, 60, 80]
#: The widest gap whose yield under the placement noise stays at 90 %.
SPEC = {
    "scene": {"resolution_um": 5, "effects": {"twist": False}},
    "design": {"name": "four-pad", "size": 200, "gap": 20},
    "axes": {"gap": GAPS, "placement_sigma_um": 40},
    "sweep": {"seed": 1, "yield_starts": 200, "capture_grid": 9},
    "search": {
        "trials": 30,
        "seed": 3,
        "maximize": "gap_um",
        "constraints": ["yield_fraction >= 0.9"],
    },
}
#: Columns that differ between two evaluations of one point (times) or are a search's own.
TIMING = {"seconds", "settings_landscape_s"}


def _sweep_doc(doc: dict) -> dict:
    d = copy.deepcopy(doc)
    d.pop("search")
    return d


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("search") / "out"
    table = search(SPEC, out, workers=0)
    return out, table


@pytest.fixture(scope="module")
def swept():
    return run_sweep(_sweep_doc(SPEC), workers=0)


def test_search_over_the_gap_finds_the_exhaustive_sweeps_best(run, swept):
    _, table = run
    trials = table[table["kind"] == "search"]
    # Every gap was tried (TPE, duplicates reused), and the search stopped there.
    assert sorted(set(trials["gap_um"])) == GAPS
    assert table.attrs["search"]["exhausted"] and len(trials) < SPEC["search"]["trials"]
    assert (trials[trials["same_as"].isna()]["gap_um"].value_counts() == 1).all()
    # Each trial is the sweep's point of the same gap, number for number.
    for _, row in trials.iterrows():
        ref = swept[swept["gap_um"] == row["gap_um"]].iloc[0]
        for col in ref.index:
            if col not in TIMING | {"point", "realization", "point_seed"}:
                assert row[col] == ref[col] or (pd.isna(row[col]) and pd.isna(ref[col])), col
    # The best is the sweep's arg-best under the same objective and constraint.
    ok = swept[swept["yield_fraction"] >= 0.9]
    want = ok.loc[ok["gap_um"].idxmax()]
    (best,) = table.attrs["search"]["best"]
    got = table[table["trial"] == best].iloc[0]
    assert got["gap_um"] == want["gap_um"] == 40 and got["yield_fraction"] == want["yield_fraction"]
    assert bool(got["best"]) and table["best"].sum() == 1
    # The physics in the columns: the maximum bias is one pad side, p = (L - g) / 2.
    assert list(trials.sort_values("gap_um").drop_duplicates("gap_um")["max_bias_x_um"]) == [
        (200 - g) / 2 for g in GAPS
    ]


def test_constraints_keep_infeasible_trials_from_being_best(run):
    _, table = run
    infeasible = table[(table["kind"] == "search") & ~table["feasible"].astype(bool)]
    # The wider gaps have the larger objective but miss the yield: recorded, never best.
    assert set(infeasible["gap_um"]) == {60, 80} and (infeasible["constraint_1"] > 0).all()
    assert (infeasible["objective_1"] > table[table["best"]]["objective_1"].iloc[0]).all()
    assert not infeasible["best"].any()
    best = table[table["best"]].iloc[0]
    assert best["feasible"] and best["constraint_1"] == pytest.approx(0.9 - best["yield_fraction"])
    # best_trials on its own: an infeasible row with the highest objective is not picked.
    spec = load_search(SPEC)
    rows = pd.DataFrame(
        {
            "trial": [0, 1, 2, 3],
            "kind": ["baseline", "search", "search", "search"],
            "state": ["complete", "complete", "complete", "fail"],
            "feasible": [True, False, True, False],
            "objective_1": [99.0, 50.0, 10.0, None],
        }
    )
    assert best_trials(spec, rows) == [2]


def test_the_baseline_is_the_files_design(run, swept):
    _, table = run
    base = table[table["trial"] == 0].iloc[0]
    ref = swept[swept["gap_um"] == SPEC["design"]["gap"]].iloc[0]
    assert base["kind"] == "baseline" and base["gap_um"] == 20
    assert base["yield_fraction"] == ref["yield_fraction"] and base["objective_1"] == 20


def test_rows_have_the_columns_the_objectives_may_name(run):
    _, table = run
    spec = load_search(SPEC)
    expected = set(expected_columns(spec.sweep)) - {"point", "realization", "point_seed"}
    own = {"trial", "kind", "realizations", "state", "same_as", "objective_1", "constraint_1"}
    own |= {"feasible", "best", "volume_nl"}
    assert set(table.columns) == expected | own
    assert (table["volume_nl"] == table["settings_volume_nl"]).all()
    # The four-pad's critical volume (docs/physics.md §8) grows with the gap.
    cv = table.drop_duplicates("gap_um").sort_values("gap_um")["critical_volume_nl"]
    assert np.all(np.diff(cv.to_numpy()) > 0)


def test_outputs_and_the_gds_is_the_best_design(run):
    out, table = run
    for name in (
        "trials.parquet",
        "trials.csv",
        "history.png",
        "pareto.png",
        "best.png",
        "best.gds",
        "best.json",
        "report.html",
        "search.json",
    ):
        assert (out / name).is_file(), name
    pq = pd.read_parquet(out / "trials.parquet")
    csv = pd.read_csv(out / "trials.csv")
    assert list(pq.columns) == list(table.columns) == list(csv.columns) and len(pq) == len(table)
    doc = json.loads((out / "best.json").read_text())
    gap = doc["best"]["values"]["gap"]
    assert doc["best"]["design"]["params"] == {"size": 200, "gap": gap}
    assert doc["baseline"]["design"]["params"] == {"size": 200, "gap": 20}
    (cell,) = gdstk.read_gds(str(out / "best.gds")).top_level()
    assert isinstance(cell, gdstk.Cell)
    polys = [Polygon(p.points) for p in cell.polygons]
    design = four_pad(200, gap)
    got = shapely.union_all(polys)
    assert len(polys) == 4 and got.symmetric_difference(design).area < 1e-6
    assert math.isclose(got.area, design.area, rel_tol=1e-12)
    assert math.isclose(doc["best"]["gds_area_um2"], (200 - gap) ** 2, rel_tol=1e-12)
    page = (out / "report.html").read_text()
    assert "baseline (trial 0)" in page and f"best (trial {doc['best']['trial']})" in page


def test_a_rerun_resumes_and_runs_nothing_new(run, run_cli, capsys):
    out, table = run
    again = search(SPEC, out, workers=0)
    st = again.attrs["search"]
    assert st["evaluated_now"] == 0 and st["reused_now"] == 0
    pd.testing.assert_frame_equal(again, table)
    other = copy.deepcopy(SPEC)
    other["search"]["maximize"] = "yield_fraction"
    with pytest.raises(Exception, match="holds a different search"):
        search(other, out, workers=0)


def test_an_interrupted_search_resumes(tmp_path, monkeypatch, run_cli):
    import simulator.sweep._store as store

    arrivals = []

    def ctrl_c_at_third(point):  # Ctrl-C once the third trial is in the journal
        arrivals.append(point)
        if len(arrivals) == 3:
            raise KeyboardInterrupt

    monkeypatch.setattr(store, "hold", ctrl_c_at_third)
    path, out = tmp_path / "gap.toml", tmp_path / "out"
    path.write_text(_toml(SPEC))
    rc, _, err = run_cli(["design", path, "--out", out, "--workers", "0", "--quiet"])
    assert rc == 130 and "interrupted; 3 finished trials are kept" in err, err
    kept = [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]
    assert [r["trial"] for r in kept] == [0, 1, 2]
    monkeypatch.undo()
    table: Any = search(SPEC, out, workers=0)
    st = table.attrs["search"]
    # The kept trials are replayed, not rerun: every gap is evaluated once over both runs.
    fresh = table[(table["kind"] == "search") & table["same_as"].isna()]
    assert sorted(fresh["gap_um"]) == GAPS and st["exhausted"]
    assert st["evaluated_now"] == len(GAPS) - len(
        {r["gap_um"] for r in kept if r["kind"] == "search"}
    )
    for r in kept:
        row = table[table["trial"] == r["trial"]].iloc[0]
        assert row["gap_um"] == r["gap_um"] and row["seconds"] == r["seconds"]
    assert table.attrs["search"]["best"] == [
        int(table[(table["gap_um"] == 40) & table["same_as"].isna()]["trial"].iloc[0])
    ]


def test_two_objectives_give_a_non_dominated_front(tmp_path):
    doc = copy.deepcopy(SPEC)
    doc["search"] = {
        "trials": 16,
        "sampler": "nsga2",
        "seed": 1,
        "maximize": ["gap_um", "yield_fraction"],
        "constraints": ["capture_fraction >= 0.2"],
    }
    table: Any = search(doc, tmp_path / "out", workers=0)
    front = table.attrs["search"]["best"]
    ok = table[(table["kind"] == "search") & (table["state"] == "complete") & table["feasible"]]
    v = ok[["objective_1", "objective_2"]].to_numpy()
    trials = ok["trial"].to_numpy()

    def dominated(k: int) -> bool:
        return bool(np.any(np.all(v >= v[k], axis=1) & np.any(v > v[k], axis=1)))

    assert front == sorted(int(t) for k, t in enumerate(trials) if not dominated(k))
    # The trade-off: every gap tried is on the front (a wider gap, a lower yield), its
    # yields falling as the gap widens.
    on = ok[ok["trial"].isin(front)].drop_duplicates("gap_um").sort_values("gap_um")
    assert len(on) >= 3 and np.all(np.diff(on["yield_fraction"].to_numpy()) < 0)
    assert (tmp_path / "out" / "pareto.png").is_file()
    doc_best = json.loads((tmp_path / "out" / "best.json").read_text())
    assert [p["trial"] for p in doc_best["pareto_front"]] == front


def test_expressions_are_values_and_nothing_else():
    known = ("a_um", "b_um", "yield_fraction")
    data = {"a_um": np.array([1.0, 3.0]), "b_um": np.array([2.0, 2.0]), "yield_fraction": 0.5}
    e = parse_expression("min(a_um, b_um) / 2 + abs(-3)", known)
    assert e(data) == pytest.approx(np.mean([0.5, 1.0]) + 3)  # per realization, then the mean
    assert e.columns == ("a_um", "b_um")
    assert parse_expression("min(a_um)", known)(data) == 1.0  # the worst realization
    assert parse_expression("max(a_um) - mean(a_um)", known)(data) == 1.0
    assert parse_expression("-yield_fraction * 2", known)(data) == -1.0
    (c,) = parse_constraints("yield_fraction >= 0.4", known, "c")
    assert c.violation(data) == pytest.approx(-0.1)
    lo, hi = parse_constraints("0.6 <= yield_fraction < 0.5", known, "c")
    assert (
        lo.violation(data) == pytest.approx(0.1) and hi.violation(data) > 0
    )  # strict: equal fails
    bad = {
        "c_um": "unknown column c_um; the columns of this search's trials are a_um, b_um, yield_fraction",
        "a_um ** 2": "is not allowed",
        "a_um.real": "is not allowed",
        "__import__('os')": "__import__() is not a function",
        "'text'": "is not a number",
        "True": "is not a number",
        "a_um if b_um else 1": "is not allowed",
        "mean(a_um, b_um)": "mean() takes one expression",
        "min(x=a_um)": "takes no keyword",
        "a_um >= 1": "is a comparison",
        "a_um +": "is not an expression",
        "[a_um]": "is not allowed",
    }
    for text, needle in bad.items():
        with pytest.raises(ValueError, match=None) as err:
            parse_expression(text, known, "[search] maximize")
        assert needle in str(err.value) and "\n" not in str(err.value), (text, err.value)


BAD = [
    ({"search": {"maximize": "yield_fraction"}}, "[search] needs trials"),
    ({"search": {"trials": 0, "maximize": "yield_fraction"}}, "trials = 0"),
    ({"search": {"trials": 3}}, "needs an objective"),
    ({"search": {"trials": 3, "maximize": "yield_frac"}}, "unknown column yield_frac;"),
    ({"search": {"trials": 3, "maximize": "gap_um", "tries": 1}}, "tries: unknown key"),
    ({"search": {"trials": 3, "maximize": "gap_um", "sampler": "grid"}}, 'sampler = "grid"'),
    (
        {"search": {"trials": 3, "maximize": ["gap_um", "yield_fraction"], "sampler": "cmaes"}},
        "optimises one objective",
    ),
    (
        {"search": {"trials": 3, "maximize": "gap_um", "constraints": ["gap_um"]}},
        "not a comparison",
    ),
    ({"axes": {"gap": {"from": 80, "to": 10}}}, "the range is inverted"),
    ({"axes": {"gap": 20}}, "nothing to search"),
    ({"axes": {"pitch": [1, 2]}}, "not a parameter of this sweep"),
    ({"sweep": {"samples": 4}}, "samples is not used by a search"),
    ({"extra": {}}, "unknown section or key"),
    # Priced before any work: the largest trial's pattern does not fit the budget.
    (
        {
            "scene": {"resolution_um": 1, "memory_budget_mb": 100, "effects": {"twist": False}},
            "axes": {"size": {"from": 200, "to": 4000}},
        },
        "a trial at gap = 10, size = 4000 would not fit",
    ),
]


@pytest.mark.parametrize(("change", "needle"), BAD)
def test_bad_specs_are_one_line_and_write_nothing(change, needle, tmp_path, run_cli):
    doc = copy.deepcopy(SPEC)
    for section, table in change.items():
        if section == "search":
            doc["search"] = table
        else:
            doc.setdefault(section, {}).update(table)
    path = tmp_path / "bad.toml"
    path.write_text(_toml(doc))
    rc, _, err = run_cli(["design", path, "--out", tmp_path / "out", "--workers", "2", "--quiet"])
    one_line_error(rc, err, needle)
    assert not (tmp_path / "out").exists()


def _toml(doc: dict) -> str:
    """A small TOML writer for these specs (tables of scalars, lists and inline tables)."""

    def value(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        return repr(v)

    lines = []
    for section, table in doc.items():
        lines.append(f"[{section}]")
        lines += [f"{k} = {value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def test_the_command_prints_the_best_and_resumes(tmp_path, run_cli):
    path = tmp_path / "gap.toml"
    path.write_text(_toml(SPEC))
    out = tmp_path / "out"
    rc, stdout, err = run_cli(["design", path, "--out", out, "--workers", "0", "--quiet"])
    assert rc == 0, err
    lines = stdout.splitlines()
    assert lines[0].startswith("search ") and "over gap" in lines[0]
    assert "all 5 designs of the space tried" in lines[0]
    assert lines[1].startswith("best: trial ") and "(gap_um = 40)" in lines[1]
    assert "maximize gap_um = 40 (baseline 20)" in lines[1]
    assert "best.gds" in lines[2] and (out / "best.gds").is_file()
    rc, stdout, _ = run_cli(["design", path, "--out", out, "--workers", "0", "--quiet"])
    assert rc == 0 and "none run now" in stdout


def test_trials_on_two_dask_workers_are_the_same_evaluations(run, tmp_path):
    _, here = run
    table = search(SPEC, tmp_path / "out", workers=2, trials=6)
    st = table.attrs["search"]
    assert st["workers"] == 2 and st["failed"] == 0 and (st["done"] == 6 or st["exhausted"])
    for _, row in table[table["same_as"].isna()].iterrows():
        ref = here[(here["gap_um"] == row["gap_um"]) & here["same_as"].isna()].iloc[0]
        assert row["yield_fraction"] == ref["yield_fraction"], row["gap_um"]
        assert row["capture_fraction"] == ref["capture_fraction"], row["gap_um"]


def test_realizations_are_averaged_and_min_takes_the_worst(tmp_path):
    # Random-jagged edges: each realization another draw of the edges (seed, seed + 1).
    doc = {
        "scene": {"resolution_um": 5, "effects": {"twist": False}},
        "design": {"name": "random-jagged", "size": 200, "sigma": 2, "seed": 4},
        "axes": {"sigma": [2, 8], "placement_sigma_um": 40},
        "sweep": {"seed": 1, "realizations": 2, "yield_starts": 200, "capture_grid": 9},
        "search": {"trials": 10, "seed": 0, "maximize": "min(max_bias_plus_x_um)"},
    }
    table: Any = search(doc, tmp_path / "out", workers=0)
    assert set(table[table["kind"] == "search"]["sigma_um"]) == {2, 8}
    seeds, spread = set(), False
    for _, row in table[table["same_as"].isna()].iterrows():
        trial = json.loads((tmp_path / "out" / "trials" / f"{row['trial']:05d}.json").read_text())
        reps = trial["realizations"]
        # Each realization its own placement draws, the same for every design (as a sweep's).
        seeds.add(tuple(r["summary"]["yield"]["seed"] for r in reps))
        bias = [r["summary"]["max_bias_um"]["+x"] for r in reps]
        assert row["objective_1"] == min(bias)
        assert row["max_bias_plus_x_um"] == pytest.approx(np.mean(bias))
        assert row["realizations"] == 2 and row["seed"] == 4
        spread |= bias[0] != bias[1]  # another draw of the edges, another bias
    ((a, b),) = seeds
    assert a != b and spread


def test_cmaes_searches_a_continuous_range(tmp_path):
    doc = copy.deepcopy(SPEC)
    doc["axes"]["gap"] = {"from": 10, "to": 80}
    doc["search"] = {
        "trials": 6,
        "sampler": "cmaes",
        "seed": 2,
        "maximize": "gap_um",
        "constraints": ["yield_fraction >= 0.9"],
    }
    table: Any = search(doc, tmp_path / "out", workers=0)
    gaps = table[table["kind"] == "search"]["gap_um"]
    assert len(gaps) == 6 and gaps.between(10, 80).all() and gaps.nunique() == 6
    best = table[table["best"]]
    assert len(best) == 1 and bool(best["feasible"].iloc[0])
    feasible = table[(table["kind"] == "search") & table["feasible"]]
    assert best["gap_um"].iloc[0] == feasible["gap_um"].max()


def test_a_failing_trial_is_its_error_row_and_the_search_goes_on(tmp_path):
    doc = copy.deepcopy(SPEC)
    doc["axes"]["gap"] = [20, 250]  # 250 um: wider than the 200 um pattern
    doc["search"]["trials"] = 6
    table: Any = search(doc, tmp_path / "out", workers=0)
    bad = table[table["gap_um"] == 250]
    assert len(bad) >= 1 and (bad["state"] == "fail").all() and not bad["best"].any()
    assert all("gap=250 um must be smaller than size=200 um" in e for e in bad["error"])
    assert bad["objective_1"].isna().all() and not bad["feasible"].any()
    assert table[table["best"]]["gap_um"].tolist() == [20]


def test_the_comparison_shows_what_the_constraints_read():
    # the example's constraint reads a footprint protocol's yield, which the base rows lack:
    # the table shows it (and each protocol's rows), once, beside the baseline's
    import tomllib
    from pathlib import Path

    from simulator.design._search._report import _compare_table

    doc = tomllib.loads(
        (Path(__file__).resolve().parents[1] / "examples" / "design_fourpad_gap.toml").read_text()
    )
    doc["search"]["constraints"] += ["protocols_pattern_yield_outcomes_plateau <= 20"]
    spec = load_search(doc)
    table = pd.DataFrame(
        {
            "trial": [0, 3],
            "objective_1": [50.0, 75.9],
            "yield_fraction": [1.0, 0.9935],
            "protocols_pattern_yield_fraction": [0.9905, 0.99],
            "protocols_chip_yield_fraction": [0.9875, 0.9865],
            "critical_volume_nl": [9.0, 10.3],
            "protocols_pattern_yield_outcomes_plateau": [19, 20],
        }
    )
    page = _compare_table(spec, table, 3)
    assert page.count("--dispense pattern: yield under placement noise (%)") == 1
    assert "<td>99.05</td><td>99</td>" in page and "<td>98.75</td><td>98.65</td>" in page
    assert "constraint volume_nl &gt;= critical_volume_nl: critical_volume_nl" not in page
    assert page.count("critical volume of the four-pad (nl)") == 1
    row = "constraint protocols_pattern_yield_outcomes_plateau &lt;= 20: "
    assert page.count(row) == 1 and "<td>19</td><td>20</td>" in page
