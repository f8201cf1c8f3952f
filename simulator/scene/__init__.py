"""What to simulate: the :class:`Scene` (chip, pattern, liquid, materials, effects, twist grid),
its parts, building it from inputs or a scene TOML file, the schema those files follow, and the
accuracy presets.
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
