"""Write ``design_freeform_rfid_chip.png``: the chip of ``design_freeform_rfid.toml``.

A 400 x 400 um RFID-like die whose wettable underside is its four 120 um contact pads
(the four-pad layout of side 400 um and gap 160 um, docs/physics.md §6.1) and a 64 x 64 um
index mark centred at (0, 140) um, in the gap between the two upper contacts. The mark
makes the chip asymmetric under every turn: without it the four contacts repeat under a
90-degree turn and no pattern could tell the orientations apart. Written at 4 um/px (the
design's pixel size), 16-bit with its scale.

Usage: ``python examples/make_freeform_rfid_chip.py`` (from the repository root).
"""

from pathlib import Path

from shapely.geometry import box

from patterns import write_mask
from patterns.geometry import four_pad, mask_from_geometry

HERE = Path(__file__).resolve().parent

contacts = four_pad(400, 160)
mark = box(-32, 108, 32, 172)
chip = contacts.union(mark)
mask = mask_from_geometry(
    chip,
    4.0,
    shape=(100, 100),
    params={
        "design": "rfid-chip",
        "contacts": "four-pad 400/160 um",
        "index_mark_um": [0, 140, 64],
    },
)
write_mask(HERE / "design_freeform_rfid_chip.png", mask)
print(f"wrote {HERE / 'design_freeform_rfid_chip.png'}: {mask.area_um2:,.0f} um^2 wettable")
