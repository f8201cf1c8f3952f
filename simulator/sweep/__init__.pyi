"""Types of ``simulator.sweep``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._axes import (
    AXES as AXES,
    HARD_MAX_POINTS as HARD_MAX_POINTS,
    Axis as Axis,
    AxisKind as AxisKind,
    axis_kinds as axis_kinds,
)
from ._cluster import (
    CONNECT_TIMEOUT_S as CONNECT_TIMEOUT_S,
    WORKER_MEMORY_MB as WORKER_MEMORY_MB,
    check_where as check_where,
    dask_client as dask_client,
    release_semaphores as release_semaphores,
    run_tasks as run_tasks,
    start_workers as start_workers,
    worker_cap as worker_cap,
)
from ._columns import (
    METRIC_LABELS as METRIC_LABELS,
    STATUS_COLUMNS as STATUS_COLUMNS,
    UNIT_TEXT as UNIT_TEXT,
    UNITS as UNITS,
    column_label as column_label,
    expected_columns as expected_columns,
    flatten as flatten,
    metric as metric,
)
from ._point import (
    assess_point as assess_point,
    design_params as design_params,
    point_bytes as point_bytes,
    point_critical_volume_nl as point_critical_volume_nl,
    point_geometry as point_geometry,
    point_scene as point_scene,
    price_point as price_point,
    run_point as run_point,
)
from ._run import (
    run_sweep as run_sweep,
)
from ._spec import (
    DEFAULT_MAX_POINTS as DEFAULT_MAX_POINTS,
    SweepSpec as SweepSpec,
    load_sweep as load_sweep,
    read_toml_file as read_toml_file,
)
from ._store import (
    ResultStore as ResultStore,
    kept_points as kept_points,
)
from ._task import (
    ID_COLUMNS as ID_COLUMNS,
    PointTask as PointTask,
    SweepPoint as SweepPoint,
)
