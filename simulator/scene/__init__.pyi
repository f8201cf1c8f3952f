"""Types of ``simulator.scene``'s names, loaded on first use (SPEC 1 lazy loading)."""

from ._accuracy import (
    DEFAULT_PRESET as DEFAULT_PRESET,
    KNOBS as KNOBS,
    PRESETS as PRESETS,
    Preset as Preset,
    apply_preset as apply_preset,
    feature_sets_pixel as feature_sets_pixel,
    feature_warning as feature_warning,
    smallest_feature_um as smallest_feature_um,
)
from ._build import (
    resampled_extent as resampled_extent,
)
from ._params import (
    CHIP_KEYS as CHIP_KEYS,
    FLAG_GROUPS as FLAG_GROUPS,
    LAYOUT_KEYS as LAYOUT_KEYS,
    SCENE_PARAMS as SCENE_PARAMS,
    SceneParam as SceneParam,
    merge_values as merge_values,
    sweep_places as sweep_places,
)
from ._parts import (
    Effects as Effects,
    TwistGrid as TwistGrid,
)
from ._scene import (
    Scene as Scene,
    chip_radius_of_gyration_px as chip_radius_of_gyration_px,
)
from ._schema import (
    SCHEMA as SCHEMA,
    read_scene_file as read_scene_file,
    validate_scene as validate_scene,
)
from ._schema_kinds import (
    ACCURACY_PRESETS as ACCURACY_PRESETS,
    DTYPES as DTYPES,
    DXF_UNITS as DXF_UNITS,
    MAX_ARRAY_ITEMS as MAX_ARRAY_ITEMS,
    MAX_DEPTH as MAX_DEPTH,
    MAX_SCENE_BYTES as MAX_SCENE_BYTES,
    Bool as Bool,
    Bounds as Bounds,
    FilePath as FilePath,
    Number as Number,
    Pose as Pose,
    Size as Size,
    number as number,
)
from ._twist_axis import (
    MAX_TWISTS as MAX_TWISTS,
    TwistAxis as TwistAxis,
    chip_symmetry as chip_symmetry,
)
