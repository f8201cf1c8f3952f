"""The ground floor both ``patterns`` and ``simulator`` stand on: the project's plumbing.

* errors: :class:`InputError` (a one-line error a user can fix, exit code 2) and the
  argument checks that raise it (:func:`positive`, :func:`require`,
  :func:`require_regular_file`);
* safe outputs: files and directories written whole or not at all, never over what the
  user did not ask to replace (:func:`atomic_output`, :func:`output_directory`, the
  ``--force`` checks);
* resources: every array a user's input sizes is priced against the memory budget before
  it is allocated (:func:`require_fits`, :func:`price_raster`, :func:`default_budget_mb`);
* hold points: where a test holds a process at a known stage instead of racing its clock
  (:func:`hold`, ``SELFALIGN_HOLD_AT``);
* finiteness: :func:`require_finite` refuses NaN and infinities by name;
* progress: the lines and bars that explain a wait, on stderr (:func:`progress_bar`,
  :func:`wait_line`, :func:`announce`).

It imports nothing from ``patterns`` or ``simulator`` (docs/architecture.md).
"""

import lazy_loader as lazy

# The names are those of __init__.pyi, each loaded from its module on first use.
__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
