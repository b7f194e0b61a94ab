"""What an assumed modulus adds to the 1σ of what is derived from it (``--pin material``).

With ``pin = "material"`` the bending stiffness is the record's, ``EI = G_w J_w`` (a coil) or
``E I`` (a beam), and the vibrations give ``κ = EI/(ρa)``; so ``ρa = EI/κ`` and a coil's
``C = ρa/(ρ_w a)``. Both scale with the assumed modulus: a modulus known to a relative 1σ
``t`` adds ``t·ρa`` and ``t·C`` (fully correlated) to their 1σ, in quadrature with the
data's. Treating the modulus as exact gave a 1σ of 0.0007 for a C that was 46 % off.

The default tolerance, :data:`MODULUS_TOLERANCE` = 20 %, is the spread of the shear moduli of
common spring wires (music wire about 79 GPa, stainless 302 about 69 GPa, phosphor bronze
about 41 GPa) within a family and temper, together with the equivalent-beam convention
``EI := G_w J_w`` for a coil, which is itself an approximation of a helix's bending
stiffness. Give a smaller one (``--modulus-tolerance``) for a material that is known, e.g. a
few percent for a handbook metal beam.
"""

import numpy as np

from .._data import CalibrationError

#: Default relative 1σ of the record's modulus under ``--pin material``.
MODULUS_TOLERANCE = 0.20
#: Quantities proportional to the assumed modulus under ``--pin material``.
SCALES_WITH_MODULUS = ("rho_a", "C")


def modulus_covariance(names, values, tolerance: float) -> np.ndarray:
    """The covariance a modulus known to relative 1σ ``tolerance`` adds to the reported
    quantities ``names`` (at ``values``) of a ``--pin material`` fit."""
    v = np.array(
        [float(x) if n in SCALES_WITH_MODULUS else 0.0 for n, x in zip(names, values, strict=True)]
    )
    return tolerance**2 * np.outer(v, v)


def check_tolerance(tolerance: float) -> float:
    """``tolerance`` if it is a relative 1σ in ``[0, 1)``.

    Raises:
        CalibrationError: Anything else.
    """
    if not (np.isfinite(tolerance) and 0 <= tolerance < 1):
        raise CalibrationError(
            f"modulus tolerance {tolerance!r} must be a relative 1-sigma between 0 and 1 "
            "(0.2 for 20 %)"
        )
    return float(tolerance)
