"""Higher modes with their own frequency and damping beside the nonlinear first mode.

A real beam's higher modes do not sit where the record's Euler–Bernoulli model puts them:
the 50 cm cantilever's second mode rings at 39.1 Hz, while the beam with its accelerometer
taken as a tip mass puts it near 38 Hz. In a decay of 20 s the frequency resolution is
0.05 Hz, so a mode column 1 Hz off is orthogonal to the line it should fit: its amplitude
stays near zero, and from zero amplitude a least-squares solver cannot move the frequency
(the cost does not depend on it). A second mode tied to the first by the beam's ratio
therefore leaves the line in the residuals, and only adds nuisance columns that widen ζ₀'s 1σ.

Here mode ``k ≥ 2`` is a free linear damped mode, ``f_k = f_k⁽⁰⁾e^{u_k}`` and
``ζ_k = ζ_k⁽⁰⁾e^{v_k}`` (``u_k``, ``v_k`` fitted, its amplitude and phase in the linear
columns as before), started where the data put it: ``f_k⁽⁰⁾`` at the strongest line of the
recordings' spectrum within a factor :data:`SEARCH` of the beam's ``f_k``, ``ζ_k⁽⁰⁾`` the
best of a few multiples of the linear fit's ζ, and the amplitudes at their least-squares
values for those starts (variable projection for the first step).
"""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .._linear import decay_rates, free_decay_columns
from ._problem import NonlinearProblem

#: The line of mode k is looked for between f_k/SEARCH and f_k·SEARCH.
SEARCH = 1.3
#: Starting damping ratios of a free mode, as multiples of the linear fit's ζ.
ZETA_STARTS = (1.0, 3.0, 10.0, 30.0)


class FreeModesProblem(NonlinearProblem):
    """A :class:`NonlinearProblem` whose modes 2… have free ``f_k`` and ``ζ_k``.

    Attributes:
        f_start: Starting ``f_k`` of modes 2… (Hz).
        zeta_start: Starting ``ζ_k`` of modes 2….
    """

    f_start: Array = None
    zeta_start: Array = None

    def zero_params(self) -> dict:
        """The nonlinear pytree plus ``hm``: ``(ln f_k/f_k⁽⁰⁾, ln ζ_k/ζ_k⁽⁰⁾)`` per mode."""
        p = super().zero_params()
        p["hm"] = np.zeros(2 * (self.base.n_modes - 1))
        return p

    def higher(self, params) -> tuple[Array, Array]:
        """``(f_k Hz, ζ_k)`` of modes 2… at ``params``."""
        u = params["hm"].reshape(-1, 2)
        return self.f_start * jnp.exp(u[:, 0]), self.zeta_start * jnp.exp(u[:, 1])

    def design(self, params):
        """As :meth:`NonlinearProblem.design`, modes 2… at their own ``f_k``, ``ζ_k``."""
        nm = self.base.n_modes
        f, z = self.higher(params)
        sigma, wd = decay_rates(2 * jnp.pi * f, z)
        out = []
        for (D, g, a), rec in zip(super().design(params), self.base.recordings, strict=True):
            c, s = free_decay_columns(rec.t[:, None], sigma, wd, rec.avg_offsets)
            D = D.at[:, 3 : 2 + nm].set(c).at[:, 3 + nm : 2 + 2 * nm].set(s)
            out.append((D, g, a))
        return out

    def reported(self, params, amplitudes):
        """As :meth:`NonlinearProblem.reported`, with the free ``f_k`` and ``ζ_k``."""
        out = super().reported(params, amplitudes)
        f, z = self.higher(params)
        for k in range(1, self.base.n_modes):
            out[f"f{k + 1}_hz"] = f[k - 1]
            out[f"zeta_{k + 1}"] = z[k - 1]
        return out


def _line_near(obs, f_hz: float) -> float:
    """The strongest line of the recordings' summed periodogram within a factor
    :data:`SEARCH` of ``f_hz`` (Hann window, zero-padded 4×, parabolic peak)."""
    lo, hi = f_hz / SEARCH, f_hz * SEARCH
    best, power = f_hz, -1.0
    for o in obs:
        dt = float(np.median(np.diff(o.t)))
        y = np.interp(o.t[0] + dt * np.arange(o.t.size), o.t, o.y)
        n = 4 * y.size
        p = np.abs(np.fft.rfft((y - y.mean()) * np.hanning(y.size), n)) ** 2
        f = np.fft.rfftfreq(n, dt)
        sel = np.flatnonzero((f >= lo) & (f <= hi))
        if sel.size < 3:
            continue
        i = int(sel[np.argmax(p[sel])])
        if p[i] > power and 0 < i < p.size - 1:
            a, b, c = np.log(p[i - 1 : i + 2])
            shift = 0.5 * (a - c) / (a - 2 * b + c) if a - 2 * b + c < 0 else 0.0
            best, power = float(f[i] + shift * (f[1] - f[0])), float(p[i])
    return best


def _project(problem, params):
    """``params`` with every recording's linear amplitudes at their least-squares values."""
    recs = []
    for (D, g, _), r, p in zip(
        problem.design(params), problem.base.recordings, params["recs"], strict=True
    ):
        c = jnp.linalg.lstsq(D, r.y - g)[0]
        recs.append({**p, "c": c})
    return {**params, "recs": recs}


def free_higher_modes(problem: NonlinearProblem, theta0: dict, obs) -> tuple:
    """The problem with free higher modes and its start (see the module docstring).

    Args:
        problem: The nonlinear problem (two or more modes).
        theta0: Its start (the linear optimum with ``nl``).
        obs: The recordings.

    Returns:
        ``(FreeModesProblem, start)``.
    """
    w = problem.base.whisker(theta0)
    nm = problem.base.n_modes
    f_beam = np.asarray(w.natural_frequencies_hz)[1:nm]
    zeta = np.asarray(w.zeta)[1:nm]
    f0 = jnp.asarray([_line_near(obs, float(f)) for f in f_beam])
    best = None
    for m in ZETA_STARTS:
        fp = FreeModesProblem(base=problem.base, a_ref=problem.a_ref, terms=problem.terms,
                              n_knots=problem.n_knots, ln_a_lo=problem.ln_a_lo,
                              f_start=f0, zeta_start=jnp.asarray(zeta * m))  # fmt: skip
        start = _project(fp, {**theta0, "hm": jnp.zeros(2 * (nm - 1))})
        cost = float(jnp.sum(fp.residuals(start) ** 2))
        if best is None or cost < best[0]:
            best = (cost, fp, start)
    return best[1], best[2]


def free_modes_table(params: dict, n_modes: int) -> dict:
    """The record's ``[fit.nonlinear.free_modes]`` table from a fit's reported ``params``:
    modes 2…'s fitted ``f_hz``, ``zeta`` and their 1σ (lists, mode 2 first), which
    ``simulate`` plays instead of the beam's (:func:`whiskerid.model.nonlinear_coefficients`).
    """
    ks = range(2, n_modes + 1)
    return {
        "f_hz": [float(params[f"f{k}_hz"]["value"]) for k in ks],
        "f_std_hz": [float(params[f"f{k}_hz"]["std"]) for k in ks],
        "zeta": [float(params[f"zeta_{k}"]["value"]) for k in ks],
        "zeta_std": [float(params[f"zeta_{k}"]["std"]) for k in ks],
    }
