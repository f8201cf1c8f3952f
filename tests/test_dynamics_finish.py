"""The dynamics finish on the 730/100 four-pad at 20 nl (issue: the inertial solver gave up).

The calibrated water parameters damp the chip heavily (the velocity relaxes in m / c, a
few microseconds, while it creeps a grid step in milliseconds), so inertial runs use the
IMEX solver (simulator.motion.stiff_solver). Before it, the implicit solver's Newton
iteration stalled on the float32-quantized force and cut its steps to nothing in the
middle of a pad: from (500, 0, 0) the overlap scene ran out of its 5000 solver steps at
x = 471 um. And a chip approaching the wall profile's floating floor crept on Phi's
rounded edge until its second was up (simulator.motion._near_rest stops it within
a twentieth of a grid step of its rest point).

10 um/px and twist off keep this fast (one compilation per scene): the starts lie on the
pattern's mirror line y = 0 at twist 0, where the y force and the torque vanish by
symmetry, so a twist axis would not move (it stays exactly 0 in the full runs).
"""

import jax.numpy as jnp
import numpy as np
import pytest

from patterns.library import library_path
from simulator.cli import build_parser
from simulator.commands._request import SceneRequest
from simulator.commands._scene import scene_from_args
from simulator.core import DEFAULT_MAX_STEPS
from simulator.landscape import build_landscape
from simulator.motion import (
    field_and_grid,
    potential_and_gradient,
    radius_of_gyration_px,
    reference_gradient,
    simulate,
)
from simulator.motion._dynamics_ode import _hessian

# One xdist group for the whole module (make test: pytest -n 2 --dist loadgroup): its tests
# share scenes whose steppers take seconds to compile; on one worker each compiles once.
pytestmark = pytest.mark.xdist_group("dynamics_finish")


def four_pad_scene(meniscus: bool):
    argv = [
        "simulate",
        "--pattern",
        str(library_path("four_pad_730_100")),
        "--chip-size",
        "730",
        "--volume",
        "20",
        "--resolution",
        "10",
        "--no-twist",
    ] + (["--meniscus"] if meniscus else [])
    return scene_from_args(SceneRequest.from_args(build_parser().parse_args(argv)))


@pytest.fixture(scope="module", params=[False, True], ids=["overlap", "meniscus"])
def scene(request):
    return four_pad_scene(request.param)


def test_inertial_run_from_500_um_finishes_within_the_default_budget(scene):
    t = simulate(scene, (500.0, 0.0, 0.0), method="inertial")
    # A stated stop: the flat part of the landscape (the overlap's plateau at 400-410 um,
    # the meniscus's flat part at 382-434 um), or alignment; never out of steps or time.
    assert t.outcome in ("plateau", "aligned"), t.outcome
    assert t.steps < DEFAULT_MAX_STEPS // 10  # measured 138 (overlap), 208 (meniscus)
    assert t.time_s is not None
    assert t.time_s < 1.0  # the default t_max_s
    assert (
        380.0 <= t.final[0] <= 440.0 and abs(t.final[1]) < 0.05 and t.final[2] == 0.0
    )  # y: round-off only
    assert np.all(np.diff(t.path[:, 0]) <= 1e-3)  # it moves towards the centre all the way


def test_inertial_run_from_300_um_aligns(scene):
    t = simulate(scene, (300.0, 0.0, 0.0), method="inertial")
    assert t.outcome == "aligned"
    assert t.steps < DEFAULT_MAX_STEPS // 10  # measured 107 (overlap), 205 (meniscus)
    # the overlap aligns at its cusp; the meniscus floats within its floor (about +-20 um)
    assert abs(t.final[0]) <= (25.0 if scene.effects.meniscus else 1.0)


def test_phi_hessian_is_the_derivative_of_its_gradient():
    scene = four_pad_scene(True)
    ls = build_landscape(scene)
    field, grid = field_and_grid(ls, radius_of_gyration_px(scene))
    rng = np.random.default_rng(1)
    for x in (15.0, 17.5, 300.0, 425.0):  # the floor's rounded edge, a pad, the flat part's edge
        q = jnp.asarray(grid.to_index([x, 0.0, 0.0]), jnp.float32) + jnp.asarray(
            [0.0, *rng.uniform(0.05, 0.95, 2)], jnp.float32
        )
        h = np.asarray(_hessian(field, grid, q))
        for k in (1, 2):
            e = jnp.zeros(3, jnp.float32).at[k].set(1e-2)
            fd = (
                np.asarray(potential_and_gradient(field, grid, q + e)[1])
                - np.asarray(potential_and_gradient(field, grid, q - e)[1])
            ) / 2e-2
            np.testing.assert_allclose(
                h[k, 1:], fd[1:], rtol=1e-2, atol=1e-3 * float(reference_gradient(field, grid))
            )
    # on a grid line (a node of the start) the one-sided value, not autodiff's branch
    q = jnp.asarray(grid.to_index([300.0, 0.0, 0.0]), jnp.float32)
    assert abs(float(_hessian(field, grid, q)[2, 2])) < 1e-3 * float(
        reference_gradient(field, grid)
    )


def test_with_twists_the_run_that_creeps_on_the_plateau_until_its_time_is_up_is_a_plateau():
    # With a twist axis the potential averages the landscape over +-1 twist step, so the
    # overlap plateau is exactly flat only at twist 0 and the chip creeps along it until
    # the simulated second is up (measured at 2, 4 and 5 um/px: it ends within 386-400 um).
    # That is a stop on a plateau, reported as one, not as running out of steps.
    argv = [
        "simulate",
        "--pattern",
        str(library_path("four_pad_730_100")),
        "--chip-size",
        "730",
        "--volume",
        "20",
        "--resolution",
        "5",
        "--twist-step",
        "2",
        "--damping-calibration",  # the former fit: the chip creeps (the damping's terms let it run)
        "600",
    ]
    sc = scene_from_args(SceneRequest.from_args(build_parser().parse_args(argv)))
    t = simulate(sc, (500.0, 0.0, 0.0), method="inertial")
    assert t.steps < DEFAULT_MAX_STEPS  # not out of steps: out of time
    assert t.time_s == pytest.approx(1.0)  # the default t_max_s
    assert (
        t.outcome == "plateau" and 315.0 <= t.final[0] <= 415.0
    )  # on the overlap model's flat part (p to p + g)
