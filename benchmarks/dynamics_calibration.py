"""The dynamics against the source's video (not a test).

A 730 um SU-8 chip on the 730/100 um four-pad with 20 nl of water, finite meniscus (free
contact lines), 2 um/px, 1 deg twist steps. Two cases (``--case``):

* ``video`` (default): the video's bench case as a user runs it, ``--dispense pattern`` (the
  droplet on the pattern first, all four pads wet) with the pads' window ``--hysteresis
  10:35`` (friction, per pose) and the default damping, the sum of its terms with the line
  friction fitted to the video (``simulator.physics.LINE_FRICTION_PA_S``, docs/physics.md §4),
  inertial. The same as ``selfalign simulate --pattern patterns/library/four_pad_730_100.png
  --chip-size 730 --meniscus --volume 20 --resolution 2 --method inertial --start=500,5,1
  --dispense pattern --hysteresis 10:35`` start by start; the pads' planes are built once.
  Writes ``docs/images/dynamics_fourpad_730_100_video.png``.
* ``former``: the stateless meniscus without hysteresis and the former damping calibration
  given as the override (``simulator.physics.DAMPING_CALIBRATION``, 600), overdamped and
  inertial. Writes ``docs/images/dynamics_fourpad_730_100.png``.

Each draws x, y and twist against time for the 500 um x-bias of the video and the 380 um
starts, with the video's frame times (135, 290 and about 326 ms), and prints the table of
docs/physics.md §4 (video) or of the dynamics section of docs/guide/trajectories.md (former).

Usage: ``python benchmarks/dynamics_calibration.py [--case video|former] [--resolution UM]
[--out docs/images] [--no-inertial] [--smoke OUT]``

``--smoke OUT``: 20 um/px and 15 degree twists, the first start only, overdamped, at most
200 steps; the table goes to OUT and the figure beside it (OUT with .png), nothing into
docs/images.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from _smoke import add_smoke_arg, smoke_out  # noqa: E402

from patterns.library import library_path  # noqa: E402
from simulator import pyplot, save_figure
from simulator.landscape import build_footprint_planes, build_landscape  # noqa: E402
from simulator.motion import simulate  # noqa: E402
from simulator.physics import DAMPING_CALIBRATION, Liquid, Materials
from simulator.scene import (
    Effects,
    Scene,
    TwistGrid,
)

FRAMES_MS = (135.0, 290.0, 326.0)  # the source's video frames; aligned at about 326 ms
STARTS = [
    (500.0, 0.0, 0.0),
    (500.0, 0.0, 2.0),
    (500.0, 5.0, 0.0),
    (380.0, 0.0, 0.0),
    (380.0, 0.0, 1.0),
    (380.0, 5.0, 0.0),
]
#: The video case's starts: the former's and the bench command's (500, 5, 1).
VIDEO_STARTS = [*STARTS[:3], (500.0, 5.0, 1.0), *STARTS[3:]]
#: The pads' receding and advancing angles of the video case (deg): a receding angle low
#: enough that the far pads stay wet from 500 um, as the video shows (docs/guide/montecarlo.md).
VIDEO_WINDOW = (10.0, 35.0)


def align_time_s(traj, floor) -> float:
    """First time within 1 um of the floating floor (interpolated between steps; inf if never)."""
    p, t = traj.path, traj.t_s
    out = np.maximum(np.abs(p[:, 0]) - floor["x_um"][1], np.abs(p[:, 1]) - floor["y_um"][1]) - 1.0
    if not (out <= 0).any():
        return float("inf")
    k = int(np.argmax(out <= 0))
    return (
        0.0 if k == 0 else float(t[k - 1] + (t[k] - t[k - 1]) * out[k - 1] / (out[k - 1] - out[k]))
    )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "images"))
    ap.add_argument("--case", choices=("video", "former"), default="video")
    ap.add_argument("--resolution", type=float, default=2.0, help="um/px (default 2)")
    ap.add_argument("--no-inertial", action="store_true", help="overdamped runs only (faster)")
    add_smoke_arg(ap, "the table (and the figure beside it)")
    args = ap.parse_args(argv)
    smoke = smoke_out(ap, args.smoke)
    video = args.case == "video"
    starts = VIDEO_STARTS if video else STARTS
    starts, max_steps = (starts[:1], 200) if smoke else (starts, 20000)
    if smoke:
        args.no_inertial = True
    common = dict(
        chip_size_um=730,
        resolution_um=20.0 if smoke else args.resolution,
        **({"twist": TwistGrid(15.0)} if smoke else {}),
    )
    planes = None
    if video:
        scene = Scene.from_inputs(
            library_path("four_pad_730_100"),
            effects=Effects(meniscus=True, hysteresis=True),
            liquid=Liquid(volume_nl=20.0, dispense="pattern"),
            materials=Materials(
                pad_receding_deg=VIDEO_WINDOW[0], pad_advancing_deg=VIDEO_WINDOW[1]
            ),
            memory_budget_mb=9000,
            **common,
        )
        planes = build_footprint_planes(scene)  # once for every start
        floor = planes.landscape(np.ones(planes.n_pads, bool)).floor_range()
        print(
            f"line friction {scene.line_friction_Pa_s:g} Pa s (the default), pads {VIDEO_WINDOW[0]:g}:"
            f"{VIDEO_WINDOW[1]:g} deg; the chip floats within +-{floor['x_um'][1]:g} um"
        )
    else:
        scene = Scene.from_inputs(
            library_path("four_pad_730_100"),
            effects=Effects(meniscus=True),
            liquid=Liquid(volume_nl=20.0),
            damping_calibration=DAMPING_CALIBRATION,
            **common,
        )
        ls = build_landscape(scene)
        floor = ls.floor_range()
        print(
            f"damping calibration {scene.damping_calibration:g}; the chip floats within +-{floor['x_um'][1]:g} um"
        )
    methods = (
        ("overdamped",)
        if args.no_inertial
        else (("inertial",) if video else ("overdamped", "inertial"))
    )
    runs = {}
    table = [
        "| start (um, um, deg) | model | outcome | final (um, um, deg) | ends at (ms) | on the floor after (ms) | largest twist (deg, at ms, at x um) |",
        "|---|---|---|---|---:|---:|---|",
    ]
    print("\n".join(table))
    for start in starts:
        for method in methods:
            on = {"planes": planes} if video else {"landscape": ls}
            t = simulate(scene, start, method=method, max_steps=max_steps, **on)
            runs[start, method] = t
            ta = align_time_s(t, floor)
            k = int(np.argmax(np.abs(t.path[:, 2])))
            f = f"{t.final[0]:.1f}, {t.final[1]:.1f}, {t.final[2]:.2f}"
            ta_txt = "never" if not np.isfinite(ta) else f"{ta * 1e3:.0f}"
            table.append(
                f"| ({start[0]:g}, {start[1]:g}, {start[2]:g}) | {method} | {t.outcome} | ({f}) | "
                f"{t.t_s[-1] * 1e3:.0f} | {ta_txt} | "
                f"{t.path[k, 2]:.2f} at {t.t_s[k] * 1e3:.0f} ms, x {t.path[k, 0]:.0f} |"
            )
            print(table[-1], flush=True)

    plt = pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(9, 9), sharex=True)
    colours = dict(zip(VIDEO_STARTS, ("0.55", "0.3", "C7", "C4", "C0", "C3", "C2"), strict=True))
    main_method = methods[0]
    for start in starts:
        t = runs[start, main_method]
        label = f"({start[0]:g}, {start[1]:g} um, {start[2]:g} deg)"
        style = "--" if start[0] == 500.0 else "-"
        for ax, col in zip(axes, range(3), strict=True):
            ax.plot(t.t_s * 1e3, t.path[:, col], style, color=colours[start], label=label)
        if len(methods) > 1:
            ti = runs[start, "inertial"]
            axes[0].plot(ti.t_s * 1e3, ti.path[:, 0], ":", color="k", lw=0.8)
    if not video:
        axes[0].axhspan(382, 434, color="C1", alpha=0.15, label="flat part (no force)")
    for ax in axes:
        for f in FRAMES_MS:
            ax.axvline(f, color="C1", lw=1)
        ax.axvspan(200, 400, color="C2", alpha=0.06)
        ax.grid(alpha=0.3)
    axes[0].axhspan(
        -floor["x_um"][1], floor["x_um"][1], color="C2", alpha=0.2, label="floating floor (aligned)"
    )
    axes[0].set_ylabel("x (um)")
    axes[1].set_ylabel("y (um)")
    axes[2].set_ylabel("twist (deg)")
    axes[2].set_xlabel("time (ms); orange lines: the video's frames at 135, 290, 326 ms")
    axes[0].legend(fontsize=7, ncol=2, loc="upper right")
    axes[0].set_xlim(0, 800)
    fig.suptitle(
        (
            f"730 um chip, 730/100 um four-pad, 20 nl, meniscus, --dispense pattern, "
            f"--hysteresis {VIDEO_WINDOW[0]:g}:{VIDEO_WINDOW[1]:g}, {main_method}, line friction "
            f"{scene.line_friction_Pa_s:g} Pa s (default), {scene.um_per_px:g} um/px"
        )
        if video
        else (
            f"730 um chip, 730/100 um four-pad, 20 nl, meniscus, overdamped (dotted: inertial x), "
            f"damping x{scene.damping_calibration:g}"
        ),
        fontsize=9,
    )
    fig.tight_layout()
    if smoke:
        smoke.write_text("\n".join(table) + "\n")
        save_figure(fig, smoke.with_suffix(".png"), dpi=40)
        print(f"wrote {smoke} and {smoke.with_suffix('.png')} (smoke run)")
        return
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "dynamics_fourpad_730_100" + ("_video" if video else "") + ".png"
    save_figure(fig, out / name, dpi=80)
    print(f"wrote {out / name}")


if __name__ == "__main__":
    main()
