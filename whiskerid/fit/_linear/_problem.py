"""A calibration's fit problem: the model of each recording, its residuals and parameters.

The model of one recording is linear in most nuisances, ``y = D(θ) c + g(θ)``: the columns
of ``D`` are an offset, a linear drift, the free (damped) modal terms (:mod:`._decay`, any
initial condition, any observable) and, when its amplitude or phase is unknown, the forced
response to the base motion; ``g`` is the forced response when gain and amplitude are both
known (a sine's start time ``τ`` then stays a parameter). For ADS1115 codes every column is
averaged over the conversion period. Data are normalised (``y`` minus its mean, divided by
its standard deviation).

The parameters ``θ`` are a pytree: ``log_kappa``, ``zeta_u`` (logistic ζ, one or one per
mode), per recording ``c`` (and ``tau`` for a sine of known amplitude), and with a static test
``log_EI`` and its offset ``static_d0``. :meth:`FitProblem.flatten` and
:meth:`FitProblem.unflatten` map it to the flat vector the solver and the covariance use
(``jax.flatten_util.ravel_pytree``; the layout follows from the problem's structure alone).

:class:`FitProblem` is an equinox Module: every number of the whisker, the sensor and the
excitation (length, line density, tip mass, eigenvalues, sensor position, sine frequency,
averaging offsets, data) is a traced array leaf, and only the structure (excitation kinds,
observables, number of modes and columns, whether averaging is on) is static. A jitted
function of a problem therefore compiles once per structure and shape, not once per whisker.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from jaxtyping import Array

from ..._choices import PINS
from ...model import (
    CoilSpring,
    Whisker,
    WhiskerRecord,
    base_motion_response,
    harmonic_steady_state,
    observe,
)
from ...model._modes import host_roots
from .._data import CalibrationError, Observation, StaticTest, nominal_gain
from .._numerics import lsq, sincos
from ._decay import decay_rates, free_decay_columns
from ._limits import limited

ZETA_MAX = 0.95


class _FixedRootsWhisker(Whisker):
    """A :class:`Whisker` whose eigenvalues ``β_i`` are given (computed once for a fixed
    tip-mass ratio), so that a jitted model does not run the root finder on every call."""

    roots: Array | None = None

    @property
    def beta(self):
        return self.roots


class RecordingModel(eqx.Module):
    """One recording's model: its structure (static) and its numbers and data (traced).

    Attributes:
        t: Sample times from the first sample (s).
        y: Normalised samples (``(y − mean)/std``).
        weight: Residual weight (1/σ of the normalised residuals, from a first pass).
        scale: Physical units → normalised observed units (gain / std of y).
        hb_m: Sine amplitude (m; a nominal 1 mm when unknown).
        x_m: Where the signal is read (m from the clamp).
        fb_hz: Sine frequency (Hz; 0 for other excitations).
        avg_offsets: The ADS1115's averaging offsets (s), or None for point samples.
        base_acc: Base acceleration at ``t`` (m/s²), for ``base``.
        excitation: ``decay``, ``sine`` or ``base``.
        observable: ``deflection``, ``acceleration``, ``voltage`` or ``adc``.
        forced: ``none``, ``free`` (forced response as linear columns) or ``known`` (fixed
            part ``g``).
        n_cols: Number of linear columns.
    """

    t: Array
    y: Array
    weight: Array
    scale: Array
    hb_m: Array
    x_m: Array
    fb_hz: Array
    avg_offsets: Array | None
    base_acc: Array | None
    excitation: str = eqx.field(static=True)
    observable: str = eqx.field(static=True)
    forced: str = eqx.field(static=True)
    n_cols: int = eqx.field(static=True)


class StaticTestModel(eqx.Module):
    """A static test as fitted: ``δ = d₀ + F x²(3l − x)/(6 EI)`` with residual scale σ."""

    force: Array
    deflection: Array
    sigma: Array
    x_m: Array
    line_fit: Array  # least-squares (d₀, slope) of deflection on force: the start values


class FitProblem(eqx.Module):
    """Everything a calibration fits, as a pytree (see the module docstring).

    Build it with :meth:`from_observations`; evaluate with :meth:`whisker`,
    :meth:`design`, :meth:`residuals`; map parameters with :meth:`flatten` and
    :meth:`unflatten`; :meth:`reported` gives the reported quantities (f_1, ζ, κ, EI or C).

    Attributes:
        recordings: One :class:`RecordingModel` per recording.
        static_test: The static test, or None.
        length_m: Free length (m).
        rho_a: Line density from the record (kg/m; freed by a static test).
        tip_mass_kg: Tip mass (kg).
        roots: Eigenvalues ``β_i`` for the record's tip-mass ratio, or None when a static
            test frees ρa (they then follow from the fitted ρa).
        ei_nominal: The record's EI (N·m²).
        coil_density: ``ρ_w a`` of a coil (kg/m; ``C = ρa/(ρ_w a)``), 1 for a beam.
        section_moment: A beam's ``I`` (``E = EI/I``) or a coil's ``J_w`` (``G_w = EI/J_w``).
        n_modes: Modes in the model.
        zeta_per_mode: One ζ per mode instead of one for all.
        pin: ``geometry`` or ``material`` (what fixes EI or C without a static test).
        kind: ``coil`` or ``beam``.
        limits: What the user fixed or bounded, ``(param, fixed)`` per parameter
            (``log_kappa``, ``zeta_u``; module ``_limits``); empty for the plain fit.
        limit_values: Their ``(lo, hi)`` rows in the fitted scale (``log κ``, ζ itself), or
            None.
    """

    recordings: tuple[RecordingModel, ...]
    static_test: StaticTestModel | None
    length_m: Array
    rho_a: Array
    tip_mass_kg: Array
    roots: Array | None
    ei_nominal: Array
    coil_density: Array
    section_moment: Array
    n_modes: int = eqx.field(static=True)
    zeta_per_mode: bool = eqx.field(static=True)
    pin: str = eqx.field(static=True)
    kind: str = eqx.field(static=True)
    limits: tuple = eqx.field(static=True, default=(), kw_only=True)
    limit_values: Array | None = eqx.field(default=None, kw_only=True)

    @classmethod
    def from_observations(
        cls,
        record: WhiskerRecord,
        observations: list[Observation],
        *,
        static: StaticTest | None = None,
        n_modes: int = 2,
        zeta_per_mode: bool = False,
        pin: str = "geometry",
        nominal: Whisker | None = None,
        limits: tuple = (),
        limit_values: np.ndarray | None = None,
    ) -> "FitProblem":
        """The problem of fitting ``record``'s whisker to recordings (and a static test);
        ``nominal`` is ``record.whisker().with_modes(n_modes)`` if the caller has it;
        ``limits`` and ``limit_values`` are the user's fixed values and bounds (module
        ``_limits``)."""
        if pin not in PINS or pin == "auto":
            raise CalibrationError(f"pin must be geometry or material, not {pin!r}")
        if nominal is None:
            nominal = record.whisker().with_modes(n_modes)
        length = record.structure.length_m
        rho_a = float(nominal.rho_a)
        recs = [_recording_model(record, o, n_modes) for o in observations]
        static_model = None if static is None else _static_model(static, length)
        structure = record.structure
        coil = isinstance(structure, CoilSpring)
        roots = None
        if static is None:
            roots = host_roots(float(nominal.mu), int(n_modes))
        # NumPy leaves: each jnp.asarray of a host number is a device transfer of its own
        # (tens of µs, a dozen per problem); a jitted program takes either alike
        f64 = lambda x: np.asarray(float(x))  # noqa: E731
        return cls(
            recordings=tuple(recs),
            static_test=static_model,
            length_m=f64(length),
            rho_a=f64(rho_a),
            tip_mass_kg=f64(record.tip_mass_kg),
            roots=roots,
            ei_nominal=f64(nominal.EI),
            coil_density=f64(
                structure.wire_density_kg_m3 * structure.wire_area_m2 if coil else 1.0
            ),
            section_moment=f64(structure.polar_moment_m4 if coil else structure.second_moment_m4),
            n_modes=int(n_modes),
            zeta_per_mode=bool(zeta_per_mode),
            pin=pin,
            kind="coil" if coil else "beam",
            limits=tuple(limits),
            limit_values=None if limit_values is None else np.asarray(limit_values, float),
        )

    @property
    def fit_ei(self) -> bool:
        """Whether EI is fitted (a static test): ρa then follows from EI/κ."""
        return self.static_test is not None

    # ------------------------------------------------------------------ parameters
    def zero_params(self) -> dict:
        """A parameter pytree of the right structure, all zeros."""
        nz = self.n_modes if self.zeta_per_mode else None
        theta = {
            "log_kappa": np.zeros(()),
            "zeta_u": np.zeros(nz) if nz else np.zeros(()),
            "recs": [],
        }
        for r in self.recordings:
            rec = {"c": np.zeros(r.n_cols)}
            if r.forced == "known" and r.excitation == "sine":
                rec["tau"] = np.zeros(())
            theta["recs"].append(rec)
        if self.fit_ei:
            theta["log_EI"] = np.zeros(())
            theta["static_d0"] = np.zeros(())
        return theta

    def flatten(self, params) -> Array:
        """The parameter pytree as one flat vector (the solver's and covariance's order)."""
        return ravel_pytree(params)[0]

    def unflatten(self, flat) -> dict:
        """Inverse of :meth:`flatten`."""
        return ravel_pytree(self.zero_params())[1](flat)

    # ------------------------------------------------------------------ model
    def whisker(self, params) -> Whisker:
        """The whisker at parameters ``params`` (sensor position 0: each recording has its own)."""
        if self.limits:  # the user's fixed values and bounds (module _limits)
            lims, values = self.limits, self.limit_values
            kappa = jnp.exp(limited(lims, values, "log_kappa", params["log_kappa"], lambda u: u))
            rho_a = jnp.exp(params["log_EI"]) / kappa if self.fit_ei else self.rho_a
            zeta = limited(lims, values, "zeta_u", params["zeta_u"],
                           lambda u: lsq.to_interval(u, 0.0, ZETA_MAX))  # fmt: skip
        else:
            kappa = jnp.exp(params["log_kappa"])
            rho_a = jnp.exp(params["log_EI"]) / kappa if self.fit_ei else self.rho_a
            zeta = lsq.to_interval(params["zeta_u"], 0.0, ZETA_MAX)
        zeta = jnp.broadcast_to(zeta, (self.n_modes,))
        fields = dict(
            length_m=self.length_m,
            EI=kappa * rho_a,
            rho_a=rho_a,
            zeta=zeta,
            tip_mass_kg=self.tip_mass_kg,
            sensor_x_m=0.0,
        )
        if self.roots is None:
            return Whisker(**fields)
        return _FixedRootsWhisker(**fields, roots=self.roots)

    def whisker_of(self, params, j: int) -> Whisker:
        """The whisker of recording ``j``: the same for all here; a problem whose recordings
        carry different tip masses (the added-mass method) gives each its own."""
        return self.whisker(params)

    def prior_residuals(self, params) -> Array:
        """Residual rows of parameters fitted under a Gaussian prior (none here; the added
        masses' rows in the added-mass method), in units of their σ."""
        return jnp.zeros(0)

    def design(self, params, *, profile: bool = False) -> list[tuple[Array, Array]]:
        """``(D, g)`` of every recording at ``params`` (see :func:`recording_design`)."""
        w = self.whisker(params)
        return [
            recording_design(r, w, p, profile=profile)
            for r, p in zip(self.recordings, params["recs"], strict=True)
        ]

    def residuals(self, params) -> Array:
        """Weighted residuals of all recordings (and the static test), one vector."""
        out = [
            (D @ p["c"] + g - r.y) * r.weight
            for (D, g), r, p in zip(
                self.design(params), self.recordings, params["recs"], strict=True
            )
        ]
        if self.static_test is not None:
            out.append(self.static_residuals(params))
        return jnp.concatenate(out)

    def static_residuals(self, params) -> Array:
        """The static test's residuals in units of its σ."""
        s = self.static_test
        x, l = s.x_m, self.length_m
        compliance = x**2 * (3 * l - x) / 6
        model = params["static_d0"] + s.force * compliance / jnp.exp(params["log_EI"])
        return (model - s.deflection) / s.sigma

    def reported(self, params) -> dict[str, Array]:
        """The quantities a calibration reports at ``params``: f_1 (and higher f_i), κ, ζ,
        and EI, ρa, C, E or G_w as the pin and the static test allow."""
        w = self.whisker(params)
        out = {"f1_hz": w.natural_frequencies_hz[0], "kappa": w.kappa}
        for i in range(1, self.n_modes):
            out[f"f{i + 1}_hz"] = w.natural_frequencies_hz[i]
        out["zeta"] = w.zeta[0]
        if self.zeta_per_mode:
            for i in range(self.n_modes):
                out[f"zeta_{i + 1}"] = w.zeta[i]
        coil = self.kind == "coil"
        if self.fit_ei:
            out["EI"] = w.EI
            out["rho_a"] = w.rho_a
            if coil:
                out["C"] = w.rho_a / self.coil_density
        elif self.pin == "geometry":
            out["EI"] = w.EI  # = κ ρa with ρa from the record
        else:  # material: EI fixed, ρa (and C) follow from κ
            rho_a = self.ei_nominal / w.kappa
            out["rho_a"] = rho_a
            if coil:
                out["C"] = rho_a / self.coil_density
        if "EI" in out and not coil and not self.fit_ei:
            out["E"] = out["EI"] / self.section_moment
        if "EI" in out and coil and (self.fit_ei or self.pin == "geometry"):
            out["G_w"] = out["EI"] / self.section_moment
        return out

    def reweighted(self, params) -> "FitProblem":
        """The problem with each recording weighted by ``1/σ`` of its own residuals at
        ``params`` (σ² = RSS/(n − columns)): the blocks are then combined fairly and s² ≈ 1."""
        return _reweighted(self, params)


@eqx.filter_jit
def _reweighted(problem, params):
    weights = []
    for (D, g), r, p in zip(
        problem.design(params), problem.recordings, params["recs"], strict=True
    ):
        res = D @ p["c"] + g - r.y
        dof = max(res.size - D.shape[1], 1)
        sigma = jnp.sqrt(jnp.sum(res**2) / dof)
        weights.append(1.0 / jnp.maximum(sigma, 1e-12))
    return eqx.tree_at(lambda q: [r.weight for r in q.recordings], problem, [w for w in weights])


def residuals(params, problem: FitProblem) -> Array:
    """``problem.residuals(params)`` in optimistix's ``fn(y, args)`` form."""
    return problem.residuals(params)


def flat_residuals(flat, problem):
    return problem.residuals(problem.unflatten(flat))


@eqx.filter_jit
def _solve(problem, flat0, solver, max_steps):
    return lsq.least_squares(
        flat_residuals, flat0, problem, solver=lsq.make_solver(solver), max_steps=max_steps
    )


def solve(problem: FitProblem, params, *, solver: str = "levenberg-marquardt",
          max_steps: int = 400) -> lsq.FitResult:  # fmt: skip
    """Least squares of ``problem`` from ``params`` (optimistix; never raises on failure).

    Returns:
        A :class:`whiskerid.fit.FitResult` whose ``value`` is the flat parameter vector
        (:meth:`FitProblem.unflatten` turns it into the pytree).
    """
    if solver not in lsq.SOLVERS:
        raise CalibrationError(f"solver must be one of {', '.join(lsq.SOLVERS)}; got {solver!r}")
    return _solve(problem, problem.flatten(params), solver, max_steps)


@eqx.filter_jit
def covariance(problem: FitProblem, flat) -> tuple[Array, Array]:
    """``s²(JᵀJ)⁻¹`` of the flat parameters at ``flat`` and ``s²`` (see
    ``lsq.residual_covariance``)."""
    return lsq.residual_covariance(flat_residuals, flat, problem)


@eqx.filter_jit
def residuals_and_jacobian(problem: FitProblem, flat) -> tuple[Array, Array]:
    """The weighted residual vector at ``flat`` and its Jacobian in the flat parameters."""
    return flat_residuals(flat, problem), jax.jacfwd(flat_residuals)(flat, problem)


@eqx.filter_jit
def problem_gradient_cosine(problem: FitProblem, flat) -> Array:
    """MINPACK's stationarity measure at ``flat`` (see ``lsq.gradient_cosine``)."""
    return lsq.gradient_cosine(flat_residuals, flat, problem)


@eqx.filter_jit
def reported_with_jacobian(problem: FitProblem, flat):
    """:meth:`FitProblem.reported` at ``flat`` as a vector, and its Jacobian in ``flat``."""
    fn = lambda f: jnp.stack(list(problem.reported(problem.unflatten(f)).values()))  # noqa: E731
    return fn(flat), jax.jacfwd(fn)(flat)


def reported_names(problem: FitProblem) -> list[str]:
    """Names of :meth:`FitProblem.reported`, in its order (they depend on the structure only,
    so they are traced once per structure)."""
    key = jax.tree_util.tree_structure(problem)
    if key not in _REPORTED_NAMES:
        names: list[str] = []

        def keys(params):
            names.extend(problem.reported(params))
            return 0.0

        jax.eval_shape(keys, problem.zero_params())
        _REPORTED_NAMES[key] = tuple(names)
    return list(_REPORTED_NAMES[key])


_REPORTED_NAMES: dict = {}


# --------------------------------------------------------------------------- columns
def _physical(w: Whisker, rec: RecordingModel, state):
    kind = "acceleration" if rec.observable == "acceleration" else "deflection"
    return observe(w, state, kind, x_m=rec.x_m, absolute=kind == "acceleration")


def _averaged(fn, t, offsets):
    """``fn`` evaluated at ``t`` or averaged over the conversion window before each ``t``."""
    if offsets is None:
        return fn(t)
    off = jnp.asarray(offsets)
    tt = (t[:, None] + off[None, :]).reshape(-1)
    out = fn(tt)
    return out.reshape(t.shape[0], off.shape[0], *out.shape[1:]).mean(axis=1)


def _forced_sine(w, rec, t, tau):
    state = harmonic_steady_state(w, t - tau, fb_hz=rec.fb_hz, hb_m=rec.hb_m)
    return _physical(w, rec, state)


def _rms(x):
    """RMS of a free column, with its derivative: a column ``c(θ)/rms(c(θ))`` no longer scales
    with the response's amplitude, and a Jacobian that missed this (the RMS held fixed) left
    sine fits crawling for hundreds of solver steps without converging, their values still
    moving with the step limit."""
    return jnp.sqrt(jnp.mean(x**2) + 1e-300)


def recording_design(rec: RecordingModel, w: Whisker, rec_params: dict, *, profile=False):
    """Columns ``D`` (n, n_cols) and fixed part ``g`` (n,) of one recording's normalised model.

    With ``profile=True`` a known forced response enters as free columns too (for the start
    grid, where τ is not known yet).
    """
    t = rec.t
    span = jnp.maximum(t[-1] - t[0], 1e-12)
    cols = [jnp.ones_like(t)[:, None], ((t - 0.5 * (t[0] + t[-1])) / span)[:, None]]
    sigma, wd = decay_rates(w.omega_rad_s, w.zeta)
    # the vectorised sin/cos (module _trig): XLA's are a scalar call per element, most of the
    # cost of every design the start search, the solver and the Jacobian evaluate
    cols.extend(free_decay_columns(t[:, None], sigma, wd, rec.avg_offsets, sincos=sincos))
    fixed = jnp.zeros_like(t)
    scale = rec.scale  # physical → normalised observed units (gain / std of y)
    if rec.forced == "free" or profile:
        cols.extend(c[:, None] for c in forced_columns(rec, w, t))
    elif rec.excitation == "sine":
        fixed = scale * _averaged(
            lambda tt: _forced_sine(w, rec, tt, rec_params["tau"]), t, rec.avg_offsets
        )
    elif rec.excitation == "base":
        fixed = scale * _base_response(w, rec, t)
    return jnp.concatenate(cols, axis=1), fixed


def forced_columns(rec: RecordingModel, w: Whisker, t) -> list[Array]:
    """A forced response as free columns of unit RMS at ``t`` (in normalised observed units):
    a sine's response and its quarter-period shift, base motion's response; none for a free
    decay (shared by :func:`recording_design` and the start search's profiles)."""
    if rec.excitation == "sine":
        out, period = [], 1.0 / rec.fb_hz
        for shift in (0.0, 0.25 * period):
            c = _averaged(lambda tt, s=shift: _forced_sine(w, rec, tt, s), t, rec.avg_offsets)
            out.append(c * rec.scale / _rms(c))
        return out
    if rec.excitation == "base":
        resp = _base_response(w, rec, t)
        return [resp * rec.scale / _rms(resp)]
    return []


def _base_response(w: Whisker, rec: RecordingModel, t):
    state = base_motion_response(w, t, rec.base_acc)
    resp = _physical(w, rec, state)
    if rec.avg_offsets is not None:
        resp = _averaged(lambda tt: jnp.interp(tt, t, resp), t, rec.avg_offsets)
    return resp


# --------------------------------------------------------------------------- building
@functools.lru_cache(maxsize=8)
def _averaging_offsets(adc) -> np.ndarray:
    """The converter's averaging offsets (s) as a host array, once per converter model."""
    out = np.asarray(adc.averaging_offsets(), dtype=float)
    out.setflags(write=False)
    return out


def _recording_model(record, o: Observation, n_modes: int) -> RecordingModel:
    forced = "none"
    if o.excitation in ("sine", "base"):
        amplitude_known = o.excitation == "base" or o.hb_m is not None
        forced = "known" if (amplitude_known and o.gain is not None) else "free"
    n_extra = {"none": 0, "known": 0, "free": 2 if o.excitation == "sine" else 1}[forced]
    avg = None
    if o.observable == "adc":
        avg = _averaging_offsets(record.adc)
    x_m = record.sensor_position_m if o.x_m is None else float(o.x_m)
    if not 0 <= x_m <= record.structure.length_m:
        raise CalibrationError(f"{o.name}: sensor position {x_m} m is not on the beam")
    y_mean, y_std = float(np.mean(o.y)), float(np.std(o.y))
    if not y_std > 0:
        raise CalibrationError(f"{o.name}: the signal is constant")
    gain = o.gain if o.gain is not None else nominal_gain(record, o.observable)
    f64 = functools.partial(np.asarray, dtype=float)  # host leaves (see from_observations)
    return RecordingModel(
        t=f64(o.t - o.t[0]),
        y=f64((o.y - y_mean) / y_std),
        weight=f64(1.0),
        scale=f64(gain / y_std),
        hb_m=f64(o.hb_m if o.hb_m is not None else 1e-3),
        x_m=f64(float(x_m)),
        fb_hz=f64(float(o.fb_hz or 0.0)),
        avg_offsets=avg,
        base_acc=None if o.excitation != "base" else f64(o.base_acc),
        excitation=o.excitation,
        observable=o.observable,
        forced=forced,
        n_cols=2 + 2 * n_modes + n_extra,
    )


def _static_model(static: StaticTest, length_m: float) -> StaticTestModel:
    x = length_m if static.x_m is None else float(static.x_m)
    A = np.stack([np.ones_like(static.force_n), static.force_n], axis=1)
    coef, *_ = np.linalg.lstsq(A, static.deflection_m, rcond=None)
    r = static.deflection_m - A @ coef
    sigma = max(
        float(np.sqrt(np.sum(r**2) / max(r.size - 2, 1))),
        1e-9 * np.abs(static.deflection_m).max(),
    )
    return StaticTestModel(
        force=jnp.asarray(static.force_n),
        deflection=jnp.asarray(static.deflection_m),
        sigma=jnp.asarray(sigma),
        x_m=jnp.asarray(x),
        line_fit=jnp.asarray(coef),
    )
