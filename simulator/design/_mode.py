"""Which mode a design file asks for: ``[search]`` (parameters) or ``[freeform]`` (pixels)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from foundation import InputError

__all__ = ["design_mode"]

MODES = ("search", "freeform")


def design_mode(doc: dict[str, Any], where: str | Path = "design file") -> str:
    """``"search"`` or ``"freeform"``: the one of the two tables ``doc`` has (InputError otherwise)."""
    have = [m for m in MODES if m in doc]
    if len(have) != 1:
        raise InputError(
            f"{where}: a design file has exactly one of the tables [search] (a parametric search "
            f"over a design's axes) or [freeform] (a pattern optimised pixel by pixel); "
            + ("it has both" if have else "it has neither")
        )
    return have[0]
