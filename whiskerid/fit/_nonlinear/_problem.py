"""The nonlinear fit's problem: a linear :class:`whiskerid.fit.FitProblem` whose first mode
follows the slow flow of :class:`whiskerid.model.NonlinearMode` (the parameters and their
scaling: see :mod:`._fit`)."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from jaxtyping import Array

from ...model import NonlinearMode, mode_shape, slow_flow
from .._linear import FitProblem, conversion_average, recording_design
from ._accelerometer import accelerometer_columns, start_on_backbone
from ._friction import _friction_offset, friction_stop
from ._logpoly import logpoly_mode

#: The nonlinear terms fitted by default, in the order of the parameter vector ``nl``.
NL_TERMS = ("cubic", "quadratic", "coulomb")


#: Every term: the defaults and ``kappa`` (``κu|u|``, a frequency shift linear in ``a``).
ALL_TERMS = (*NL_TERMS, "kappa")


#: Physical coefficient (as :class:`whiskerid.model.NonlinearMode` names it) of each term.
COEFFICIENT_OF = {"cubic": "gamma_per_m2", "quadratic": "quadratic_per_m",
                  "coulomb": "coulomb_m_s2", "kappa": "kappa_per_m"}  # fmt: skip


_SCALED = {"cubic": "g", "quadratic": "zeta_v", "coulomb": "zeta_c", "kappa": "h"}


class NonlinearProblem(eqx.Module):
    """A linear :class:`FitProblem` whose first mode follows the slow flow.

    Attributes:
        base: The linear problem (recordings, whisker, weights).
        a_ref: Reference amplitude (m) that scales the nonlinear parameters.
        terms: The nonlinear terms fitted (a subset of :data:`ALL_TERMS`; empty for a
            log-polynomial backbone).
        n_knots: 0 for the parametric backbone, else the knots of a log-polynomial backbone
            (:mod:`._nl_logpoly`; ``nl`` then holds its values at knots 2…).
        ln_a_lo: ``ln a_lo`` (m) of a log-polynomial backbone's first knot (None without one).
        masks: Per recording, 1 for a sample and 0 for the zero-weight padding of its shape
            bucket (:func:`whiskerid.fit._nonlinear._program.padded`); None when not padded.
    """

    base: FitProblem
    a_ref: Array
    terms: tuple[str, ...] = eqx.field(static=True)
    n_knots: int = eqx.field(static=True, default=0)
    ln_a_lo: Array | None = None
    masks: tuple[Array, ...] | None = None

    def __check_init__(self):
        if jnp.shape(self.a_ref) != ():
            raise ValueError("NonlinearProblem.a_ref must be a scalar")
        if self.n_knots and (self.terms or self.ln_a_lo is None):
            raise ValueError("a log-polynomial backbone takes no terms and needs ln_a_lo")
        if not self.n_knots and (not self.terms or any(t not in ALL_TERMS for t in self.terms)):
            raise ValueError(f"terms must be a non-empty subset of {ALL_TERMS}")

    def zero_params(self) -> dict:
        """The linear problem's pytree plus ``nl`` (one entry per term, or the polynomial's
        ``S_f``, ``S_z`` at knots 2…)."""
        p = self.base.zero_params()
        p["nl"] = np.zeros(2 * (self.n_knots - 1) if self.n_knots else len(self.terms))
        return p

    def flatten(self, params) -> Array:
        """The parameter pytree as one flat vector (the solver's and covariance's order)."""
        return ravel_pytree(params)[0]

    def unflatten(self, flat) -> dict:
        """Inverse of :meth:`flatten`."""
        return ravel_pytree(self.zero_params())[1](flat)

    def scaled(self, params) -> dict[str, Array]:
        """``g``, ``h``, ``zeta_v``, ``zeta_c`` (zero for the terms not fitted)."""
        out = dict.fromkeys(_SCALED.values(), 0.0)
        for i, term in enumerate(self.terms):
            out[_SCALED[term]] = params["nl"][i]
        return out

    def mode(self, params) -> NonlinearMode:
        """The first mode at ``params`` (physical coefficients from the scaled ones, or the
        log-polynomial backbone)."""
        if self.n_knots:
            return logpoly_mode(self, params)
        w = self.base.whisker(params)
        s = self.scaled(params)
        w0 = w.omega_rad_s[0]
        a = self.a_ref
        return NonlinearMode(
            f0_hz=w0 / (2 * jnp.pi),
            zeta0=w.zeta[0],
            gamma_per_m2=8 * s["g"] / (3 * a**2),
            quadratic_per_m=3 * jnp.pi * s["zeta_v"] / (4 * a),
            coulomb_m_s2=jnp.pi * w0**2 * s["zeta_c"] * a / 2,
            kappa_per_m=3 * jnp.pi * s["h"] / (4 * a),
        )

    def design(self, params) -> list[tuple[Array, Array, Array]]:
        """``(D, g, a)`` per recording: the linear design with mode 1's two columns replaced
        by the slow flow's, and the envelope ``a(t)`` (m)."""
        w = self.base.whisker(params)
        mode = self.mode(params)
        nm = self.base.n_modes
        out = []
        for i, (rec, p) in enumerate(zip(self.base.recordings, params["recs"], strict=True)):
            D, g = recording_design(rec, w, p)
            obs = observed_per_metre(rec, mode, w)
            a0 = jnp.hypot(p["c"][2], p["c"][2 + nm]) / (jnp.abs(rec.scale) * obs)
            if rec.observable == "acceleration":  # it reads a·|K(a)|, not a·ω₀²
                a0 = start_on_backbone(mode, a0)
            a, phi = slow_flow(mode, rec.t, a0)
            if "coulomb" in self.terms:
                psi = phi - jnp.arctan2(p["c"][2 + nm], p["c"][2])
                a, held, _ = friction_stop(mode, rec.t, a, psi)
            env = a / jnp.maximum(a0, 1e-300)
            if rec.observable == "acceleration":
                c, s = accelerometer_columns(mode, jnp.maximum(a, 0.0), a0, env, phi)
            else:
                c, s = env * jnp.cos(phi), env * jnp.sin(phi)
            if rec.avg_offsets is not None:
                wd = mode.omega(a) * jnp.sqrt(1 - mode.zeta0**2)
                re, im = conversion_average(mode.zeta0 * mode.omega0 + 0 * wd, wd, rec.avg_offsets)
                c, s = c * re - s * im, s * re + c * im
            D = D.at[:, 2].set(c).at[:, 2 + nm].set(s)
            if "coulomb" in self.terms:
                g = g + _friction_offset(rec, psi, held, mode, obs)
                # the held level is profiled out (a free constant after the stop): the stop's
                # turn is discrete, and one turn more or less would move the exact level by
                # 2F/ω₀², a step over the whole rest of the recording (a rugged cost)
                real = held if self.masks is None else held & (self.masks[i] > 0)
                level = jnp.sum(jnp.where(real, rec.y - D @ p["c"] - g, 0.0))
                g = g + jnp.where(held, level / jnp.maximum(jnp.sum(real), 1), 0.0)
            out.append((D, g, jnp.maximum(a, 0.0)))
        return out

    def residuals(self, params) -> Array:
        """Weighted residuals of all recordings, one vector (0 where padded)."""
        masks = self.masks or (1.0,) * len(self.base.recordings)
        return jnp.concatenate(
            [
                (D @ p["c"] + g - r.y) * r.weight * m
                for (D, g, _), r, p, m in zip(
                    self.design(params), self.base.recordings, params["recs"], masks, strict=True
                )
            ]
        )

    def reported(self, params, amplitudes: Array) -> dict[str, Array]:
        """The linear fit's quantities (f1_hz, ζ … at ``a → 0``), the physical nonlinear
        coefficients, and the backbone ``f(a)``, ``ζ(a)`` at ``amplitudes`` (m)."""
        out = dict(self.base.reported(params))
        m = self.mode(params)
        for term in self.terms:
            out[COEFFICIENT_OF[term]] = getattr(m, COEFFICIENT_OF[term])
        for i in range(amplitudes.shape[0]):
            out[f"backbone_f_{i}"] = m.frequency_hz(amplitudes[i])
            out[f"backbone_zeta_{i}"] = m.zeta(amplitudes[i])
        return out


def observed_per_metre(rec, mode, whisker):
    """Observed (physical) amplitude per metre of mode-1 tip deflection: the mode shape's
    ``φ₁(x)/φ₁(l)`` where it is read, times ``ω₀²`` for acceleration."""
    acc = mode.omega0**2 if rec.observable == "acceleration" else 1.0
    return acc / tip_per_sensor(whisker, rec.x_m)


def tip_per_sensor(whisker, x_m):
    """``φ₁(l)/φ₁(x)``: mode 1's tip deflection per unit of its deflection at ``x_m``."""
    shape = mode_shape(whisker.beta, jnp.stack([x_m / whisker.length_m, 1.0]))[:, 0]
    return shape[1] / shape[0]
