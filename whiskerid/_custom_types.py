"""Shape-named array aliases used across whiskerid (jaxtyping)."""

from jaxtyping import Array, ArrayLike, Float, Int

#: A scalar float array (0-d) or anything convertible to one.
Scalar = Float[Array, ""]
ScalarLike = float | Float[ArrayLike, ""]
#: One value per vibration mode.
PerMode = Float[Array, " modes"]
#: One value per sample time.
Times = Float[Array, " samples"]
Samples = Float[Array, " samples"]
Codes = Int[Array, " samples"]
#: Modal coordinates over time.
ModalSeries = Float[Array, "samples modes"]

__all__ = ["Codes", "ModalSeries", "PerMode", "Samples", "Scalar", "ScalarLike", "Times"]
