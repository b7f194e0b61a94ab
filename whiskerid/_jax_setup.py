"""JAX settings every model needs, applied once before the first array is made.

The modal sums near the clamp and the eigenvalue bisection lose their accuracy in float32, so
float64 (``jax_enable_x64``) is switched on by every sub-package that computes with JAX.
"""

import jax

jax.config.update("jax_enable_x64", True)
