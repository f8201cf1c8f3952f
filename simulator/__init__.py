"""selfalign simulator: energy landscapes, trajectories and yields of capillary self-alignment.

JAX runs with 64-bit types enabled (``jax_enable_x64``) so that a float64 landscape
stays float64 inside the steppers; float32 landscapes still compute in float32.
"""

import jax

jax.config.update("jax_enable_x64", True)
