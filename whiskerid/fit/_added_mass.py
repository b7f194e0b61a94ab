"""The added-mass method: EI, ρa (a coil's C) and ζ from plucks with and without a known tip mass.

Why it works. A pluck's frequencies are ``f_i = β_i(μ)² sqrt(κ)/(2π l²)`` with ``κ = EI/(ρa)``
and the roots ``β_i`` of the tip-mass frequency equation
``1 + cos β cosh β + μβ(cos β sinh β − sin β cosh β) = 0``, ``μ = M_t/(ρa l)``. Without a
tip mass the plucks reveal only κ. A known mass ``m`` clipped to the tip changes μ by
``m/(ρa l)``: how much the frequencies fall then measures ρa, and ``EI = κ ρa``. This is the
mass-change method of experimental modal analysis.

The joint model. Every recording belongs to a *configuration*, the extra tip mass it carries
(0 for the plain whisker; recordings with the same stated mass share one). All share
``log κ`` and ``log ρa``; each configuration has its own ζ (a clipped mass changes the
damping ratio: the same damper acting on a heavier mode) and its own mass
``m_k = m̂_k + σ_k u_k``, with ``u_k`` fitted under a unit Gaussian prior (one residual
row each): the stated 1σ of each mass thus enters the covariance of everything derived,
``σ(ρa)/ρa ≥ σ_m/m``. Each recording keeps its own nuisances (offset, drift, modal
amplitudes), as in :func:`whiskerid.fit.calibrate`. The mass is taken as a point mass at
the tip; its rotary inertia is neglected (a clip small next to the whisker's length).

How C's 1σ scales. For the first mode, Rayleigh's quotient gives
``f_1 ∝ 1/sqrt(μ_e + μ)`` with the cantilever's effective mass ``μ_e ≈ 33/140``; with
``x = Δμ/(μ_e + μ_0)`` the log frequency shift is ``r = ½ ln(1 + x)`` and
``σ(ρa)/ρa ≈ 2 σ_r (1 + x)/x`` (``σ_r``: 1σ of the measured log shift, which falls as
``1/sqrt(plucks)`` per configuration), plus the mass's own ``σ_m/m`` in quadrature: it
falls as ``1/x`` for light masses and levels off at ``2 σ_r`` for heavy ones. A fit whose
ρa (so C) is known to worse than :data:`MAX_REL_STD` is flagged (check ``added-mass-small``)
with the mass that would do.

Start values: each configuration is fitted alone (the usual start search and one
Levenberg–Marquardt solve), which gives its f_1 and ζ; ρa then follows from the f_1 ratios
(a 1-D search over ρa with κ profiled out), and the joint fit starts there.
"""

import math
from dataclasses import dataclass, fields, replace

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ..model import CoilSpring, UniformBeam, Whisker, WhiskerRecord, cantilever_roots
from ._checks import LAG1_MAX, check_fit, decay_sampling_rates_hz, hac_covariance, no_smaller_than
from ._data import CalibrationError, Observation
from ._linear import (
    GTOL,
    ZETA_MAX,
    FitProblem,
    recording_design,
    reported_names,
    reported_with_jacobian,
    residuals_and_jacobian,
    solve,
    start_values,
)
from ._numerics import gradient_cosine_from, lsq, residual_variance, scaled_inverse_gram
from ._result import (
    Calibration,
    correlation_table,
    fit_diagnostics,
    fit_status,
    poor_fit_warnings,
    record_with_fit,
    recording_blocks,
    recording_diagnostics,
    reported_std,
)

#: A fit whose ρa (so EI and C) has a relative 1σ above this is flagged: the mass is too
#: small for the data's precision.
MAX_REL_STD = 0.10
#: Rayleigh's effective tip mass of a cantilever's first mode, over the beam's (33/140).
EFFECTIVE_MASS = 33.0 / 140.0


@dataclass(frozen=True)
class AddedMass:
    """A known point mass clipped to the tip for a recording.

    Attributes:
        kg: The mass (kg).
        std_kg: Its 1σ (kg), e.g. the scale's resolution.
    """

    kg: float
    std_kg: float = 0.0

    def __post_init__(self):
        if not (math.isfinite(self.kg) and self.kg > 0):
            raise CalibrationError(f"added mass {self.kg!r} kg must be positive")
        if not (math.isfinite(self.std_kg) and 0 <= self.std_kg < 0.5 * self.kg):
            raise CalibrationError(
                f"added mass {self.kg:g} kg: its 1-sigma {self.std_kg!r} kg must be below half "
                "the mass"
            )


class AddedMassProblem(FitProblem):
    """:class:`FitProblem` of recordings with different known tip masses (see the module).

    Parameters: ``log_kappa``, ``log_rho_a``, ``zeta_u`` (one per configuration, or per
    configuration and mode), ``mass_u`` (each configuration's mass in units of its 1σ from
    the stated value) and each recording's ``c``.

    Attributes:
        config_of: Each recording's configuration (0 is the lightest).
        added_kg: Each configuration's stated added mass (kg; 0 for the plain whisker).
        added_std: Their 1σ (kg).
        plain: Whether configuration 0 is the plain whisker (no added mass).
    """

    added_kg: Array
    added_std: Array
    config_of: tuple[int, ...] = eqx.field(static=True)
    plain: bool = eqx.field(static=True)

    @property
    def n_configs(self) -> int:
        """Number of configurations (static)."""
        return int(self.added_kg.shape[0])

    def zero_params(self) -> dict:
        """A parameter pytree of the right structure, all zeros (see the class)."""
        theta = super().zero_params()
        n = self.n_configs
        theta["zeta_u"] = np.zeros((n, self.n_modes) if self.zeta_per_mode else (n,))
        theta["log_rho_a"] = np.zeros(())
        theta["mass_u"] = np.zeros(n)
        return theta

    def added_mass(self, params, k: int) -> Array:
        """Configuration ``k``'s added mass at ``params`` (kg)."""
        return self.added_kg[k] + self.added_std[k] * params["mass_u"][k]

    def whisker_config(self, params, k: int) -> Whisker:
        """The whisker of configuration ``k`` (its tip mass and ζ)."""
        kappa = jnp.exp(params["log_kappa"])
        rho_a = jnp.exp(params["log_rho_a"])
        zeta = lsq.to_interval(params["zeta_u"][k], 0.0, ZETA_MAX)
        return Whisker(
            length_m=self.length_m,
            EI=kappa * rho_a,
            rho_a=rho_a,
            zeta=jnp.broadcast_to(zeta, (self.n_modes,)),
            tip_mass_kg=jnp.maximum(self.tip_mass_kg + self.added_mass(params, k), 0.0),
            sensor_x_m=0.0,
        )

    def whisker(self, params) -> Whisker:
        """The whisker of configuration 0 (the plain one when there is one)."""
        return self.whisker_config(params, 0)

    def whisker_of(self, params, j: int) -> Whisker:
        """The whisker of recording ``j``: its configuration's tip mass and ζ."""
        return self.whisker_config(params, self.config_of[j])

    def design(self, params, *, profile: bool = False) -> list[tuple[Array, Array]]:
        """``(D, g)`` of every recording, each with its configuration's whisker."""
        ws = [self.whisker_config(params, k) for k in range(self.n_configs)]
        return [
            recording_design(r, ws[k], p, profile=profile)
            for r, p, k in zip(self.recordings, params["recs"], self.config_of, strict=True)
        ]

    def prior_residuals(self, params) -> Array:
        """The masses' prior rows: each mass's departure from its stated value in σ."""
        return params["mass_u"]

    def residuals(self, params) -> Array:
        """Weighted residuals of all recordings, then the masses' prior rows."""
        return jnp.concatenate([super().residuals(params), self.prior_residuals(params)])

    def reported(self, params) -> dict[str, Array]:
        """f_1, κ, ζ (of configuration 0), EI, ρa, C or E, G_w, and per loaded configuration
        ``k``: its f_1 (``f1_hz_mass{k}``), ζ (``zeta_mass{k}``), mass and ``μ``."""
        w = self.whisker(params)
        out = {"f1_hz": w.natural_frequencies_hz[0], "kappa": w.kappa}
        for i in range(1, self.n_modes):
            out[f"f{i + 1}_hz"] = w.natural_frequencies_hz[i]
        out["zeta"] = w.zeta[0]
        if self.zeta_per_mode:
            for i in range(self.n_modes):
                out[f"zeta_{i + 1}"] = w.zeta[i]
        out["EI"] = w.EI
        out["rho_a"] = w.rho_a
        if self.kind == "coil":
            out["C"] = w.rho_a / self.coil_density
            out["G_w"] = w.EI / self.section_moment
        else:
            out["E"] = w.EI / self.section_moment
        for k in range(self.n_configs):
            if k == 0 and self.plain:
                continue
            wk = self.whisker_config(params, k)
            out[f"f1_hz_mass{k}"] = wk.natural_frequencies_hz[0]
            out[f"zeta_mass{k}"] = wk.zeta[0]
            out[f"added_mass_kg_{k}"] = self.added_mass(params, k)
            out[f"mu_mass{k}"] = self.added_mass(params, k) / (w.rho_a * self.length_m)
        return out


def configurations(masses: list[AddedMass | None]) -> tuple[list[int], list[AddedMass | None]]:
    """Each recording's configuration index and the configurations, lightest first
    (recordings with equal stated masses and 1σ share a configuration)."""
    distinct = sorted({m for m in masses if m is not None}, key=lambda m: (m.kg, m.std_kg))
    configs: list[AddedMass | None] = ([None] if None in masses else []) + distinct
    return [configs.index(m) for m in masses], configs


def added_mass_problem(
    record: WhiskerRecord,
    observations: list[Observation],
    masses: list[AddedMass | None],
    *,
    n_modes: int = 2,
    zeta_per_mode: bool = False,
) -> AddedMassProblem:
    """The joint problem of recordings with the stated added masses (None: no mass)."""
    if len(masses) != len(observations):
        raise CalibrationError(
            f"{len(masses)} added masses for {len(observations)} recordings: give one each"
        )
    config_of, configs = configurations(masses)
    if len(configs) < 2:
        raise CalibrationError(
            "the added-mass method needs recordings with two different tip masses, e.g. "
            "plucks without and with the clipped mass"
        )
    base = FitProblem.from_observations(
        record, observations, n_modes=n_modes, zeta_per_mode=zeta_per_mode, pin="geometry"
    )
    kg = [0.0 if m is None else m.kg for m in configs]
    std = [0.0 if m is None else m.std_kg for m in configs]
    return AddedMassProblem(
        **{f.name: getattr(base, f.name) for f in fields(base)},
        added_kg=jnp.asarray(kg),
        added_std=jnp.asarray(std),
        config_of=tuple(config_of),
        plain=configs[0] is None,
    )


# --------------------------------------------------------------------------- start values
def start_params(
    problem: AddedMassProblem,
    record: WhiskerRecord,
    observations: list[Observation],
    *,
    solver: str = "levenberg-marquardt",
    max_steps: int = 400,
    f1_start_hz: float | None = None,
) -> dict:
    """Start parameters: each configuration fitted alone, then ρa from the f_1 ratios."""
    n = problem.n_configs
    kg = np.asarray(problem.added_kg)
    f1_nominal0 = None
    f1s, zetas, recs = [], [], [None] * len(observations)
    for k in range(n):
        idx = [j for j, c in enumerate(problem.config_of) if c == k]
        rec_k = record.replace(tip_mass_kg=record.tip_mass_kg + float(kg[k]))
        obs_k = [observations[j] for j in idx]
        prob_k = FitProblem.from_observations(
            rec_k, obs_k, n_modes=problem.n_modes, zeta_per_mode=problem.zeta_per_mode
        )
        nominal = rec_k.whisker().with_modes(problem.n_modes)
        f1_nom = float(nominal.natural_frequencies_hz[0])
        f1_nominal0 = f1_nominal0 or f1_nom
        centre = None if f1_start_hz is None else f1_start_hz * f1_nom / f1_nominal0
        theta = start_values(prob_k, obs_k, nominal, f1_hz=centre)
        res = solve(prob_k, theta, solver=solver, max_steps=max_steps)
        opt = prob_k.unflatten(res.value)
        if not np.all(np.isfinite(np.asarray(res.value))):
            opt = theta
        f1s.append(float(prob_k.whisker(opt).natural_frequencies_hz[0]))
        zetas.append(np.asarray(opt["zeta_u"]))
        for j, r in zip(idx, opt["recs"], strict=True):
            recs[j] = r
    rho_a = rho_a_from_frequencies(
        np.asarray(f1s), kg + record.tip_mass_kg, float(problem.length_m),
        float(problem.rho_a),
    )  # fmt: skip
    mu = (kg + record.tip_mass_kg) / (rho_a * float(problem.length_m))
    beta1 = np.array([float(cantilever_roots(float(m), 1)[0]) for m in mu])
    l2 = float(problem.length_m) ** 2
    sqrt_kappa = np.exp(np.mean(np.log(2 * np.pi * np.asarray(f1s) * l2 / beta1**2)))
    return {
        "log_kappa": np.asarray(2 * np.log(sqrt_kappa)),
        "log_rho_a": np.asarray(np.log(rho_a)),
        "zeta_u": np.stack(zetas),
        "mass_u": np.zeros(n),
        "recs": recs,
    }


def rho_a_from_frequencies(f1_hz, tip_kg, length_m: float, rho_a_nominal: float) -> float:
    """The line density (kg/m) whose tip-mass ratios best explain the first-mode
    frequencies ``f1_hz`` at total tip masses ``tip_kg`` (κ profiled out; least squares
    in log frequency), searched within a factor 100 of ``rho_a_nominal``."""
    log_f = np.log(np.asarray(f1_hz, float))
    tip = np.asarray(tip_kg, float)

    def cost(log_rho):
        mu = tip / (np.exp(log_rho) * length_m)
        r = log_f - 2 * np.log([float(_beta1(m)) for m in mu])
        return float(np.sum((r - r.mean()) ** 2))

    grid = np.log(rho_a_nominal) + np.linspace(-np.log(100), np.log(100), 161)
    costs = [cost(g) for g in grid]
    i = int(np.argmin(costs))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    for _ in range(40):  # golden section between the grid neighbours
        a = hi - 0.618 * (hi - lo)
        b = lo + 0.618 * (hi - lo)
        lo, hi = (lo, b) if cost(a) < cost(b) else (a, hi)
    return float(np.exp(0.5 * (lo + hi)))


def _beta1(mu: float) -> float:
    return float(np.asarray(cantilever_roots(float(mu), 1))[0])


# --------------------------------------------------------------------------- report
def added_mass_check(params: dict, problem: AddedMassProblem, record: WhiskerRecord) -> str | None:
    """A sentence when ρa (so C) is known to worse than :data:`MAX_REL_STD`, with the mass
    that would give half of it; None otherwise."""
    rho = params["rho_a"]
    rel = rho["std"] / abs(rho["value"])
    if rel <= MAX_REL_STD:
        return None
    beam = rho["value"] * float(problem.length_m)
    mu0 = record.tip_mass_kg / beam
    kg = np.asarray(problem.added_kg)
    std = np.asarray(problem.added_std)
    k = int(np.argmax(kg))
    x_now = (kg[k] - kg[0]) / beam / (EFFECTIVE_MASS + mu0)
    mass_rel = std[k] / kg[k] if kg[k] > 0 else 0.0
    stat = math.sqrt(max(rel**2 - mass_rel**2, 0.0))
    target = 0.5 * MAX_REL_STD
    ratio = target / max(stat * x_now / (1 + x_now), 1e-300)  # (1 + x)/x needed
    name = "C" if "C" in params else "rho a"
    text = (
        f"the added mass is too small to separate EI and rho a at this data's precision: "
        f"{name} is known to {100 * rel:.2g} % (1 sigma, above {100 * MAX_REL_STD:.0f} %); "
        f"the mass is {100 * (kg[k] - kg[0]) / beam:.2g} % of the whisker's"
    )
    if mass_rel > target:
        return text + f"; weigh it more precisely (its own 1 sigma is {100 * mass_rel:.2g} %)"
    if ratio > 1:
        need = (EFFECTIVE_MASS + mu0) * beam / (ratio - 1)
        return text + (
            f"; a mass of about {need * 1e3:.3g} g would give about {100 * target:.0f} %, "
            "as would more plucks of each configuration"
        )
    return text + "; record longer or cleaner plucks (more of them) of each configuration"


def added_mass_note(problem: AddedMassProblem, record: WhiskerRecord, masses_text: str) -> str:
    """What the data determine and what C rests on."""
    coil = isinstance(record.structure, CoilSpring)
    rest = (
        " C = rho a/(rho_w a_w) rests on the record's wire density "
        f"({record.structure.wire_density_kg_m3:g} kg/m^3) and wire radius."
        if coil
        else ""
    )
    return (
        "The plucks with and without the added tip mass(es) determine f_1 (kappa = EI/(rho a)) "
        f"and zeta, and through the frequency shift the mass causes ({masses_text}) also rho a, "
        "so EI = kappa rho a: both are reported as fitted, and their 1-sigma include the "
        "masses' stated uncertainties. The mass is taken as a point mass at the tip (its "
        f"rotary inertia neglected); zeta is fitted per configuration.{rest}"
    )


def updated_structure(record: WhiskerRecord, ei: float, rho_a: float):
    """The record's structure with the fitted EI (modulus) and ρa (density: for a coil the
    wire density that gives ``C_geometry ρ_w a = ρa``), so that its whisker is the fit's."""
    s = record.structure
    if isinstance(s, UniformBeam):
        return replace(
            s, youngs_modulus_pa=ei / s.second_moment_m4, density_kg_m3=rho_a / s.area_m2
        )
    return replace(
        s,
        shear_modulus_pa=ei / s.polar_moment_m4,
        wire_density_kg_m3=rho_a / (s.coil_factor * s.wire_area_m2),
    )


@eqx.filter_jit
def reported_vector(problem: AddedMassProblem, flat):
    """``problem.reported`` at ``flat`` as a vector (for tests and benchmarks)."""
    return jnp.stack(list(problem.reported(problem.unflatten(flat)).values()))


# --------------------------------------------------------------------------- calibrate
def calibrate_added_mass(
    record: WhiskerRecord,
    observations: list[Observation],
    masses: list[AddedMass | None],
    *,
    n_modes: int = 2,
    zeta_per_mode: bool = False,
    solver: str = "levenberg-marquardt",
    max_steps: int = 400,
    f1_start_hz: float | None = None,
    start: dict | None = None,
):
    """Fit κ, ρa (so EI and C), ζ per configuration and the nuisances to recordings with
    and without known tip masses (the added-mass method; see the module docstring).

    Called by :func:`whiskerid.fit.calibrate` when it is given ``added_mass``; the
    arguments are as there, with ``masses`` one :class:`AddedMass` (or None) per recording.

    Returns:
        A :class:`whiskerid.fit.Calibration` whose ``params`` hold EI, ρa and C (or E) as
        fitted, and per loaded configuration its f_1, ζ, mass and μ.
    """
    obs = list(observations)
    problem = added_mass_problem(record, obs, masses, n_modes=n_modes, zeta_per_mode=zeta_per_mode)
    if start is None:
        theta0 = start_params(problem, record, obs, solver=solver, max_steps=max_steps,
                              f1_start_hz=f1_start_hz)  # fmt: skip
    else:
        theta0 = start
    theta0 = jax.tree_util.tree_map(jnp.asarray, theta0)
    res = solve(problem, theta0, solver=solver, max_steps=max_steps)
    problem = problem.reweighted(problem.unflatten(res.value))
    res = solve(problem, problem.unflatten(res.value), solver=solver, max_steps=max_steps)
    resid_w, jac = (np.asarray(a) for a in residuals_and_jacobian(problem, res.value))
    bread = np.asarray(scaled_inverse_gram(jac))
    s2 = float(residual_variance(resid_w, res.value.size))
    cov = s2 * bread
    gcos = float(gradient_cosine_from(jac, resid_w))
    ok = (bool(res.ok) or gcos < GTOL) and bool(np.all(np.isfinite(np.diag(cov))))
    status = "ok" if ok else ("non-finite" if not np.isfinite(float(res.cost)) else "not converged")
    optimum = problem.unflatten(res.value)
    per_rec, curves, resid = recording_diagnostics(
        problem, optimum, obs, _models(problem, optimum), np.asarray(problem.residuals(optimum))
    )
    for r, k in zip(per_rec, problem.config_of, strict=True):
        r["added_mass_kg"] = float(problem.added_kg[k])
        r["configuration"] = int(k)
    uncertainty = "white noise: s^2 (J^T J)^-1, masses' 1-sigma included"
    if ok and max(r["lag1_autocorr"] for r in per_rec) > LAG1_MAX:
        hac, lag = hac_covariance(recording_blocks(jac, resid_w, obs), bread)
        cov = no_smaller_than(hac, cov)
        uncertainty = (
            f"HAC (Newey-West, Bartlett weights to lag {lag}; never below the white-noise "
            "1-sigma), masses' 1-sigma included: the residuals are correlated"
        )
    names = reported_names(problem)
    values, rjac = (np.asarray(a) for a in reported_with_jacobian(problem, res.value))
    dcov = rjac @ cov @ rjac.T
    std = reported_std(dcov)
    params = {}
    for i, name in enumerate(names):
        source = "fit"
        if name in ("EI", "rho_a", "C", "E", "G_w"):
            source = "fit (added mass)"
        elif name.startswith(("added_mass_kg_", "mu_mass")):
            source = "stated mass (its 1-sigma)" if name.startswith("added") else "derived"
        params[name] = {"value": float(values[i]), "std": float(std[i]), "source": source}
    masses_text = ", ".join(
        f"{1e3 * float(problem.added_kg[k]):.4g} g ± {1e3 * float(problem.added_std[k]):.2g} g"
        for k in range(problem.n_configs)
        if float(problem.added_kg[k]) > 0
    )
    note = added_mass_note(problem, record, masses_text)
    fixed = {"length_m": float(record.structure.length_m), "tip_mass_kg": float(record.tip_mass_kg)}
    diagnostics = fit_diagnostics(per_rec, obs, res, resid, s2=s2, gcos=gcos,
                                          uncertainty=uncertainty)  # fmt: skip
    warnings = poor_fit_warnings(per_rec)
    checks = {}
    if ok:
        nominal = record.whisker().with_modes(n_modes)
        rates = decay_sampling_rates_hz(obs)
        checks = check_fit(params, per_rec, float(nominal.natural_frequencies_hz[0]),
                           decay_rates_hz=rates, f1_expected_hz=f1_start_hz)  # fmt: skip
        small = added_mass_check(params, problem, record)
        if small is not None:
            checks["added-mass-small"] = small
    status, warnings = fit_status(status, ok, warnings, checks)
    out = Calibration(
        status=status,
        ok=ok,
        params=params,
        correlations=correlation_table(names, dcov, std),
        fixed=fixed,
        note=note,
        diagnostics=diagnostics,
        per_recording=per_rec,
        record=record,
        solver=solver,
        curves=curves,
        warnings=warnings,
        checks=checks,
        problem=problem,
        optimum=optimum,
        covariance=cov,
    )
    out.record = _record_with_added_mass_fit(record, out, obs, problem)
    return out


def _models(problem: AddedMassProblem, optimum) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per recording, the normalised model ``D c + g`` and each mode's part of it (what
    :func:`whiskerid.fit._calibrate._per_recording` reads; the linear calibration gets them
    from its compiled program)."""
    nm = problem.n_modes
    out = []
    for (D, g), rec in zip(problem.design(optimum), optimum["recs"], strict=True):
        D, c = np.asarray(D), np.asarray(rec["c"])
        cols = D[:, 2 : 2 + 2 * nm] * c[2 : 2 + 2 * nm]
        out.append((D @ c + np.asarray(g), cols[:, :nm] + cols[:, nm:]))
    return out


def _record_with_added_mass_fit(record, cal, obs, problem: AddedMassProblem):
    """The record with the fit written in (EI and ρa into its structure) and a ``[fit]``
    table that lists the configurations."""
    new = record_with_fit(record, cal, "added mass", None, obs, problem)
    if cal.ok:
        p = cal.params
        new = new.replace(
            structure=updated_structure(record, p["EI"]["value"], p["rho_a"]["value"])
        )
    fit = dict(new.extra["fit"])
    fit["added_mass"] = [
        {
            "name": o.name,
            "configuration": int(k),
            "kg": float(problem.added_kg[k]),
            "std_kg": float(problem.added_std[k]),
        }
        for o, k in zip(obs, problem.config_of, strict=True)
    ]
    if isinstance(record.structure, CoilSpring) and cal.ok:
        fit["structure_note"] = (
            "wire_density_kg_m3 is set so that the record's rho a (C_geometry rho_w a) equals "
            "the fitted one; the fitted C is in [fit.params.C]"
        )
    return new.replace(extra={**new.extra, "fit": fit})
