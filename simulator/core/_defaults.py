"""Defaults and limits the command line quotes, in a module that imports nothing (but os).

The command modules (:mod:`simulator.commands`) register their flags with these values
without importing JAX, the landscape engine or matplotlib, so that ``selfalign --help``
and ``selfalign pattern`` start at once; the library reads them from here too (one import
path each). ``tests/test_cli_usage.py`` checks that every default a help text quotes is the
code's.
"""

import os

#: Environment variable: how many threads this process's FFTs and batch runs may use.
THREADS_ENV = "SELFALIGN_THREADS"


def threads() -> int:
    """Threads for the correlator's FFTs and for Monte Carlo chunks: ``SELFALIGN_THREADS``
    when set (a whole number >= 1; a sweep's Dask workers set it to 1), else the CPU count."""
    v = os.environ.get(THREADS_ENV, "").strip()
    if not v:
        return os.cpu_count() or 1
    if not v.isdigit() or int(v) < 1:
        from foundation import InputError

        raise InputError(
            f"{THREADS_ENV}={v!r} must be a whole number of threads >= 1; set it to e.g. 1, or unset it"
        )
    return int(v)


#: Trajectory methods (:func:`simulator.motion.simulate`).
METHODS = ("greedy", "gradient", "overdamped", "inertial")
#: Largest |twist| of a start or of the twist grid (degrees: ten turns), as the scene's
#: schema, :class:`simulator.scene.TwistGrid` and the start checks of a run and a batch take it.
MAX_TWIST_DEG = 3600
#: Most starts of one Monte Carlo batch (``--random``, a start grid, a table of poses).
MAX_STARTS = 10**8
#: The Monte Carlo placements' distributions (:func:`simulator.batch.random_starts`).
DISTRIBUTIONS = ("normal", "uniform")
#: Default bound on moves or solver steps of one run.
DEFAULT_MAX_STEPS = 5000
#: Largest max_steps: step counters are int32.
MAX_STEPS_LIMIT = 2**31 - 2
#: The methods a Monte Carlo batch runs (:func:`simulator.batch.run_batch`): every
#: trajectory method, the dynamics (overdamped, inertial) included.
BATCH_METHODS = METHODS
#: The outcomes a trajectory reports (:class:`simulator.motion.Trajectory`), in the order of
#: the outcome codes batches store (:class:`simulator.batch.BatchResult`).
OUTCOMES = ("aligned", "plateau", "local_minimum", "no_contact", "max_steps")
#: The time-resolved methods (they need :class:`simulator.motion.DynamicsParams`).
DYNAMIC_METHODS = ("overdamped", "inertial")
#: Starts per compiled batch of the steppers (measured best on a 2-core CPU, see docs/benchmarks.md).
DEFAULT_CHUNK = 2048
#: Starts per compiled batch of the dynamics (a vmapped solver runs until its slowest
#: lane stops, and the bar advances per chunk; see docs/guide/montecarlo.md).
DEFAULT_DYNAMICS_CHUNK = 64
#: The most lanes a footprint batch's group runs at once (``--dispense pattern`` or
#: ``chip``: a larger chunk is cut to it, a smaller group padded to it): every group,
#: large or small, in one compiled shape. On the benchmark (``benchmarks/footprint.py
#: --batch``: groups of 1,976, 17, 14, 8, 7 and 1 lanes) the lanes took 1.8 s in chunks of
#: 128 against 2.4 s in one chunk of up to 2,048 with the small groups in chunks of 32 (a
#: second compile, 0.4 s), and 2.0 s in chunks of 64 or 256, 2.2 s of 512; the ends are
#: the same (lanes are independent).
FOOTPRINT_CHUNK = 128
#: Largest chunk of starts compiled together.
MAX_CHUNK = 2**20
#: ``evaluate``: landscapes above this (MB) are built at a coarser resolution unless the user chose one.
AUTO_LANDSCAPE_MB = 320.0
