"""Pictures: trajectory GIFs (chip drawn at the right pose, y up, twist CCW), landscape
and force plots, the demo command and the ``--gif`` option of ``simulate``."""

import json

import imageio.v3 as iio
import numpy as np
import pytest
from matplotlib.colors import to_rgb
from shapely.geometry import Polygon

from foundation import InputError, announce_once
from patterns.geometry import Mask, build, mask_from_geometry
from patterns.library import library_path
from simulator.cli import main
from simulator.landscape import build_landscape
from simulator.motion import Trajectory, simulate
from simulator.render import (
    CHIP_COLOUR,
    TrajectoryAnimation,
    chip_outline,
    frame_indices,
    plot_forces,
    plot_landscape,
    write_trajectory_gif,
)
from simulator.scene import Effects, Scene

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("render")

SQUARE = str(library_path("square_200"))
START = (40.0, -30.0, 6.0)
CHIP_RGB = np.array(to_rgb(CHIP_COLOUR)) * 255


@pytest.fixture(scope="module")
def run():
    scene = Scene.from_inputs(SQUARE, chip_size_um=200)
    traj = simulate(scene, START)
    assert traj.outcome == "aligned" and traj.steps > 12
    return scene, traj


@pytest.fixture(scope="module")
def small_landscape():
    pattern = mask_from_geometry(build("four-pad", size=200, gap=20), 4.0, margin_um=8)
    return build_landscape(Scene.from_inputs(pattern, chip_size_um=200)), pattern


# ---------------------------------------------------------------- frames and outlines
def _fake(n: int, t_s=None) -> Trajectory:
    return Trajectory("greedy", "aligned", np.zeros((n, 3)), np.zeros(n), n - 1, t_s=t_s)


@pytest.mark.parametrize(
    "n, most", [(1, 120), (50, 120), (120, 120), (121, 120), (5000, 120), (5000, 2)]
)
def test_frame_indices_keep_first_and_last_within_the_limit(n, most):
    idx = frame_indices(_fake(n), most)
    assert idx[0] == 0 and idx[-1] == n - 1 and len(idx) <= most
    assert len(idx) == min(n, most) and np.all(np.diff(idx) > 0)


def test_frame_indices_of_dynamics_are_even_in_time():
    t = np.concatenate([np.linspace(0, 1e-3, 900), np.linspace(1.1e-3, 1e-2, 100)])  # dense start
    idx = frame_indices(_fake(1000, t), 20)
    assert idx[0] == 0 and idx[-1] == 999 and len(idx) <= 20
    assert np.ptp(np.diff(t[idx])[1:-1]) < 2e-4  # gaps of about 0.5 ms, not 900 frames of the start


def test_frame_indices_bad_limit():
    with pytest.raises(InputError, match="max_frames"):
        frame_indices(_fake(10), 1)


def test_chip_outline_of_a_png_keeps_its_area_and_hole():
    data = np.zeros((60, 80))
    data[10:50, 10:70] = 1
    data[20:30, 20:40] = 0  # a hole, left of and above the centre
    geom = chip_outline(Mask(data, 2.0))
    assert isinstance(geom, Polygon)
    assert geom.area == pytest.approx(data.sum() * 4.0, rel=0.03)
    assert len(geom.interiors) == 1
    hole = geom.interiors[0].centroid  # rows 20..30, cols 20..40: x = (30 - 40) 2, y = (30 - 25) 2
    assert (hole.x, hole.y) == pytest.approx((-20.0, 10.0), abs=0.5)


def test_chip_outline_of_exact_geometry_is_the_geometry(run):
    scene, _ = run
    assert chip_outline(scene.chip) is scene.chip.geometry


# ---------------------------------------------------------------- the GIF
def _chip_pixels(frame: np.ndarray, box: tuple[slice, slice]) -> np.ndarray:
    """(row, col) of the pixels drawn in the chip's outline colour inside ``box``."""
    crop = frame[box].astype(float)
    rows, cols = np.nonzero(np.abs(crop - CHIP_RGB).sum(axis=-1) < 60)
    return np.column_stack([rows + box[0].start, cols + box[1].start])


def test_gif_frames_show_the_chip_at_the_start_and_final_poses(run, tmp_path):
    scene, traj = run
    out = tmp_path / "t.gif"
    n = write_trajectory_gif(scene, traj, out, max_frames=12)
    frames = iio.imread(out, index=None)
    assert n == len(frames) == 12
    assert iio.immeta(out)["loop"] == 0

    anim = TrajectoryAnimation(scene, traj, max_frames=12)  # same layout as the GIF
    assert frames.shape[1:] == (440, 880, 3)
    (c0, r1), (c1, r0) = anim.pixel_of(anim.ax.get_xlim(), anim.ax.get_ylim())
    box = (slice(int(r0) + 3, int(r1) - 2), slice(int(c0) + 3, int(c1) - 2))  # inside the left axes

    for frame, pose in ((frames[0], traj.path[0]), (frames[-1], traj.path[-1])):
        # The pad: light pixels (white, or pink under the chip), 200 um wide, centred on the origin.
        crop = frame[box].astype(int)
        light_r, light_c = np.nonzero(crop.min(axis=-1) > 200)
        px_per_um = (light_c.max() - light_c.min() + 1) / 200.0
        origin = np.array(
            [(light_c.min() + light_c.max()) / 2, (light_r.min() + light_r.max()) / 2]
        )
        origin += [box[1].start + 0.5, box[0].start + 0.5]
        # The chip outline: its bounding box is centred on the chip centre (a square).
        red = _chip_pixels(frame, box)
        centre_px = (
            np.array(
                [(red[:, 1].min() + red[:, 1].max()) / 2, (red[:, 0].min() + red[:, 0].max()) / 2]
            )
            + 0.5
        )
        x_um, y_um = (centre_px - origin) / px_per_um * [1, -1]  # image rows grow downwards, y up
        assert (x_um, y_um) == pytest.approx((pose[0], pose[1]), abs=2.5 / px_per_um)
        # ... and where the animation's own axes put it, within two pixels.
        assert centre_px == pytest.approx(anim.pixel_of(pose[0], pose[1])[0], abs=2.0)

    # Twist counter-clockwise: the top corner of a square turned by +6 deg lies right of its centre.
    red = _chip_pixels(frames[0], box)
    top = red[red[:, 0] <= red[:, 0].min() + 1]
    assert top[:, 1].mean() - (red[:, 1].min() + red[:, 1].max()) / 2 > 0.05 * np.ptp(red[:, 1])
    assert "step 0/" in anim.title_of(0) and anim.title_of(len(traj.path) - 1).endswith("aligned")
    assert anim.energy_title.startswith("energy E = Δγ · overlap area")  # the overlap model
    anim.close()


def test_gif_of_dynamics_titles_time_and_holds_the_last_frame(run, tmp_path):
    scene, _ = run
    t = np.linspace(0, 4e-3, 30)
    path = np.column_stack([np.linspace(30, 0, 30), np.zeros(30), np.linspace(5, 0, 30)])
    traj = Trajectory("overdamped", "aligned", path, np.linspace(-8e-10, -1e-9, 30), 29, 4e-3, t)
    out = tmp_path / "d.gif"
    assert write_trajectory_gif(scene, traj, out, max_frames=10, fps=10, hold_s=1.0) == 10
    meta = [iio.immeta(out, index=i) for i in (0, 1, 9)]
    assert [m["duration"] for m in meta] == [1000, 100, 1000]
    anim = TrajectoryAnimation(scene, traj, max_frames=10)
    assert "t = 4.00 ms" in anim.title_of(29)
    anim.close()


def test_the_energy_panel_of_a_meniscus_run_names_the_meniscus_not_the_overlap_area():
    # the energy of a meniscus run is the footprint's (docs/physics.md §3), not Δγ times the
    # overlap area: the panel's title says which, with the meniscus height
    from simulator.physics import Liquid

    scene = Scene.from_inputs(
        SQUARE,
        chip_size_um=200,
        effects=Effects(meniscus=True),
        liquid=Liquid(volume_nl=1.0, dispense="none"),
    )
    path = np.column_stack([np.linspace(30, 0, 5), np.zeros(5), np.zeros(5)])
    traj = Trajectory("greedy", "aligned", path, np.linspace(-8e-10, -1e-9, 5), 4)
    anim = TrajectoryAnimation(scene, traj, max_frames=5)
    try:
        h = scene.meniscus_height_um
        assert h is not None and h > 0
        assert (
            anim.energy_title
            == f"energy of the footprint, meniscus h = {h:.3g} µm (lower = better aligned)"
        )
    finally:
        anim.close()


def test_gif_of_a_run_that_never_moved_is_one_held_frame(run, tmp_path):
    # A chip released where it stops (aligned already, or on a flat part where its far pads
    # dried at release) has a path of one pose: one frame, held for hold_s. (Before, Pillow's
    # single-frame writer was handed the list of delays and the run failed, losing its JSON.)
    scene, _ = run
    traj = Trajectory("greedy", "aligned", np.zeros((1, 3)), np.array([-1e-9]), 0)
    out = tmp_path / "one.gif"
    assert write_trajectory_gif(scene, traj, out, hold_s=1.0) == 1
    assert len(iio.imread(out, index=None)) == 1
    assert iio.immeta(out, index=0)["duration"] == 1000


@pytest.mark.parametrize(
    "kwargs, message", [({"fps": 0}, "fps"), ({"max_frames": 1}, "max_frames")]
)
def test_gif_bad_arguments(run, tmp_path, kwargs, message):
    scene, traj = run
    with pytest.raises(InputError, match=message):
        write_trajectory_gif(scene, traj, tmp_path / "x.gif", **kwargs)
    with pytest.raises(InputError, match="must end in .gif"):
        write_trajectory_gif(scene, traj, tmp_path / "x.png")
    assert not list(tmp_path.iterdir())


# ---------------------------------------------------------------- landscape and force plots
def test_plot_landscape_and_forces_write_pngs(small_landscape, tmp_path):
    ls, pattern = small_landscape
    plot_landscape(ls, tmp_path / "l.png", pattern=pattern)
    plot_forces(ls, tmp_path / "f.png")
    plot_forces(ls, tmp_path / "g.png", through=(0, 30, 5), span_um=150)
    for name in ("l.png", "f.png", "g.png"):
        img = iio.imread(tmp_path / name)
        assert img.ndim == 3 and min(img.shape[:2]) > 300
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "f.png",
        "g.png",
        "l.png",
    ]  # no temporaries


def test_plots_of_an_untwisted_landscape(tmp_path):
    scene = Scene.from_inputs(SQUARE, chip_size_um=200, effects=Effects(twist=False))
    ls = build_landscape(scene, half_px=60)
    plot_landscape(ls, tmp_path / "l.png")
    plot_forces(ls, tmp_path / "f.png", span_um=50)
    assert iio.imread(tmp_path / "l.png").ndim == 3 and iio.imread(tmp_path / "f.png").ndim == 3


def test_plot_forces_bad_span(small_landscape, tmp_path):
    with pytest.raises(InputError, match="span_um"):
        plot_forces(small_landscape[0], tmp_path / "f.png", span_um=-1)
    assert not (tmp_path / "f.png").exists()


# ---------------------------------------------------------------- commands and feedback
def test_demo_writes_all_its_files(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["demo", "--out", str(out), "--quiet"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        ".selfalign-output.json",
        "demo.gif",
        "demo_energy.png",
        "report",
        "summary.txt",
        "trajectory.json",
    ]
    assert (out / "report" / "report.html").exists() and (out / "report" / "summary.json").exists()
    captured = capsys.readouterr()
    assert captured.err == ""  # --quiet: no progress bars or waiting messages
    assert (
        "aligned at (0.00 um, 0.00 um, 0.00 deg)" in captured.out
        and f"wrote {out / 'demo.gif'}" in captured.out
    )
    doc = json.loads((out / "trajectory.json").read_text())
    assert (
        doc["outcome"] == "aligned" and max(abs(p["twist_deg"]) for p in doc["path"]) > 15
    )  # escapes by twisting
    summary = (out / "summary.txt").read_text()
    assert "outcome      aligned" in summary and "plateau at (380.00 um" in summary
    # the files by their paths in --out (it named report.html, which is report/report.html)
    assert "report/report.html" in summary and " report.html" not in summary
    frames = iio.imread(out / "demo.gif", index=None)
    assert 100 <= len(frames) <= 120 and (out / "demo.gif").stat().st_size < 2e6


def test_demo_out_with_a_missing_parent(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "no" / "out")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "no").exists()


def test_simulate_gif(tmp_path, capsys):
    out = tmp_path / "s.gif"
    assert (
        main(
            [
                "simulate",
                "--pattern",
                SQUARE,
                "--chip-size",
                "200",
                "--start",
                "12,5,3",
                "--gif",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    captured = capsys.readouterr()
    assert f"wrote {out}" in captured.out and captured.err == ""
    assert len(iio.imread(out, index=None)) == 13  # 12 steps + start


@pytest.mark.parametrize("gif", ["/nonexistent/dir/t.gif", "t.png"])
def test_simulate_gif_bad_output_fails_before_any_work(gif, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc = main(
        [
            "simulate",
            "--pattern",
            SQUARE,
            "--chip-size",
            "200",
            "--start",
            "1,2,3",
            "--json",
            "t.json",
            "--gif",
            gif,
        ]
    )
    assert rc == 2
    err = capsys.readouterr().err
    assert "--gif" in err and len(err.strip().splitlines()) == 1
    assert not list(tmp_path.iterdir())


def test_announce_once_prints_on_stderr_once_and_respects_quiet(capsys):
    announce_once("test message 8e1f", quiet=True)
    announce_once("test message 8e1f")  # quiet calls do not use up the message
    announce_once("test message 8e1f")
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == "test message 8e1f\n"
