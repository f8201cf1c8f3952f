"""Units and reference constants, defined once for the whole package.

Owns the SI factors of selfalign's units (:data:`UM2`: m^2 per um^2, the factor that
turns an overlap in um^2 times ``Delta_gamma`` into joules; :data:`UM`: m per um;
:data:`UM3_PER_NL`: um^3 per nl) and the constants of the default liquid and chip body
(water's surface tension, viscosity and density; SU-8's density). Imports nothing, so
:mod:`simulator.physics` and :mod:`simulator.physics` both build on it; every name
is importable from :mod:`simulator.physics` as before.
"""

#: m^2 per um^2: multiply an area in um^2 (an overlap in px^2 at 1 um/px) by
#: ``Delta_gamma * UM2`` to get joules.
UM2 = 1e-12
UM = 1e-6
UM3_PER_NL = 1e6

WATER_SURFACE_TENSION_N_M = 0.0728
WATER_VISCOSITY_PA_S = 1.0e-3
WATER_DENSITY_KG_M3 = 998.0
SU8_DENSITY_KG_M3 = 1200.0
