"""Optuna as the design search and the calibration run it: quiet (no per-trial INFO
lines, no experimental-feature warnings)."""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator
from typing import Any


@contextlib.contextmanager
def quiet_optuna() -> Iterator[Any]:
    """Optuna (the module) without its per-trial INFO lines and its experimental-feature
    warnings; its verbosity restored on leaving."""
    import optuna

    before = optuna.logging.get_verbosity()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            yield optuna
    finally:
        optuna.logging.set_verbosity(before)
