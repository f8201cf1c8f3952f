"""Write examples/site.gds: a four-pad alignment site as a pattern designer draws it.

    python examples/make_site_gds.py [OUT.gds]

* cell ``PAD``: one 180 x 180 um pad on layer 1/0, drawn in the first quadrant of the
  site, 20 um from both axes (half of the 40 um gap);
* cell ``SITE`` (the top cell): four references of ``PAD``, turned by 0, 90, 180 and 270
  degrees about the site centre, at layout position (1500, 800) um; the 400 x 400 um chip
  outline on layer 2/0, centred on the site; two alignment crosses on layer 3/0 (paths)
  and a text label, which selfalign ignores.

User unit 1 um, database unit 1 nm. Evaluate it with

    selfalign evaluate examples/site.gds --layer 1/0 --chip-layer 2/0 --out rep/
"""

from __future__ import annotations

import datetime
import math
import sys
from pathlib import Path

import gdstk

SITE_XY = (1500.0, 800.0)
PAD_UM, GAP_UM, CHIP_UM = 180.0, 40.0, 400.0


def build() -> gdstk.Library:
    lib = gdstk.Library("SITE_EXAMPLE", unit=1e-6, precision=1e-9)
    pad = lib.new_cell("PAD")
    g = GAP_UM / 2
    pad.add(gdstk.rectangle((g, g), (g + PAD_UM, g + PAD_UM), layer=1, datatype=0))
    site = lib.new_cell("SITE")
    for k in range(4):
        site.add(gdstk.Reference(pad, SITE_XY, rotation=k * math.pi / 2))
    x, y = SITE_XY
    h = CHIP_UM / 2
    site.add(gdstk.rectangle((x - h, y - h), (x + h, y + h), layer=2, datatype=0))
    for cx in (x - 600, x + 600):  # alignment crosses, 100 um arms, 10 um wide
        site.add(gdstk.FlexPath([(cx - 50, y), (cx + 50, y)], 10, layer=3, datatype=0))
        site.add(gdstk.FlexPath([(cx, y - 50), (cx, y + 50)], 10, layer=3, datatype=0))
    site.add(gdstk.Label("site A: 4 x 180 um pads, 40 um gap", (x - h, y + h + 20), layer=10))
    return lib


def main(out: str = str(Path(__file__).with_name("site.gds"))) -> None:
    build().write_gds(out, timestamp=datetime.datetime(2000, 1, 1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main(*sys.argv[1:])
