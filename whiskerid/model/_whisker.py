"""Whisker descriptions: geometry and material in, equivalent-beam parameters out.

Two structures are supported:

* :class:`CoilSpring`, the paper's whisker, modelled as an equivalent cantilever beam
  (its Section III): wire area ``a = π r_w²``, bending stiffness ``EI := G_w J_w`` with
  ``J_w = π r_w⁴/4``, pitch ``p = l/n``, wire length ``l_w = n sqrt((2πr)² + p²)``,
  coil correction ``C = l_w/(n p)`` and line density ``ρa = C ρ_w a``.
* :class:`UniformBeam`, a plain prismatic beam with a rectangular or circular section:
  ``EI = E I`` and ``ρa = ρ A``.

Either turns into a :class:`Whisker`, the pytree of physical parameters that every model
takes (``EI``, ``ρa``, per-mode ``ζ``, tip mass, sensor position, length).
"""

import math
from dataclasses import dataclass
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import PerMode, Scalar
from ._modes import cantilever_roots


def _scalar(x) -> jax.Array:
    return jnp.asarray(x, dtype=float)


def _vector(x) -> jax.Array:
    return jnp.atleast_1d(jnp.asarray(x, dtype=float))


def _is_concrete(*xs) -> bool:
    return not any(isinstance(x, jax.core.Tracer) for x in xs)


class Whisker(eqx.Module):
    """Physical parameters of an equivalent cantilever (a pytree; all SI units).

    Attributes:
        length_m: Free length ``l`` (m).
        EI: Bending stiffness (N·m²).
        rho_a: Line density ``ρa`` (kg/m).
        zeta: Modal damping ratio per mode (dimensionless, ``0 ≤ ζ < 1``); its length is the
            number of modes the models use.
        tip_mass_kg: Point mass at the free end (kg).
        sensor_x_m: Where the sensor reads the beam, measured from the clamp (m).
    """

    length_m: Scalar = eqx.field(converter=_scalar)
    EI: Scalar = eqx.field(converter=_scalar)
    rho_a: Scalar = eqx.field(converter=_scalar)
    zeta: PerMode = eqx.field(converter=_vector)
    tip_mass_kg: Scalar = eqx.field(converter=_scalar, default=0.0)
    sensor_x_m: Scalar = eqx.field(converter=_scalar, default=0.005)

    def __check_init__(self):
        for name in ("length_m", "EI", "rho_a", "tip_mass_kg", "sensor_x_m"):
            if jnp.ndim(getattr(self, name)) != 0:
                raise ValueError(
                    f"Whisker.{name} must be a scalar, got shape {jnp.shape(getattr(self, name))}"
                )
        if self.zeta.ndim != 1 or self.zeta.shape[0] < 1:
            raise ValueError(f"Whisker.zeta must have shape (modes,), got {self.zeta.shape}")
        if _is_concrete(*(getattr(self, name) for name in _VALUE_FIELDS)):
            _check_values(self)

    @property
    def n_modes(self) -> int:
        """Number of modes (static: the length of ``zeta``)."""
        return self.zeta.shape[0]

    @property
    def kappa(self) -> Scalar:
        """``κ = EI/(ρa)`` (m⁴/s²): the only stiffness combination vibrations reveal alone."""
        return self.EI / self.rho_a

    @property
    def mu(self) -> Scalar:
        """Tip-mass ratio ``μ = M_t/(ρ a l)``."""
        return self.tip_mass_kg / (self.rho_a * self.length_m)

    @property
    def beta(self) -> PerMode:
        """Dimensionless eigenvalues ``β_i`` (tip mass included)."""
        return cantilever_roots(self.mu, self.n_modes)

    @property
    def omega_rad_s(self) -> PerMode:
        """Undamped natural angular frequencies ``ω_i = β_i² sqrt(κ)/l²`` (rad/s)."""
        return _omega(self.beta, self.kappa, self.length_m)

    @property
    def natural_frequencies_hz(self) -> PerMode:
        """Undamped natural frequencies ``f_i = ω_i/(2π)`` (Hz)."""
        return self.omega_rad_s / (2 * jnp.pi)

    @property
    def damped_frequencies_hz(self) -> PerMode:
        """Damped natural frequencies ``f_i sqrt(1 − ζ_i²)`` (Hz)."""
        return self.natural_frequencies_hz * jnp.sqrt(1.0 - self.zeta**2)

    def with_modes(self, n_modes: int) -> "Whisker":
        """The same whisker with ``n_modes`` modes (extra modes take the last mode's ζ)."""
        zeta = jnp.concatenate([self.zeta, jnp.full(max(0, n_modes - self.n_modes), self.zeta[-1])])
        return eqx.tree_at(lambda w: w.zeta, self, zeta[:n_modes])


@jax.jit  # one program when the whisker is concrete, not one per operation
def _omega(beta, kappa, length_m):
    return beta**2 * jnp.sqrt(kappa) / length_m**2


def _check_values(w: Whisker) -> None:
    """Refuse non-physical values, naming the field.

    The values are concrete here, so NumPy reads them: JAX operations would each be compiled,
    and a whisker is built for every fit, simulation and plot.
    """
    v = {name: np.asarray(getattr(w, name), dtype=float) for name in _VALUE_FIELDS}
    checks = [
        ("length_m", v["length_m"] > 0, "must be positive"),
        ("EI", v["EI"] > 0, "must be positive"),
        ("rho_a", v["rho_a"] > 0, "must be positive"),
        ("tip_mass_kg", v["tip_mass_kg"] >= 0, "must be zero or positive"),
        ("zeta", np.all((v["zeta"] >= 0) & (v["zeta"] < 1)), "must satisfy 0 <= zeta < 1"),
        (
            "sensor_x_m",
            0 <= v["sensor_x_m"] <= v["length_m"],
            f"must lie on the beam, between 0 and length_m = {float(v['length_m'])} m",
        ),
    ]
    for name, ok, why in checks:
        if not ok or not np.all(np.isfinite(v[name])):
            raise ValueError(f"{name} = {_show(v[name])} {why}")


_VALUE_FIELDS = ("length_m", "EI", "rho_a", "tip_mass_kg", "zeta", "sensor_x_m")


def _show(x: np.ndarray) -> str:
    return repr(float(x)) if x.ndim == 0 else repr([float(v) for v in x])


@dataclass(frozen=True)
class CoilSpring:
    """A helical spring treated as an equivalent beam (the paper's Section III).

    Attributes:
        length_m: Free (axial) length ``l`` (m).
        wire_radius_m: Wire radius ``r_w`` (m).
        mean_coil_radius_m: Mean coil radius ``r`` (m), half of (outside + inside)/2 diameter.
        n_coils: Number of active coils ``n``.
        wire_density_kg_m3: Wire material density ``ρ_w`` (kg/m³).
        shear_modulus_pa: Wire shear modulus ``G_w`` (Pa); ``EI := G_w J_w``.
    """

    length_m: float
    wire_radius_m: float
    mean_coil_radius_m: float
    n_coils: float
    wire_density_kg_m3: float
    shear_modulus_pa: float

    kind: Literal["coil"] = "coil"

    def __post_init__(self):
        for name in (
            "length_m",
            "wire_radius_m",
            "mean_coil_radius_m",
            "n_coils",
            "wire_density_kg_m3",
            "shear_modulus_pa",
        ):
            _require_positive(name, getattr(self, name))

    @property
    def wire_area_m2(self) -> float:
        """Wire cross-section ``a = π r_w²`` (m²)."""
        return math.pi * self.wire_radius_m**2

    @property
    def polar_moment_m4(self) -> float:
        """``J_w = π r_w⁴ / 4`` as printed in the paper (m⁴)."""
        return math.pi * self.wire_radius_m**4 / 4

    @property
    def pitch_m(self) -> float:
        """``p = l/n`` (m)."""
        return self.length_m / self.n_coils

    @property
    def wire_length_m(self) -> float:
        """``l_w = n sqrt((2πr)² + p²)`` (m)."""
        return self.n_coils * math.hypot(2 * math.pi * self.mean_coil_radius_m, self.pitch_m)

    @property
    def coil_factor(self) -> float:
        """Coil correction ``C = l_w/(n p)`` (dimensionless)."""
        return self.wire_length_m / (self.n_coils * self.pitch_m)

    @property
    def EI(self) -> float:
        """Equivalent bending stiffness ``G_w J_w`` (N·m²)."""
        return self.shear_modulus_pa * self.polar_moment_m4

    @property
    def rho_a(self) -> float:
        """Equivalent line density ``C ρ_w a`` (kg/m)."""
        return self.coil_factor * self.wire_density_kg_m3 * self.wire_area_m2


@dataclass(frozen=True)
class UniformBeam:
    """A prismatic beam of one material.

    Attributes:
        length_m: Free length (m).
        youngs_modulus_pa: Young's modulus ``E`` (Pa).
        density_kg_m3: Material density ``ρ`` (kg/m³).
        section: ``"rectangular"`` (``width_m`` × ``thickness_m``, bending about the width)
            or ``"circular"`` (``diameter_m``).
    """

    length_m: float
    youngs_modulus_pa: float
    density_kg_m3: float
    section: Literal["rectangular", "circular"] = "rectangular"
    width_m: float | None = None
    thickness_m: float | None = None
    diameter_m: float | None = None

    kind: Literal["beam"] = "beam"

    def __post_init__(self):
        for name in ("length_m", "youngs_modulus_pa", "density_kg_m3"):
            _require_positive(name, getattr(self, name))
        needed = {"rectangular": ("width_m", "thickness_m"), "circular": ("diameter_m",)}
        if self.section not in needed:
            raise ValueError(f"section = {self.section!r} must be 'rectangular' or 'circular'")
        for name in needed[self.section]:
            _require_positive(name, getattr(self, name))

    @property
    def area_m2(self) -> float:
        """Cross-section area (m²)."""
        if self.section == "rectangular":
            return self.width_m * self.thickness_m
        return math.pi * self.diameter_m**2 / 4

    @property
    def second_moment_m4(self) -> float:
        """Second moment of area about the bending axis (m⁴)."""
        if self.section == "rectangular":
            return self.width_m * self.thickness_m**3 / 12
        return math.pi * self.diameter_m**4 / 64

    @property
    def EI(self) -> float:
        """Bending stiffness ``E I`` (N·m²)."""
        return self.youngs_modulus_pa * self.second_moment_m4

    @property
    def rho_a(self) -> float:
        """Line density ``ρ A`` (kg/m)."""
        return self.density_kg_m3 * self.area_m2


Structure = CoilSpring | UniformBeam


def _require_positive(name: str, value) -> None:
    if value is None:
        raise ValueError(f"{name} is missing")
    if not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} = {value!r} must be a positive finite number")


def whisker_from_structure(
    structure: Structure,
    *,
    zeta: float | PerMode = 0.04,
    n_modes: int = 5,
    tip_mass_kg: float = 0.0,
    sensor_x_m: float = 0.005,
) -> Whisker:
    """Build the :class:`Whisker` pytree for a coil spring or a uniform beam.

    Args:
        structure: A :class:`CoilSpring` or :class:`UniformBeam`.
        zeta: One damping ratio for all modes, or one per mode (then ``n_modes`` is ignored).
        n_modes: Number of modes when ``zeta`` is a scalar.
        tip_mass_kg: Point mass at the tip (kg).
        sensor_x_m: Sensor position from the clamp (m).
    """
    zeta = jnp.asarray(zeta, dtype=float)
    if zeta.ndim == 0:
        zeta = jnp.full(n_modes, zeta)
    return Whisker(
        length_m=structure.length_m,
        EI=structure.EI,
        rho_a=structure.rho_a,
        zeta=zeta,
        tip_mass_kg=tip_mass_kg,
        sensor_x_m=sensor_x_m,
    )


def paper_coil() -> CoilSpring:
    """The paper's spring (its Section III): 60 mm, r_w 0.5 mm, r 4.5 mm, 13 coils, steel."""
    return CoilSpring(
        length_m=0.060,
        wire_radius_m=0.0005,
        mean_coil_radius_m=0.0045,
        n_coils=13,
        wire_density_kg_m3=8050.0,
        shear_modulus_pa=70e9,
    )


def paper_whisker(n_modes: int = 5) -> Whisker:
    """The paper's whisker: :func:`paper_coil`, ζ = 0.04, Hall sensor at 5 mm."""
    return whisker_from_structure(paper_coil(), zeta=0.04, n_modes=n_modes, sensor_x_m=0.005)
