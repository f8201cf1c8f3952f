"""Each derived quantity has one home and is carried from there: the liquid's height and the
chip's radius of gyration in the Scene (one formula each, computed once per scene, used by
the energy and the dynamics alike), the twist step of a pose grid (one rule, on its twist
axis), the size of a landscape at another pixel size (computed, not found by resampling),
and the scene file (read once per command)."""

from __future__ import annotations

import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from foundation import InputError
from patterns import read_mask
from patterns.geometry import four_pad, mask_from_geometry, square
from patterns.library import library_path
from simulator.batch import auto_resolution
from simulator.cli import build_parser, main
from simulator.commands._request import SceneRequest
from simulator.commands._scene import scene_from_args
from simulator.landscape import PoseGrid, build_landscape, estimate_bytes, plan
from simulator.motion import DynamicsParams, field_and_grid
from simulator.physics import Liquid, couette_damping, couette_torsional_damping, meniscus_height_um
from simulator.scene import Effects, Scene, TwistAxis, TwistGrid, chip_radius_of_gyration_px
from simulator.testing import radius_of_gyration_um

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("derived_once")


def small_scene(**kw) -> Scene:
    """A 200 um square on its own pad at 4 um/px, untwisted: cheap to build."""
    kw.setdefault("effects", Effects(twist=False))
    return Scene(
        pattern=mask_from_geometry(square(200), 4.0, margin_um=20),
        chip=mask_from_geometry(square(200), 4.0),
        **kw,
    )


def cli_scene(*flags: str) -> Scene:
    argv = [
        "simulate",
        "--pattern",
        str(library_path("square_200")),
        "--chip-size",
        "200",
        "--resolution",
        "4",
        "--no-twist",
        *flags,
    ]
    return scene_from_args(SceneRequest.from_args(build_parser().parse_args(argv)))


# ---------------------------------------------------------------- the liquid's height
def test_an_explicit_meniscus_height_is_the_height_of_the_energy_and_of_the_damping():
    # --meniscus-height 8 with --volume 0.5 (V / A = 12.5 um under the 200 um chip): the
    # meniscus's energy and the dynamics' Couette damping both take the 8 um.
    scene = cli_scene("--meniscus-height", "8", "--volume", "0.5", "--damping-calibration", "600")
    p = DynamicsParams.from_scene(scene)
    area, mu, cal = scene.chip.area_um2, scene.liquid.viscosity_Pa_s, scene.damping_calibration
    assert cal is not None
    assert scene.meniscus_height_um == scene.liquid_height_um == 8.0
    assert build_landscape(scene).meniscus_height_um == 8.0
    assert p.damping_N_s_m == pytest.approx(cal * couette_damping(mu, area, 8.0), rel=1e-12)
    assert p.damping_N_s_m != pytest.approx(
        cal * couette_damping(mu, area, meniscus_height_um(0.5, area)), rel=1e-3
    )
    j = area * (scene.chip_rg_px * scene.um_per_px) ** 2
    assert p.rot_damping_N_m_s == pytest.approx(
        cal * couette_torsional_damping(mu, j, 8.0), rel=1e-12
    )


def test_without_a_given_height_energy_and_damping_take_the_volume_over_the_area():
    scene = cli_scene("--meniscus", "--volume", "0.5", "--damping-calibration", "600")
    h = meniscus_height_um(0.5, scene.chip.area_um2)
    assert scene.meniscus_height_um == scene.liquid_height_um == h == pytest.approx(12.5)
    p = DynamicsParams.from_scene(scene)
    assert scene.damping_calibration is not None
    assert p.damping_N_s_m == pytest.approx(
        scene.damping_calibration
        * couette_damping(scene.liquid.viscosity_Pa_s, scene.chip.area_um2, h),
        rel=1e-12,
    )
    # The overlap model (no meniscus) has no meniscus height; the film under the chip is the same.
    flat = cli_scene("--volume", "0.5", "--damping-calibration", "600")
    assert flat.meniscus_height_um is None and flat.liquid_height_um == h
    assert DynamicsParams.from_scene(flat).damping_N_s_m == p.damping_N_s_m


def test_the_height_is_derived_once_per_scene(monkeypatch):
    calls = []
    rule = Liquid.meniscus_height_um
    monkeypatch.setattr(
        Liquid, "meniscus_height_um", lambda self, area: calls.append(area) or rule(self, area)
    )
    scene = small_scene(effects=Effects(twist=False, meniscus=True), liquid=Liquid(volume_nl=0.5))
    for _ in range(3):
        assert scene.meniscus_height_um == scene.liquid_height_um
    _ = scene.meniscus_height_px, scene.wall_profile, scene.meniscus_margin_px
    ls = build_landscape(scene)
    DynamicsParams.from_scene(scene)
    assert ls.meniscus_height_um is scene.meniscus_height_um
    assert len(calls) == 1


# ---------------------------------------------------------------- the radius of gyration
def test_one_radius_of_gyration_for_the_pose_grid_the_steppers_and_the_dynamics():
    scene = small_scene(effects=Effects(), twist=TwistGrid(5.0), damping_calibration=600.0)
    rg = chip_radius_of_gyration_px(scene.chip)
    assert scene.chip_rg_px == rg
    # The plan makes the pose grid complete: the landscape and the steppers carry it unchanged.
    assert plan(scene).grid.rg_px == rg
    ls = build_landscape(scene)
    assert ls.grid.rg_px == rg
    assert field_and_grid(ls)[1].rg_px == rg
    # The dynamics' polar moment is A rg^2, in the inertia and the rotational damping.
    p = DynamicsParams.from_scene(scene)
    area, s = scene.chip.area_um2, scene.um_per_px
    j = area * (rg * s) ** 2
    rho_t = scene.chip_density_kg_m3 * scene.chip_thickness_um * 1e-6
    assert p.inertia_kg_m2 == pytest.approx(rho_t * j * 1e-24, rel=1e-12)
    assert p.mass_kg == pytest.approx(rho_t * area * 1e-12, rel=1e-12)
    h = scene.liquid_height_um
    assert scene.damping_calibration is not None
    assert p.rot_damping_N_m_s == pytest.approx(
        scene.damping_calibration * couette_torsional_damping(scene.liquid.viscosity_Pa_s, j, h),
        rel=1e-12,
    )


def test_the_raster_radius_of_gyration_is_the_exact_one_less_the_pixels_own_moment():
    # A 200 um square of 50 x 50 full pixels: pixel centres give (n^2 - 1) / 6 px^2, the exact
    # value n^2 / 6 (simulator.testing's, from the polygon) less 1/6 px^2 (each pixel's own moment).
    scene = small_scene()
    exact_px = radius_of_gyration_um(square(200)) / scene.um_per_px
    assert scene.chip_rg_px**2 + 1 / 6 == pytest.approx(exact_px**2, rel=1e-12)
    assert exact_px == pytest.approx(50 / math.sqrt(6), rel=1e-12)


# ---------------------------------------------------------------- the twist step
def test_one_rule_for_the_twist_step_of_a_pose_grid():
    axis = TwistAxis(None, 2.0, -22, 45, True, 90.0, True)
    assert axis.grid_step_deg == axis.step_deg_for(45) == 2.0
    whole = PoseGrid((45, 3, 3), 1.0, axis, wrap=True)
    one = PoseGrid((1, 3, 3), 1.0, axis, t_first=4)
    assert whole.twist_step_deg == axis.grid_step_deg == 2.0
    assert one.twist_step_deg == axis.step_deg_for(1) == 1.0
    untwisted = small_scene().twist_axis
    assert (
        untwisted.count == 1
        and untwisted.grid_step_deg == 1.0 == build_landscape(small_scene()).twist_step_deg
    )


# ---------------------------------------------------------------- the pixel size
def _old_auto_resolution(scene: Scene, budget_mb: float) -> Scene:
    """The search auto_resolution made before: resample at each multiple, measure, stop when it fits."""
    for k in range(1, 17):
        s = scene if k == 1 else scene.at_resolution(scene.um_per_px * k)
        if estimate_bytes(s) / 2**20 <= budget_mb:
            return s
    return s


def _scenes() -> dict[str, Scene]:
    fp = mask_from_geometry(four_pad(400, 40), 2.0, margin_um=10)
    png = read_mask(library_path("square_200"), default_um_per_px=1.0)
    return {
        "four-pad geometry": Scene(
            pattern=fp, chip=mask_from_geometry(square(400), 2.0), twist=TwistGrid(3.0)
        ),
        "meniscus, window": Scene(
            pattern=fp,
            chip=mask_from_geometry(square(400), 2.0),
            effects=Effects(twist=False, meniscus=True),
            liquid=Liquid(volume_nl=2.0),
            window_um=150.0,
        ),
        "PNG pattern and chip": Scene.from_inputs(png, chip=png, twist=TwistGrid(5.0)),
    }


@pytest.mark.parametrize("name", list(_scenes()))
def test_the_size_of_a_landscape_at_another_pixel_size_is_computed(name):
    scene = _scenes()[name]
    for k in range(1, 17):
        s = scene.um_per_px * k
        assert estimate_bytes(scene, um_per_px=s) == estimate_bytes(scene.at_resolution(s)), (
            name,
            k,
        )


@pytest.mark.parametrize("name", list(_scenes()))
def test_auto_resolution_chooses_what_the_resampling_search_chose(name, monkeypatch):
    import simulator.scene._scene as scene_module

    scene = _scenes()[name]
    sizes = [estimate_bytes(scene, um_per_px=scene.um_per_px * k) / 2**20 for k in (1, 2, 3, 5, 16)]
    resampled = []
    real = scene_module.resample_to_scale
    monkeypatch.setattr(
        scene_module, "resample_to_scale", lambda m, s, b=None: resampled.append(s) or real(m, s, b)
    )
    for budget in sorted({*sizes, *(0.999 * v for v in sizes), 1e-9}):
        old = _old_auto_resolution(scene, budget).um_per_px
        resampled.clear()
        new = auto_resolution(scene, budget)
        assert new.um_per_px == old, (name, budget)
        assert len(resampled) == (
            0 if new is scene else 2
        )  # pattern and chip, once, at the size chosen


# ---------------------------------------------------------------- the scene file
@pytest.fixture
def count_toml_reads(monkeypatch):
    calls = []
    loads = tomllib.loads
    monkeypatch.setattr(tomllib, "loads", lambda text, **kw: calls.append(1) or loads(text, **kw))
    return calls


def _scene_file(tmp_path, table: str) -> str:
    p = tmp_path / "scene.toml"
    p.write_text(
        f'pattern = "{library_path("square_200")}"\nchip_size_um = [200, 200]\nresolution_um = 4\n'
        f"[effects]\ntwist = false\n[liquid]\nvolume_nl = 0.5\n{table}"
    )
    return str(p)


def test_simulate_reads_its_scene_file_once(tmp_path, count_toml_reads, capsys):
    scene = _scene_file(tmp_path, "[simulate]\nstart = [12, 0, 0]\n")
    assert main(["simulate", scene, "--quiet", "--json", str(tmp_path / "t.json")]) == 0
    assert "aligned" in capsys.readouterr().out
    assert len(count_toml_reads) == 1


def test_montecarlo_reads_its_scene_file_once(tmp_path, count_toml_reads, capsys):
    scene = _scene_file(tmp_path, '[montecarlo]\ngrid = "-12:12:12,-12:12:12"\n')
    assert main(["montecarlo", scene, "--quiet", "--json", str(tmp_path / "m.json")]) == 0
    capsys.readouterr()
    assert len(count_toml_reads) == 1


def test_energy_reads_its_scene_file_once(tmp_path, count_toml_reads, capsys):
    scene = _scene_file(tmp_path, "")
    assert main(["energy", scene, "--at", "10,0,0", "--json", str(tmp_path / "e.json")]) == 0
    capsys.readouterr()
    assert len(count_toml_reads) == 1


def test_the_smallest_feature_of_a_pattern_image_is_measured_once(monkeypatch):
    """A pattern image's smallest feature (outlining the whole image) is measured once per
    mask, whether the preset, the warning or the pattern's own check asks."""
    from simulator.scene import _accuracy, smallest_feature_um

    calls = []
    measure = _accuracy._smallest_feature_um
    monkeypatch.setattr(
        _accuracy, "_smallest_feature_um", lambda *a: calls.append(1) or measure(*a)
    )
    mask = read_mask(library_path("four_pad_730_50"))
    first = smallest_feature_um(mask)
    assert smallest_feature_um(mask) == first and len(calls) == 1
    assert first == pytest.approx(50, abs=2 * mask.um_per_px)  # the gap


# ---------------------------------------------------------------- the method names
SIMULATOR = Path(__file__).resolve().parents[1] / "simulator"


def _sources_matching(pattern: str) -> set[str]:
    """The modules under simulator/ (paths relative to it) whose text matches ``pattern``."""
    rx = re.compile(pattern)
    return {
        p.relative_to(SIMULATOR).as_posix()
        for p in SIMULATOR.rglob("*.py")
        if rx.search(p.read_text(encoding="utf-8"))
    }


def test_the_method_names_are_written_once():
    """The dynamic methods are simulator.core.DYNAMIC_METHODS and the methods METHODS,
    written out in core alone (the scene schema's value kinds still list the methods: its
    own registry, which may take them from core)."""
    from simulator.core import DYNAMIC_METHODS, METHODS

    assert DYNAMIC_METHODS == METHODS[-2:] == ("overdamped", "inertial")
    assert _sources_matching(r'\(\s*"overdamped",\s*"inertial",?\s*\)') == {"core/_defaults.py"}
    assert _sources_matching(r'"greedy",\s*"gradient",\s*"overdamped",\s*"inertial"') <= {
        "core/_defaults.py",
        "scene/_schema_kinds.py",
    }
    assert _sources_matching(r"\bDYNAMIC\s*=|DYNAMIC_METHODS as ") == set()


def test_the_start_limits_and_distributions_are_written_once():
    """The largest |twist| (ten turns), the most starts and the placements' distributions
    are simulator.core's: the schema, the twist grid, a run's and a batch's start checks and
    the sweep's axes import them, and no module writes the numbers or the pair again."""
    from simulator.core import DISTRIBUTIONS, MAX_STARTS, MAX_TWIST_DEG
    from simulator.scene import TwistGrid, _schema as schema

    assert (MAX_TWIST_DEG, MAX_STARTS, DISTRIBUTIONS) == (3600, 10**8, ("normal", "uniform"))
    assert (schema.MAX_TWIST_DEG, schema.MAX_STARTS) == (MAX_TWIST_DEG, MAX_STARTS)
    assert schema.DISTRIBUTIONS is DISTRIBUTIONS
    assert _sources_matching(r"(?<![\w.])3600(?![\w.])") == {"core/_defaults.py"}
    assert _sources_matching(r"10\s*\*\*\s*8\b") == {"core/_defaults.py"}
    assert _sources_matching(r'\(\s*"normal",\s*"uniform",?\s*\)') == {"core/_defaults.py"}
    TwistGrid(1.0, -MAX_TWIST_DEG, MAX_TWIST_DEG)  # the grid takes the limit itself
    with pytest.raises(InputError, match=f"within \\+-{MAX_TWIST_DEG} degrees"):
        TwistGrid(1.0, -MAX_TWIST_DEG - 1.0, 0.0)


# ---------------------------------------------------------------- simulate's plan
def test_simulate_chooses_its_engine_with_the_bands_of_the_run():
    """One plan (simulator.motion.plan_run) chooses the engine and prices the first
    landscape; choose_engine is called with the run's own bands, never with numbers."""
    assert _sources_matching(r"\bchoose_engine\(") == {
        "motion/_pathrun.py",  # its definition
        "motion/_pricing.py",  # plan_run
        "motion/_footprint_run.py",  # a --dispense run's engine
    }
    rx = re.compile(r"\bchoose_engine\(([^)]*)\)")
    for name in ("_pricing.py", "_footprint_run.py"):
        for args in rx.findall((SIMULATOR / "motion" / name).read_text()):
            assert args.split(",")[-2:] in (
                [" band_steps", " band_px"],
                [" BAND_STEPS", " BAND_PX"],
            ), (name, args)


@pytest.mark.parametrize("engine", ["auto", "fft", "path"])
def test_the_simulate_command_runs_on_the_library_plans_engine(engine, monkeypatch, capsys):
    import simulator.motion as face
    import simulator.motion._pricing as pricing
    import simulator.motion._trajectory as trajectory

    planned, ran = [], []
    real = pricing.plan_run

    def plan_run(*a, **k):
        plan = real(*a, **k)
        planned.append(plan.engine)
        return plan

    def fake_simulate(scene, start, **kw):  # the run stops here, once planned
        ran.append(kw["plan"].engine)
        raise InputError("stopped before the run")

    for module in (face, pricing, trajectory):  # the face may hold a name it loaded before
        monkeypatch.setattr(module, "plan_run", plan_run, raising=module is pricing)
        monkeypatch.setattr(module, "simulate", fake_simulate, raising=module is trajectory)
    argv = ["simulate", "--pattern", str(library_path("square_200")), "--chip-size", "200"]
    argv += ["--resolution", "4", "--no-twist", "--start", "12,0,0", "--engine", engine]
    assert main([*argv, "--quiet"]) == 2
    assert "stopped before the run" in capsys.readouterr().err
    assert len(planned) == 1 and ran == planned and planned[0] in ("fft", "path")
    assert planned[0] == (engine if engine != "auto" else "fft")  # a 50 px chip: the FFT engine


def _count_pricing(monkeypatch) -> list[int]:
    """Count the first landscape's pricings (simulator.motion.require_run_fits, which
    plan_run calls from its own module); returns the list each call appends to."""
    import simulator.motion._pricing as pricing

    calls: list[int] = []
    real = pricing.require_run_fits

    def require_run_fits(*a, **k):
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(pricing, "require_run_fits", require_run_fits)
    return calls


def test_the_simulate_command_plans_once(monkeypatch, capsys):
    """selfalign simulate makes the run's plan once and the library runs on it: one pricing
    of the first landscape for the whole command (the run was priced twice before)."""
    calls = _count_pricing(monkeypatch)
    argv = ["simulate", "--pattern", str(library_path("square_200")), "--chip-size", "200"]
    argv += ["--resolution", "4", "--no-twist", "--start", "12,0,0", "--quiet"]
    assert main(argv) == 0
    assert "greedy: aligned" in capsys.readouterr().out
    assert len(calls) == 1


def test_a_run_given_its_plan_does_not_plan_again(monkeypatch):
    """simulate(..., plan=) takes the plan's engine and prices nothing again; without a plan
    it plans as before; the plan carries what was decided, with its units."""
    from simulator.motion import RunPlan, plan_run, simulate

    scene, start = small_scene(), (12.0, 0.0, 0.0)
    plan = plan_run(scene, start, "greedy")
    assert isinstance(plan, RunPlan) and plan.engine == "fft" and plan.landscape_bytes > 0
    assert (plan.method, plan.start, plan.path) == ("greedy", start, False)
    with pytest.raises(AttributeError):
        plan.engine = "path"  # type: ignore[misc]  # frozen
    calls = _count_pricing(monkeypatch)
    given = simulate(scene, start, plan=plan)
    assert given.cost is not None  # a packaged run has its cost
    assert calls == [] and given.cost.engine == "fft"
    planned = simulate(scene, start)
    assert calls == [1]
    np.testing.assert_array_equal(given.path, planned.path)


def test_a_plan_for_another_run_is_refused():
    """A plan is the run's it was made for: another scene (even an equal one), start or
    method is refused in one line, and so is a plan with a landscape."""
    from simulator.motion import plan_run, simulate

    scene, start = small_scene(), (12.0, 0.0, 0.0)
    plan = plan_run(scene, start, "greedy")
    with pytest.raises(InputError, match="made for another scene") as err:
        simulate(small_scene(), start, plan=plan)
    assert "\n" not in str(err.value)
    with pytest.raises(InputError, match="made for another start"):
        simulate(scene, (8.0, 0.0, 0.0), plan=plan)
    with pytest.raises(InputError, match="made for another method"):
        simulate(scene, start, method="gradient", plan=plan)
    ls = build_landscape(scene)
    with pytest.raises(InputError, match="give plan or landscape, not both"):
        simulate(scene, start, landscape=ls, plan=plan)


# ---------------------------------------------------------------- the default chip
def test_evaluate_and_a_sweep_point_take_the_same_default_chip(tmp_path):
    """Without a chip, evaluate and a sweep's point take the pattern's wettable bounding box
    (patterns.geometry.default_chip_um), to the last bit."""
    from patterns.geometry import default_chip_um
    from simulator.commands._flags import parse_chip_size
    from simulator.commands.evaluate import _bbox_chip
    from simulator.sweep import PointTask
    from simulator.sweep._point import point_scene

    png = str(library_path("four_pad_730_50"))
    out = ["--out", str(tmp_path / "o")]
    odd = ["--pattern-um-per-px", "0.7654321", "--override-scale"]
    args = build_parser().parse_args(["evaluate", "--pattern", png, *out, *odd])
    assert parse_chip_size(_bbox_chip(args)) == default_chip_um(read_mask(png, um_per_px=0.7654321))
    args = build_parser().parse_args(["evaluate", "--pattern", png, *out])
    task = PointTask(0, 0, 0, {}, {"pattern": png}, None, tmp_path, 2000, 25)
    chip = point_scene(task)[0].chip.geometry.bounds
    assert parse_chip_size(_bbox_chip(args)) == (chip[2] - chip[0], chip[3] - chip[1])
    # a generated design's point: the bounds of its exact geometry
    assert default_chip_um(four_pad(400, 40)) == (400, 400)
    # every other default chip is this rule's
    rx = re.compile(r'chip_size_um"\]\s*=\s*(.*)')
    for path in ("sweep/_point.py", "commands/evaluate.py"):
        for rhs in rx.findall((SIMULATOR / path).read_text()):
            assert rhs.startswith(('v["chip_size_um"]', "list(default_chip_um(")), (path, rhs)


# ---------------------------------------------------------------- the critical volume
def test_the_critical_volume_of_a_scenes_four_pad_has_one_home(monkeypatch):
    """The warnings, the volume window and a sweep's point take the critical volume of a
    scene's four-pad from simulator.liquid.scene_critical_volume, computed once."""
    import simulator.liquid._critical_volume as cv_module
    from simulator.liquid import scene_critical_volume, scene_warnings, volume_window
    from simulator.liquid._warnings import _critical_volume
    from simulator.sweep import PointTask
    from simulator.sweep._point import point_critical_volume_nl

    calls = []
    real = cv_module.critical_volume
    monkeypatch.setattr(cv_module, "critical_volume", lambda *a: calls.append(a) or real(*a))
    _critical_volume.cache_clear()
    pattern = read_mask(library_path("four_pad_730_50"))
    scene = Scene.from_inputs(
        pattern,
        chip=mask_from_geometry(square(730), pattern.um_per_px),
        liquid=Liquid(volume_nl=0.001),
    )
    critical = scene_critical_volume(scene)
    assert critical is not None
    cv = critical.critical_volume_nl
    assert volume_window(scene)["critical_volume_nl"] == cv
    task = PointTask(0, 0, 0, {}, {}, None, Path("."), 2000, 25)
    assert point_critical_volume_nl(scene, task) == cv
    assert any(f"critical volume {cv:.3g} nl" in w for w in scene_warnings(scene))
    assert len(calls) == 1
    _critical_volume.cache_clear()
    assert _sources_matching(r"(?<![_\w])critical_volume\(") == {
        "liquid/_critical_volume.py",  # its definition
        "liquid/_warnings.py",  # scene_critical_volume
        "liquid/_dispense.py",  # the dispensed drop's split
        "commands/liquid.py",  # selfalign liquid critical-volume: the user's L and g
    }


# ---------------------------------------------------------------- the units
def test_the_unit_factors_are_cores():
    """um -> m, um^2 -> m^2 and nl -> um^3 are simulator.core's UM, UM2 and UM3_PER_NL,
    defined there alone and never multiplied in as literals."""
    from simulator.core import UM, UM2, UM3_PER_NL

    assert (UM, UM2, UM3_PER_NL) == (1e-6, 1e-12, 1e6)
    assert _sources_matching(r"(?m)^\s*(UM|UM2|UM3_PER_NL)\s*=") == {"core/_constants.py"}
    assert _sources_matching(r"[*/]\s*1(\.0)?e-(0?6|12)\b") == set()
    assert _sources_matching(r"volume_nl\s*[*/]\s*1(\.0)?e\+?0?6\b") == set()


# ---------------------------------------------------------------- the packages
ROOT = SIMULATOR.parent


def _tree_packages() -> set[str]:
    """Every package of the three floors, by its folder's ``__init__.py``."""
    return {
        ".".join(p.parent.relative_to(ROOT).parts)
        for floor in ("foundation", "patterns", "simulator")
        for p in (ROOT / floor).rglob("__init__.py")
    }


def _faces() -> list[str]:
    """simulator's packages (its folders with an ``__init__.py``), the tree's one list."""
    return sorted(p.parent.name for p in SIMULATOR.glob("*/__init__.py"))


def test_every_list_of_the_packages_is_the_tree():
    """The packages are the folders: the build's list (pyproject.toml), the architecture's
    table, the API reference's index and the manual's navigation name exactly those."""
    faces = _faces()
    assert {"core", "design", "commands"} <= set(faces)
    built = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    # patterns.library: the bundled PNGs' folder, declared so that setuptools installs them
    assert sorted(built) == sorted(_tree_packages() | {"patterns.library"})

    arch = (ROOT / "docs" / "architecture.md").read_text()
    table = arch.split("\n`simulator/`:\n", 1)[1].split("\n`foundation/`", 1)[0]
    rows = [r.split("|")[1] for r in table.splitlines() if r.startswith("| `")]
    assert sorted(n for r in rows for n in re.findall(r"`(\w+)`", r)) == sorted([*faces, "cli"])

    index = (ROOT / "docs" / "api" / "index.md").read_text()
    listed = re.findall(r"^\| \[`simulator\.(\w+)`", index, re.M)
    pages = sorted(n if n != "commands" else "cli" for n in faces)  # one page: cli, commands
    assert sorted(listed) == pages
    assert "[`simulator.cli`, `simulator.commands`](cli.md)" in index
    nav = (ROOT / "mkdocs.yml").read_text()
    assert sorted([*re.findall(r"- simulator\.(\w+): api/\w+\.md", nav), "cli"]) == pages
    assert "(cli, commands): api/cli.md" in nav
    assert all((ROOT / "docs" / "api" / f"{page}.md").is_file() for page in pages)


# ---------------------------------------------------------------- the Dask start
def test_a_sweep_and_a_search_start_their_workers_in_one_place():
    """simulator.sweep.start_workers caps, starts and names the workers of a sweep and of a
    design search; nothing else starts a Dask client or caps its workers."""
    import contextlib

    from simulator.sweep import start_workers

    assert _sources_matching(r"\bdask_client\(|\bworker_cap\(|\bLocalCluster\(") == {
        "sweep/_cluster.py"
    }
    asked = []

    def price() -> tuple[float | None, float | None]:
        asked.append(1)
        return None, None

    with contextlib.ExitStack() as stack:
        for workers, points in ((0, 5), (None, 0), (3, 0)):
            client, _, where = start_workers(stack, workers, None, points, price)
            assert client is None and where == "this process"
    assert asked == []  # no workers start: nothing priced


# ---------------------------------------------------------------- the metrics' labels
def test_each_metric_has_one_label():
    """The sweep's pictures and a search's comparison label a metric alike: from
    simulator.sweep.METRIC_LABELS, whose columns are the assessment's."""
    from simulator.design._search._report import COMPARED, PROTOCOL_COMPARED
    from simulator.sweep import METRIC_LABELS, metric
    from simulator.sweep._columns import _metric_columns
    from simulator.sweep._report import METRICS

    for row in (*METRICS, *COMPARED):
        assert row == metric(row[0]) and row[0] in METRIC_LABELS, row
    for column, label, factor in PROTOCOL_COMPARED:
        name, base = column.removeprefix("protocols_").split("_", 1)
        assert (label, factor) == (f"--dispense {name}: {metric(base)[1]}", metric(base)[2])
    every = _metric_columns(twist=True, meniscus=True, free=True, dynamics=True, dispense=True)
    assert set(METRIC_LABELS) - set(every) == {"volume_nl", "critical_volume_nl"}  # not assess's
    for label, _ in METRIC_LABELS.values():  # written in one place (an axis's help aside)
        found = _sources_matching(re.escape(f'"{label}"')) - {"sweep/_axes.py", "scene/_params.py"}
        assert found == {"sweep/_columns.py"}, label


# ---------------------------------------------------------------- the result files' JSON
def test_every_result_json_is_written_by_one_helper():
    """summary.json, fit.json, result.json, best.json, a sweep's point files and journal, and
    every command's --json: foundation.json_text, the same bytes as before, no NaN."""
    import json

    from foundation import json_text

    doc = {"x_um": 1.5, "n": [1, 2], "name": "a", "nested": {"ok": True}}
    assert json_text(doc) == json.dumps(doc, indent=2, allow_nan=False) + "\n"
    assert json_text(doc, indent=1) == json.dumps(doc, indent=1, allow_nan=False) + "\n"
    assert json_text(doc, indent=None) == json.dumps(doc, allow_nan=False) + "\n"
    with pytest.raises(ValueError):
        json_text({"x": math.nan})
    assert _sources_matching(r"allow_nan\s*=") == set()
