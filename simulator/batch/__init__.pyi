"""Types of ``simulator.batch``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._assessment import (
    ABSENT as ABSENT,
    EFFECTS as EFFECTS,
    Absent as Absent,
    AssessedMinimum as AssessedMinimum,
    Assessment as Assessment,
    AssessmentSettings as AssessmentSettings,
    AxisErrors as AxisErrors,
    CaptureCentre as CaptureCentre,
    CaptureGrid as CaptureGrid,
    CaptureSummary as CaptureSummary,
    CentreOffset as CentreOffset,
    ContactLineReach as ContactLineReach,
    ErrorLimit as ErrorLimit,
    ErrorStats as ErrorStats,
    FloatingRange as FloatingRange,
    MaxBias as MaxBias,
    MeniscusSummary as MeniscusSummary,
    PlacementSigma as PlacementSigma,
    Plateaus as Plateaus,
    Protocols as Protocols,
    ProtocolSummary as ProtocolSummary,
    RestoringForce as RestoringForce,
    RestoringTorque as RestoringTorque,
    Stiffness as Stiffness,
    TimeStats as TimeStats,
    TwistErrors as TwistErrors,
    YieldSummary as YieldSummary,
    summary_shape as summary_shape,
)
from ._evaluate import (
    NOISE_FRACTION as NOISE_FRACTION,
    NOISE_TWIST_DEG as NOISE_TWIST_DEG,
    YIELD_STARTS as YIELD_STARTS,
    assess as assess,
    auto_resolution as auto_resolution,
    chip_size as chip_size,
    evaluate as evaluate,
)
from ._montecarlo import (
    run_batch as run_batch,
    run_realizations as run_realizations,
)
from ._pricing import (
    DYNAMICS_BYTES_PER_LANE as DYNAMICS_BYTES_PER_LANE,
    price_dynamics_lanes as price_dynamics_lanes,
)
from ._starts import (
    StartGrid as StartGrid,
    random_starts as random_starts,
)
from ._stats import (
    BatchResult as BatchResult,
    capture_map as capture_map,
    max_bias as max_bias,
    summarize as summarize,
    time_histogram as time_histogram,
    time_stats as time_stats,
    twist_error as twist_error,
)
