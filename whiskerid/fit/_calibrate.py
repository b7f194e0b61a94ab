"""Calibrate a whisker from its recordings: stiffness (κ, EI or C), damping ζ, nuisances.

What the data determine (NOTES §3). Vibration records alone determine the natural
frequencies, hence ``κ = EI/(ρa)`` (equivalently ``f_1``), and the modal damping ``ζ``;
``EI`` and ``ρa`` (so the coil factor ``C``) only as their ratio. The fit is therefore
parametrised in identifiable quantities, ``log κ`` and ``ζ`` (a logistic transform keeps
``0 < ζ < 0.95``), and EI or C is *derived* from κ and one pinned quantity, with the
uncertainty propagated through the Jacobian:

* ``geometry`` (default for coils and beams): ``ρa`` from the record's geometry and density
  (a coil's ``C`` from its wire and coil dimensions) → ``EI = κ ρa``;
* ``material``: ``EI`` from the record's material (``G_w J_w`` or ``E I``) → ``ρa = EI/κ``
  and a coil's ``C = ρa/(ρ_w a)``;
* a static test (tip force and deflection) fitted jointly: ``EI`` from the test, ``ρa`` and
  ``C`` from ``EI/κ``. Only then are both EI and C reported as fitted.

A tip mass makes the mode-frequency ratios depend on ``μ = M_t/(ρa l)``, so on ρa, but only
weakly; μ is taken from the record unless a static test fixes ρa.

The model of one recording is linear in most nuisances, ``y = D(θ) c + g(θ)``: the columns
of ``D`` are the free (damped) modal terms ``e^{σ_i t} cos ω_d,i t`` and ``sin`` (any
initial condition, any observable), an offset, a linear drift and, when its amplitude or
phase is unknown, the forced response to the base motion; ``g`` is the forced response when
gain and amplitude are both known (a sine's start time ``τ`` then stays a parameter). For
ADS1115 codes every column is averaged over the conversion period (the converter's sinc
response). Start values come from the data: a grid over ``(κ, ζ)`` seeded by the spectral
peaks (sub-bin interpolation, aliases unfolded with the nominal ``f_1``) and the envelope's
logarithmic decay, with the linear coefficients solved exactly at every grid point
(variable projection); the best point starts a Levenberg–Marquardt fit of all parameters
(optimistix, ``throw=False``, a status per fit). The covariance is ``s²(JᵀJ)⁻¹`` at the
optimum (:func:`whiskerid._lsq.covariance`); with several recordings (or a static test) each
block is weighted by its own residual scale from a first pass.

jaxopt is not used as a second backend: version 0.8.5 warns on import that it is no longer
maintained (which fails a test run with ``filterwarnings = error``) and its
Levenberg–Marquardt ignored ``tol`` (always ``maxiter`` steps, NOTES §9); the bounds it
could add are handled here by transforms. ``scipy.optimize.least_squares`` and lmfit are
compared in ``benchmarks/calibrate.py`` instead.

:func:`fit_windows` fits many short windows at once (``vmap``) for per-window modal
features (damped frequency, ζ, amplitude); one bad window only flags itself.
"""

import functools
import hashlib
import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._choices import EXCITATIONS, OBSERVABLES, PINS
from ..io._recording import RecordingError, check_samples
from ..model._record import WhiskerRecord
from ..model._response import base_motion_response, harmonic_steady_state, observe
from ..model._whisker import CoilSpring, UniformBeam, Whisker
from . import _lsq as _lsq
from ._signal import amplitude_spectrum, find_peaks, resample_uniform

ZETA_MAX = 0.95
# fit_windows: converged when |cos(residuals, each Jacobian column)| < this (MINPACK gtol).
WINDOW_GTOL = 1e-4
G0 = 9.80665  # m/s² per g
_MAX_PROFILE_SAMPLES = 6000


class CalibrationError(ValueError):
    """Input that cannot be calibrated (message says what)."""


# --------------------------------------------------------------------------- inputs
@dataclass(frozen=True)
class Observation:
    """One recording prepared for calibration.

    Attributes:
        t: Sample times (s), increasing, uniform or not.
        y: Samples in the observable's units (m, m/s², V or ADS1115 codes).
        excitation: ``decay`` (pluck or tap, free vibration), ``sine`` (base excitation at
            ``fb_hz``) or ``base`` (measured base acceleration ``base_acc`` at ``t``).
        observable: ``deflection`` (relative, m), ``acceleration`` (absolute, m/s²),
            ``voltage`` (Hall output, V) or ``adc`` (codes, averaged over the conversion).
        x_m: Where the signal is read, from the clamp (m); the record's sensor by default.
        fb_hz: Sine frequency (Hz), for ``sine``.
        hb_m: Sine amplitude (m); None when unknown (then only gain·h_b is fitted).
        base_acc: Base acceleration at ``t`` (m/s²), for ``base``.
        gain: Observed units per unit of the physical observable (1 for deflection and
            acceleration; V/m for voltage; codes/m for adc); None to fit it (as a product
            with the excitation amplitude).
        name: Label used in reports.
        source: File it came from (hashed into the record), if any.
    """

    t: np.ndarray
    y: np.ndarray
    excitation: str = "decay"
    observable: str = "deflection"
    x_m: float | None = None
    fb_hz: float | None = None
    hb_m: float | None = None
    base_acc: np.ndarray | None = None
    gain: float | None = 1.0
    name: str = "recording"
    source: str | None = None

    def __post_init__(self):
        object.__setattr__(self, "t", np.asarray(self.t, dtype=float))
        object.__setattr__(self, "y", np.asarray(self.y, dtype=float))
        check_samples(self.t, self.y, where=self.name, min_samples=16)
        if self.excitation not in EXCITATIONS:
            raise CalibrationError(
                f"excitation must be one of {EXCITATIONS}, not {self.excitation!r}"
            )
        if self.observable not in OBSERVABLES:
            raise CalibrationError(
                f"observable must be one of {OBSERVABLES}, not {self.observable!r}"
            )
        if self.excitation == "sine" and not (self.fb_hz and self.fb_hz > 0):
            raise CalibrationError(f"{self.name}: a sine excitation needs its frequency (--fb)")
        if self.excitation == "base":
            if self.base_acc is None:
                raise CalibrationError(
                    f"{self.name}: a base excitation needs the base acceleration"
                )
            acc = np.asarray(self.base_acc, dtype=float)
            check_samples(self.t, acc, where=f"{self.name} (base acceleration)", min_samples=16)
            object.__setattr__(self, "base_acc", acc)

    def window(self, t_start: float | None = None, t_end: float | None = None) -> "Observation":
        """The samples with ``t_start ≤ t ≤ t_end`` (base acceleration cut alike)."""
        keep = np.ones(self.t.size, bool)
        if t_start is not None:
            keep &= self.t >= t_start
        if t_end is not None:
            keep &= self.t <= t_end
        acc = None if self.base_acc is None else self.base_acc[keep]
        return _replace(self, t=self.t[keep], y=self.y[keep], base_acc=acc)


def _replace(obj, **changes):
    from dataclasses import replace

    return replace(obj, **changes)


@dataclass(frozen=True)
class StaticTest:
    """A static test: forces at (or near) the tip and the deflections they cause.

    ``δ_k = d₀ + F_k x²(3l − x)/(6 EI)`` (Euler–Bernoulli, force at the tip, deflection read at
    ``x``, the tip by default); ``d₀`` absorbs the zero of the gauge.

    Attributes:
        force_n: Forces (N).
        deflection_m: Deflections (m).
        x_m: Where the deflection is read (m from the clamp); the tip when None.
        source: File it came from, if any.
    """

    force_n: np.ndarray
    deflection_m: np.ndarray
    x_m: float | None = None
    source: str | None = None

    def __post_init__(self):
        f = np.asarray(self.force_n, dtype=float)
        d = np.asarray(self.deflection_m, dtype=float)
        if f.shape != d.shape or f.ndim != 1 or f.size < 3:
            raise CalibrationError("static test: need at least 3 (force, deflection) pairs")
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(d))):
            raise CalibrationError("static test: non-finite force or deflection")
        if np.ptp(f) <= 0:
            raise CalibrationError("static test: the forces must differ")
        object.__setattr__(self, "force_n", f)
        object.__setattr__(self, "deflection_m", d)


def read_static_test(path: str | Path) -> StaticTest:
    """Read a static test CSV with columns ``force_n`` and ``deflection_m`` (optional ``x_m``)."""
    from ..io._recording import read_csv_table

    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such static-test file")
    table = read_csv_table(path)
    need = ("force_n", "deflection_m")
    missing = [c for c in need if c not in table.header]
    if missing:
        raise RecordingError(
            f"{path}: static test needs columns {list(need)}; header is {table.header}"
        )
    col = {h: table.data[:, j] for j, h in enumerate(table.header)}
    x = col.get("x_m")
    return StaticTest(
        force_n=col["force_n"],
        deflection_m=col["deflection_m"],
        x_m=None if x is None else float(x[0]),
        source=str(path),
    )


def sha256_of(path: str | Path) -> str:
    """SHA-256 of a file's bytes (provenance in the calibration record)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


# --------------------------------------------------------------------------- start values
def unalias(f_obs_hz: float, rate_hz: float, f_nominal_hz: float, *, folds: int = 6) -> float:
    """The frequency, among ``|k·rate ± f_obs|``, closest (in ratio) to a nominal one."""
    cands = [abs(k * rate_hz + s * f_obs_hz) for k in range(folds + 1) for s in (-1, 1)]
    cands = [c for c in cands if c > 0]
    return min(cands, key=lambda c: abs(math.log(c / f_nominal_hz)))


def spectral_peaks(
    t: np.ndarray, y: np.ndarray, *, n: int = 3, window: str = "hann"
) -> tuple[list[float], float]:
    """Largest spectral peaks (Hz, sub-bin interpolated) and the median sample rate.

    ``window="hann"`` suits steady oscillations; ``"none"`` suits a decay that is over early
    in the record, which a Hann window (near zero at the ends) all but erases.
    """
    _, yu, rate = resample_uniform(t, y)
    freqs, amps = amplitude_spectrum(yu, rate, window=window)
    df = freqs[1] - freqs[0] if freqs.size > 1 else 1.0
    peaks = find_peaks(freqs, amps, n=n, min_separation_hz=3 * df)
    return [p.frequency_hz for p in peaks if p.frequency_hz > 0], rate


def envelope_zeta(t: np.ndarray, y: np.ndarray, f_obs_hz: float, f_true_hz: float) -> float | None:
    """ζ from the logarithmic decay of the signal's RMS envelope (None if not measurable).

    RMS over consecutive windows of about four periods of the observed (possibly aliased)
    frequency; windows near the noise floor are dropped; ``ζ = −slope/(2π f)``.
    """
    y = y - np.median(y)
    span = t[-1] - t[0]
    win = max(4.0 / max(f_obs_hz, 1e-9), 12 * float(np.median(np.diff(t))))
    n_win = int(span // win)
    if n_win < 3:
        return None
    edges = t[0] + win * np.arange(n_win + 1)
    idx = np.searchsorted(t, edges)
    rms = np.array(
        [np.sqrt(np.mean(y[a:b] ** 2)) if b > a else np.nan for a, b in itertools.pairwise(idx)]
    )
    mid = 0.5 * (edges[:-1] + edges[1:])
    floor = np.nanmin(rms)
    keep = np.isfinite(rms) & (rms > 4 * floor)
    # Use only the first run of windows above the floor (the decay, not later noise bumps).
    if keep.sum() < 2:
        return None
    first = np.flatnonzero(keep)
    run = first[: np.argmax(np.diff(np.concatenate([first, [first[-1] + 2]])) > 1) + 1]
    if run.size < 2:
        return None
    slope = np.polyfit(mid[run], np.log(rms[run]), 1)[0]
    zeta = -slope / (2 * np.pi * f_true_hz)
    return float(np.clip(zeta, 1e-4, 0.5)) if np.isfinite(zeta) else None


def release_time(t: np.ndarray, y: np.ndarray) -> float:
    """When a pluck was released: the sample of largest deviation from the median."""
    return float(t[int(np.argmax(np.abs(y - np.median(y))))])


# --------------------------------------------------------------------------- model
@dataclass(frozen=True)
class _Spec:
    """Static description of one recording's model (hashable: part of the jit key)."""

    excitation: str
    observable: str
    forced: str  # "none", "free" (amplitude/phase fitted linearly) or "known" (fixed part)
    n_cols: int
    x_m: float
    fb_hz: float
    avg_offsets: tuple[float, ...] | None


@dataclass(frozen=True)
class _Problem:
    """Static description of the whole fit."""

    specs: tuple[_Spec, ...]
    n_modes: int
    zeta_per_mode: bool
    fit_ei: bool
    length_m: float
    rho_a: float
    tip_mass_kg: float
    static_x_m: float | None


def _whisker(p: _Problem, theta: dict) -> Whisker:
    kappa = jnp.exp(theta["log_kappa"])
    rho_a = jnp.exp(theta["log_EI"]) / kappa if p.fit_ei else jnp.asarray(p.rho_a)
    zeta = _lsq.to_interval(theta["zeta_u"], 0.0, ZETA_MAX)
    zeta = jnp.broadcast_to(zeta, (p.n_modes,))
    return Whisker(
        length_m=p.length_m,
        EI=kappa * rho_a,
        rho_a=rho_a,
        zeta=zeta,
        tip_mass_kg=p.tip_mass_kg,
        sensor_x_m=0.0,
    )


def _physical(w: Whisker, spec: _Spec, state):
    kind = "acceleration" if spec.observable == "acceleration" else "deflection"
    return observe(w, state, kind, x_m=spec.x_m, absolute=kind == "acceleration")


def _averaged(fn, t, offsets):
    """``fn`` evaluated at ``t`` or averaged over the conversion window before each ``t``."""
    if offsets is None:
        return fn(t)
    off = jnp.asarray(offsets)
    tt = (t[:, None] + off[None, :]).reshape(-1)
    out = fn(tt)
    return out.reshape(t.shape[0], off.shape[0], *out.shape[1:]).mean(axis=1)


def _free_columns(w: Whisker, t):
    """``e^{σ_i t} cos(ω_d,i t)`` and ``e^{σ_i t} sin(ω_d,i t)`` per mode, ``(n, 2 modes)``."""
    omega, zeta = w.omega_rad_s, w.zeta
    wd = omega * jnp.sqrt(1.0 - zeta**2)
    e = jnp.exp(-zeta * omega * t[:, None])
    return jnp.concatenate([e * jnp.cos(wd * t[:, None]), e * jnp.sin(wd * t[:, None])], axis=1)


def _free_columns_averaged(w: Whisker, t, offsets):
    """:func:`_free_columns` averaged over the conversion window, in closed form.

    With ``λ = −ζω + iω_d`` each column is ``Re`` or ``Im`` of ``e^{λt}``, and the mean of
    ``e^{λ(t + o_k)}`` over the offsets ``o_k`` is ``e^{λt}`` times the constant
    ``A = mean_k e^{λ o_k}``: the same midpoint-rule average as :func:`_averaged`, at the
    cost of one evaluation per sample instead of one per offset.
    """
    cols = _free_columns(w, t)
    if offsets is None:
        return cols
    omega, zeta = w.omega_rad_s, w.zeta
    wd = omega * jnp.sqrt(1.0 - zeta**2)
    off = jnp.asarray(offsets)[:, None]
    e = jnp.exp(-zeta * omega * off)
    a_re = jnp.mean(e * jnp.cos(wd * off), axis=0)
    a_im = jnp.mean(e * jnp.sin(wd * off), axis=0)
    c, s = jnp.split(cols, 2, axis=1)
    return jnp.concatenate([c * a_re - s * a_im, s * a_re + c * a_im], axis=1)


def _forced_sine(w, spec, t, hb, tau):
    state = harmonic_steady_state(w, t - tau, fb_hz=spec.fb_hz, hb_m=hb)
    return _physical(w, spec, state)


def _design(p: _Problem, spec: _Spec, w: Whisker, rec: dict, d: dict, *, profile: bool = False):
    """Columns ``D`` (n, n_cols) and fixed part ``g`` (n,) of one recording's normalised model.

    With ``profile=True`` a known forced response enters as free columns too (for the start
    grid, where τ is not known yet).
    """
    t = d["t"]
    span = jnp.maximum(t[-1] - t[0], 1e-12)
    cols = [jnp.ones_like(t)[:, None], ((t - 0.5 * (t[0] + t[-1])) / span)[:, None]]
    cols.append(_free_columns_averaged(w, t, spec.avg_offsets))
    fixed = jnp.zeros_like(t)
    scale = d["scale"]  # physical → normalised observed units (gain / std of y)
    if spec.excitation == "sine":
        period = 1.0 / spec.fb_hz
        if spec.forced == "free" or profile:
            for shift in (0.0, 0.25 * period):
                c = _averaged(
                    lambda tt, s=shift: _forced_sine(w, spec, tt, d["hb"], s), t, spec.avg_offsets
                )
                cols.append((c * scale / _rms(c))[:, None])
        else:
            fixed = scale * _averaged(
                lambda tt: _forced_sine(w, spec, tt, d["hb"], rec["tau"]), t, spec.avg_offsets
            )
    elif spec.excitation == "base":
        state = base_motion_response(w, d["t_full"], d["base_acc"])
        resp = _physical(w, spec, state)
        if spec.avg_offsets is not None:
            resp = _averaged(
                lambda tt: jnp.interp(tt, d["t_full"], resp), d["t_full"], spec.avg_offsets
            )
        if spec.forced == "free" or profile:
            cols.append((resp * scale / _rms(resp))[:, None])
        else:
            fixed = scale * resp
    return jnp.concatenate(cols, axis=1), fixed


# Eager callers (start values, reweighting, reports) use the compiled form: an eager
# lax.fori_loop (the eigenvalue bisection) would otherwise recompile at every call.
_design_eval = eqx.filter_jit(_design)


def _rms(x):
    return jax.lax.stop_gradient(jnp.sqrt(jnp.mean(x**2)) + 1e-300)


@dataclass(frozen=True)
class _Unravel:
    """Flat vector → parameter pytree; hashable by value, so compiled fits are reused
    across calls with the same problem (e.g. many trials or windows of one shape)."""

    treedef: Any
    shapes: tuple[tuple[int, ...], ...]

    def __call__(self, flat):
        leaves, i = [], 0
        for shape in self.shapes:
            n = math.prod(shape)
            leaves.append(flat[i : i + n].reshape(shape))
            i += n
        return jax.tree_util.tree_unflatten(self.treedef, leaves)


def _ravel(tree):
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    shapes = tuple(tuple(int(d) for d in jnp.shape(x)) for x in leaves)
    flat = jnp.concatenate([jnp.ravel(jnp.asarray(x, dtype=float)) for x in leaves])
    return flat, _Unravel(treedef, shapes)


def _residuals(p: _Problem, unravel, theta_flat, args):
    theta = unravel(theta_flat)
    w = _whisker(p, theta)
    out = []
    for spec, rec, d in zip(p.specs, theta["recs"], args["recs"], strict=True):
        D, g = _design(p, spec, w, rec, d)
        out.append((D @ rec["c"] + g - d["y"]) * d["weight"])
    if p.static_x_m is not None:
        s = args["static"]
        x, l = p.static_x_m, p.length_m
        compliance = x**2 * (3 * l - x) / 6
        model = theta["static_d0"] + s["force"] * compliance / jnp.exp(theta["log_EI"])
        out.append((model - s["deflection"]) / s["sigma"])
    return jnp.concatenate(out)


# --------------------------------------------------------------------------- results
@dataclass
class Calibration:
    """Outcome of :func:`calibrate`.

    Attributes:
        status: ``"ok"`` or why not (``"not converged"``, ``"non-finite"``, or ``"poor fit"``
            when the model explains little of a recording: see ``warnings``).
        ok: Whether the solver reported success and the covariance is finite.
        params: Reported parameters, name → ``{"value", "std", "source"}`` (``source`` is
            ``"fit"`` or ``"derived"``, the latter with the pin it used).
        correlations: ``{"names": [...], "matrix": [[...]]}`` of the reported parameters.
        fixed: Values taken from the record (prior, geometry, material), name → value.
        note: What the data determine and what came from elsewhere (identifiability).
        diagnostics: RMS residual, reduced χ², residual lag-1 autocorrelation, samples, steps.
        per_recording: Nuisances and residual diagnostics per recording.
        record: The input record with the fitted values written in, and a ``[fit]`` table.
        solver: Solver name.
        curves: Per recording ``(t, y, model)`` in observed units (for plots).
        warnings: What the user should check (one sentence each), e.g. a poor fit.
    """

    status: str
    ok: bool
    params: dict[str, dict]
    correlations: dict[str, Any]
    fixed: dict[str, float]
    note: str
    diagnostics: dict[str, Any]
    per_recording: list[dict]
    record: WhiskerRecord
    solver: str
    curves: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(
        repr=False, default_factory=list
    )
    warnings: list[str] = field(default_factory=list)

    def to_json(self) -> dict:
        """The JSON summary (``whiskerid calibrate --json``)."""
        return {
            "status": self.status,
            "ok": self.ok,
            "solver": self.solver,
            "params": {k: {"value": v["value"], "std": v["std"]} for k, v in self.params.items()},
            "sources": {k: v["source"] for k, v in self.params.items()},
            "fixed": self.fixed,
            "identifiability": self.note,
            "correlations": self.correlations,
            "diagnostics": self.diagnostics,
            "recordings": self.per_recording,
            "warnings": self.warnings,
        }


# --------------------------------------------------------------------------- calibrate
def calibrate(
    record: WhiskerRecord,
    observations: list[Observation] | Observation,
    *,
    static: StaticTest | None = None,
    n_modes: int = 2,
    zeta_per_mode: bool = False,
    pin: str = "auto",
    solver: str = "levenberg-marquardt",
    max_steps: int = 400,
    f1_start_hz: float | None = None,
) -> Calibration:
    """Fit κ (f_1), ζ and the nuisances to one or more recordings (and a static test).

    Args:
        record: The whisker's record: geometry, material, tip mass, sensor, ADC, and the
            nominal values the start grid is centred on.
        observations: Recordings, fitted jointly (shared κ, ζ; own nuisances each).
        static: Optional static test; pins EI, so that ρa (a coil's C) follows from κ.
        n_modes: Modes in the model (frequencies tied by the cantilever's eigenvalues).
        zeta_per_mode: One ζ per mode instead of one for all.
        pin: What fixes EI or C without a static test: ``geometry`` (ρa, so C, from the
            record → EI derived), ``material`` (EI from the record → ρa, C derived), or
            ``auto`` (= geometry).
        solver: ``levenberg-marquardt`` (default), ``dogleg`` or ``gauss-newton``.
        max_steps: Solver step limit.
        f1_start_hz: Override the nominal f_1 the start search is centred on.

    Returns:
        A :class:`Calibration`; never raises on a failed solve (see ``status``).
    """
    obs = [observations] if isinstance(observations, Observation) else list(observations)
    if not obs:
        raise CalibrationError("no recordings to calibrate")
    if pin not in PINS:
        raise CalibrationError(f"pin must be one of {PINS}, not {pin!r}")
    if not 1 <= n_modes <= 10:
        raise CalibrationError(f"n_modes = {n_modes} must be between 1 and 10")
    pin = "geometry" if pin == "auto" else pin
    nominal = record.whisker().with_modes(n_modes)
    rho_a_nom = float(nominal.rho_a)
    problem, args, recs0 = _prepare(record, obs, static, n_modes, zeta_per_mode, rho_a_nom)
    f1_nom = f1_start_hz or float(nominal.natural_frequencies_hz[0])
    zeta_nom = float(np.mean(nominal.zeta))

    # Start: grid over (κ, ζ) with the linear coefficients solved exactly.
    theta0 = _start(problem, args, recs0, obs, nominal, f1_nom, zeta_nom, static)
    flat0, unravel = _ravel(theta0)
    fn = jax.tree_util.Partial(_residuals_entry, problem, unravel)
    res = _fit(fn, flat0, args, solver, max_steps)
    # Weight each block (recording, static test) by its own residual scale, then refit:
    # the blocks are then combined fairly and s² ≈ 1 (a reduced χ²).
    args = _reweight(problem, unravel, res.value, args)
    res = _fit(fn, res.value, args, solver, max_steps)
    cov, s2 = _covariance_jit(fn, res.value, args)
    cov, s2 = np.asarray(cov), float(s2)
    # The solver's own test (steps below rtol 1e-10 of every parameter) can stall at
    # rounding level on long real recordings (timestamps rounded to 1 µs: the same optimum,
    # 400 steps); MINPACK's gradient test says whether the point is stationary anyway.
    gcos = float(_gradient_cosine_jit(fn, res.value, args))
    converged = bool(res.ok) or gcos < GTOL
    ok = converged and bool(np.all(np.isfinite(np.diag(cov))))
    status = "ok" if ok else ("non-finite" if not np.isfinite(float(res.cost)) else "not converged")

    params, corr, fixed, note = _report(
        record, problem, unravel, res.value, cov, pin, static, nominal
    )
    per_rec, curves = _per_recording(problem, unravel, res.value, args, obs)
    resid = np.asarray(fn(res.value, args))
    diagnostics = {
        "rms_residual": [r["rms_residual"] for r in per_rec],
        "reduced_chi2": s2,
        "gradient_cosine": gcos,
        "n_samples": int(sum(o.t.size for o in obs)),
        "n_params": int(res.value.size),
        "steps": int(res.steps),
        "lag1_autocorr": [r["lag1_autocorr"] for r in per_rec],
        "weighted_rms": float(np.sqrt(np.mean(resid**2))),
    }
    warnings = _poor_fit_warnings(per_rec)
    if ok and warnings:
        status = "poor fit"
    out = Calibration(
        status=status,
        ok=ok,
        params=params,
        correlations=corr,
        fixed=fixed,
        note=note,
        diagnostics=diagnostics,
        per_recording=per_rec,
        record=record,
        solver=solver,
        curves=curves,
        warnings=warnings,
    )
    out.record = _updated_record(record, out, pin, static, obs, problem)
    return out


def _residuals_entry(problem, unravel, theta_flat, args):
    return _residuals(problem, unravel, theta_flat, args)


_covariance_jit = eqx.filter_jit(_lsq.covariance)
_gradient_cosine_jit = eqx.filter_jit(_lsq.gradient_cosine)
#: A fit is converged when the solver says so, or when no parameter direction has a cosine
#: with the residuals above this (MINPACK's ``gtol``).
GTOL = 1e-6


@eqx.filter_jit
def _fit_jit(fn, y0, args, solver_name, max_steps):
    return _lsq.least_squares(
        fn, y0, args, solver=_lsq.make_solver(solver_name), max_steps=max_steps
    )


def _fit(fn, y0, args, solver, max_steps):
    if solver not in _lsq.SOLVERS:
        raise CalibrationError(f"solver must be one of {', '.join(_lsq.SOLVERS)}; got {solver!r}")
    return _fit_jit(fn, y0, args, solver, max_steps)


def _prepare(record, obs, static, n_modes, zeta_per_mode, rho_a):
    specs, recs_args, recs0 = [], [], []
    adc = record.adc
    for o in obs:
        forced = "none"
        if o.excitation in ("sine", "base"):
            amplitude_known = o.excitation == "base" or o.hb_m is not None
            forced = "known" if (amplitude_known and o.gain is not None) else "free"
        n_free = 2 * n_modes
        n_cols = (
            2 + n_free + {"none": 0, "known": 0, "free": 2 if o.excitation == "sine" else 1}[forced]
        )
        avg = (
            tuple(float(x) for x in np.asarray(adc.averaging_offsets()))
            if o.observable == "adc"
            else None
        )
        x_m = record.sensor_position_m if o.x_m is None else float(o.x_m)
        if not 0 <= x_m <= record.structure.length_m:
            raise CalibrationError(f"{o.name}: sensor position {x_m} m is not on the beam")
        specs.append(
            _Spec(o.excitation, o.observable, forced, n_cols, x_m, float(o.fb_hz or 0.0), avg)
        )
        t0 = o.t[0]
        y_mean, y_std = float(np.mean(o.y)), float(np.std(o.y))
        if not y_std > 0:
            raise CalibrationError(f"{o.name}: the signal is constant")
        gain = o.gain if o.gain is not None else _nominal_gain(record, o.observable)
        d = {
            "t": jnp.asarray(o.t - t0),
            "y": jnp.asarray((o.y - y_mean) / y_std),
            "weight": jnp.asarray(1.0),
            "scale": jnp.asarray(gain / y_std),
            "hb": jnp.asarray(o.hb_m if o.hb_m is not None else 1e-3),
        }
        if o.excitation == "base":
            d["t_full"] = d["t"]
            d["base_acc"] = jnp.asarray(o.base_acc)
        recs_args.append(d)
        r0 = {"c": jnp.zeros(n_cols)}
        if forced == "known" and o.excitation == "sine":
            r0["tau"] = jnp.asarray(0.0)
        recs0.append(r0)
    static_x = None
    args = {"recs": recs_args}
    if static is not None:
        l = record.structure.length_m
        static_x = l if static.x_m is None else float(static.x_m)
        A = np.stack([np.ones_like(static.force_n), static.force_n], axis=1)
        coef, *_ = np.linalg.lstsq(A, static.deflection_m, rcond=None)
        r = static.deflection_m - A @ coef
        sigma = max(
            float(np.sqrt(np.sum(r**2) / max(r.size - 2, 1))),
            1e-9 * np.abs(static.deflection_m).max(),
        )
        args["static"] = {
            "force": jnp.asarray(static.force_n),
            "deflection": jnp.asarray(static.deflection_m),
            "sigma": jnp.asarray(sigma),
            "fit": coef,
        }
    problem = _Problem(
        specs=tuple(specs),
        n_modes=n_modes,
        zeta_per_mode=zeta_per_mode,
        fit_ei=static is not None,
        length_m=record.structure.length_m,
        rho_a=rho_a,
        tip_mass_kg=record.tip_mass_kg,
        static_x_m=static_x,
    )
    return problem, args, recs0


def _nominal_gain(record, observable):
    """Observed units per physical unit from the record (V/m, codes/m) or 1."""
    g = float(record.hall.gain_v_per_m)
    return {"voltage": g, "adc": g / record.adc.lsb_v}.get(observable, 1.0)


def _kappa_from_f1(nominal: Whisker, f1_hz):
    beta1 = float(nominal.beta[0])
    return (2 * np.pi * np.asarray(f1_hz) * nominal.length_m**2 / beta1**2) ** 2


def _start(problem, args, recs0, obs, nominal, f1_nom, zeta_nom, static):
    """Best (κ, ζ) on a grid seeded by the data, with exact linear coefficients."""
    # f_1 is searched within a factor 1.6 of the nominal: at low sample rates a higher mode
    # can alias onto the first (e.g. f_2 = 645 Hz folds to 45 Hz at 200 Hz), and only the
    # nominal tells these apart; near-ties are broken towards the nominal below.
    lo, hi = f1_nom / 1.6, f1_nom * 1.6
    f_cands = list(f1_nom * np.geomspace(1 / 1.6, 1.6, 25))
    z_cands = [zeta_nom * k for k in (0.25, 0.5, 1.0, 2.0, 4.0)]
    for o in obs:
        if o.excitation != "decay":
            continue
        # Both windows: a pluck that dies out within the first few percent of the record is
        # below the noise in the Hann-windowed spectrum (the start then rested on the grid
        # alone and picked an aliased higher mode in 5 of 200 seeded trials).
        yc = o.y - np.median(o.y)
        peaks, rate = spectral_peaks(o.t, yc)
        peaks = peaks + spectral_peaks(o.t, yc, window="none")[0]
        for fp in peaks:
            f_true = unalias(fp, rate, f1_nom)
            if not lo <= f_true <= hi:
                continue
            f_cands.append(f_true)
            z = envelope_zeta(o.t, o.y, fp, f_true)
            if z is not None:
                z_cands.append(z)
    z_cands = np.clip(np.unique(np.round(z_cands, 6)), 1e-4, 0.5)
    f_cands = np.asarray(f_cands)
    grid_f = np.repeat(f_cands, z_cands.size)
    grid_z = np.tile(z_cands, f_cands.size)
    # Profile on at most ~6000 samples per recording (every k-th sample: the model is
    # evaluated at the same instants, so decimation aliases model and data alike).
    sub = []
    for d in args["recs"]:
        step = max(1, int(np.ceil(d["t"].shape[0] / _MAX_PROFILE_SAMPLES)))
        sub.append(step)
    log_kappa = np.log(_kappa_from_f1(nominal, grid_f))
    zeta_u = np.asarray(_lsq.from_interval(jnp.asarray(grid_z), 0.0, ZETA_MAX))
    log_ei0 = math.log(float(nominal.EI))
    # Pad the grid to a multiple of 64 points: its length varies with the data, and every
    # new length would compile the grid again (seconds, against milliseconds to run it).
    n_grid = grid_f.size
    pad = -n_grid % 64
    costs = np.asarray(
        _profile_grid(
            problem,
            args,
            tuple(sub),
            jnp.asarray(np.pad(log_kappa, (0, pad), mode="edge")),
            jnp.asarray(np.pad(zeta_u, (0, pad), mode="edge")),
            jnp.asarray(log_ei0),
        )
    )[:n_grid]
    costs = np.where(np.isfinite(costs), costs, np.inf)
    # Among (near-)equally good candidates take the one closest to the nominal f_1.
    near = np.flatnonzero(costs <= costs.min() * 1.02 + 1e-300)
    best = int(near[np.argmin(np.abs(np.log(grid_f[near] / f1_nom)))])
    nz = problem.n_modes if problem.zeta_per_mode else 1
    theta = {
        "log_kappa": jnp.asarray(log_kappa[best]),
        "zeta_u": jnp.full(nz, zeta_u[best])
        if problem.zeta_per_mode
        else jnp.asarray(zeta_u[best]),
        "recs": [],
    }
    if problem.fit_ei:
        fit = args["static"]["fit"]
        x, l = problem.static_x_m, problem.length_m
        ei = (x**2 * (3 * l - x) / 6) / fit[1] if fit[1] > 0 else float(nominal.EI)
        theta["log_EI"] = jnp.asarray(math.log(ei))
        theta["static_d0"] = jnp.asarray(float(fit[0]))
    w = _whisker(problem, theta)
    for spec, r0, d in zip(problem.specs, recs0, args["recs"], strict=True):
        D, _ = _design_eval(problem, spec, w, r0, d, profile=True)
        coef = np.linalg.lstsq(np.asarray(D), np.asarray(d["y"]), rcond=None)[0]
        r = dict(r0)
        if spec.forced == "known" and spec.excitation == "sine":
            # Coefficients of the unit-RMS columns W(t), W(t − T/4): c1 W(t) + c2 W(t − T/4)
            # = R W(t − ψ/ω_b) with ψ = atan2(c2, c1).
            c1, c2 = coef[-2:]
            r["tau"] = jnp.asarray(math.atan2(c2, c1) / (2 * np.pi * spec.fb_hz))
            coef = coef[:-2]
        elif spec.forced == "known":  # base motion: its free column only served the start
            coef = coef[:-1]
        r["c"] = jnp.asarray(coef)
        theta["recs"].append(r)
    return theta


@eqx.filter_jit
def _profile_grid(problem, args, steps, log_kappa, zeta_u, log_ei):
    return jax.lax.map(
        lambda xz: _profile_cost(problem, args, steps, xz[0], xz[1], log_ei), (log_kappa, zeta_u)
    )


def _profile_cost(problem, args, steps, log_kappa, zeta_u, log_ei):
    theta = {"log_kappa": log_kappa, "zeta_u": zeta_u, "log_EI": log_ei, "recs": None}
    w = _whisker(problem, theta)
    total = 0.0
    for spec, d, step in zip(problem.specs, args["recs"], steps, strict=True):
        dd = dict(d)
        if spec.excitation != "base":  # base motion needs every step of its input
            dd = {k: (v[::step] if k in ("t", "y") else v) for k, v in d.items()}
        D, _ = _design(problem, spec, w, {"tau": 0.0}, dd, profile=True)
        # Normal equations on unit-norm columns (a tiny ridge for a vanished column):
        # jnp.linalg.lstsq here (an SVD) made XLA re-evaluate the design several times,
        # 20 ms per grid point instead of 1 ms.
        norm = jnp.sqrt(jnp.sum(D**2, axis=0)) + 1e-300
        Dn = D / norm
        gram = Dn.T @ Dn + 1e-12 * jnp.eye(D.shape[1])
        k = D.shape[1]
        L = _lsq.cholesky_small([[gram[i, j] for j in range(i + 1)] for i in range(k)])
        coef = jnp.stack(_lsq.cho_solve_small(L, list(Dn.T @ dd["y"])))
        r = Dn @ coef - dd["y"]
        total = total + jnp.mean(r**2)
    return total


def _reweight(problem, unravel, flat, args):
    theta = unravel(flat)
    w = _whisker(problem, theta)
    new = {"recs": []}
    for spec, rec, d in zip(problem.specs, theta["recs"], args["recs"], strict=True):
        D, g = _design_eval(problem, spec, w, rec, d)
        r = D @ rec["c"] + g - d["y"]
        dof = max(r.size - D.shape[1], 1)
        sigma = float(jnp.sqrt(jnp.sum(r**2) / dof))
        new["recs"].append({**d, "weight": jnp.asarray(1.0 / max(sigma, 1e-12))})
    if "static" in args:
        new["static"] = args["static"]
    return new


# --------------------------------------------------------------------------- reporting
def _derived_fn(problem, unravel, pin, has_static, ei_nominal, structure):
    """θ ↦ dict of reported scalars (for the delta method)."""

    def fn(flat):
        theta = unravel(flat)
        w = _whisker(problem, theta)
        out = {"f1_hz": w.natural_frequencies_hz[0], "kappa": w.kappa}
        for i in range(1, problem.n_modes):
            out[f"f{i + 1}_hz"] = w.natural_frequencies_hz[i]
        if problem.zeta_per_mode:
            out["zeta"] = w.zeta[0]
            for i in range(problem.n_modes):
                out[f"zeta_{i + 1}"] = w.zeta[i]
        else:
            out["zeta"] = w.zeta[0]
        if has_static:
            out["EI"] = w.EI
            out["rho_a"] = w.rho_a
            if isinstance(structure, CoilSpring):
                out["C"] = w.rho_a / (structure.wire_density_kg_m3 * structure.wire_area_m2)
        elif pin == "geometry":
            out["EI"] = w.EI  # = κ ρa with ρa from the record
        else:  # material: EI fixed, ρa (and C) follow from κ
            rho_a = ei_nominal / w.kappa
            out["rho_a"] = rho_a
            if isinstance(structure, CoilSpring):
                out["C"] = rho_a / (structure.wire_density_kg_m3 * structure.wire_area_m2)
        if "EI" in out and isinstance(structure, UniformBeam) and not has_static:
            out["E"] = out["EI"] / structure.second_moment_m4
        if "EI" in out and isinstance(structure, CoilSpring) and (has_static or pin == "geometry"):
            out["G_w"] = out["EI"] / structure.polar_moment_m4
        return jnp.stack(list(out.values())), tuple(out)

    return fn


@eqx.filter_jit
def _derived_with_jacobian(problem, unravel, pin, has_static, ei_nominal, structure, flat):
    fn = _derived_fn(problem, unravel, pin, has_static, ei_nominal, structure)
    names = fn(flat)[1]
    return fn(flat)[0], jax.jacfwd(lambda g: fn(g)[0])(flat), names


def _report(record, problem, unravel, flat, cov, pin, static, nominal):
    structure = record.structure
    values, jac, names = _derived_with_jacobian(
        problem, unravel, pin, static is not None, float(nominal.EI), structure, flat
    )
    dcov = np.asarray(jac) @ cov @ np.asarray(jac).T
    std = np.sqrt(np.maximum(np.diag(dcov), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = dcov / np.outer(std, std)
    pinned = {"geometry": "rho_a", "material": "EI"}[pin]
    params = {}
    for i, name in enumerate(names):
        source = "fit"
        if static is not None and name in ("EI", "G_w"):
            source = "fit (static test)"
        elif name in ("EI", "C", "rho_a", "E", "G_w"):
            source = (
                "derived from kappa and the static test"
                if static is not None
                else f"derived from kappa and {pinned} ({pin})"
            )
        params[name] = {"value": float(values[i]), "std": float(std[i]), "source": source}
    fixed = {"length_m": float(nominal.length_m), "tip_mass_kg": float(nominal.tip_mass_kg)}
    coil = isinstance(structure, CoilSpring)
    if static is None:
        if pin == "geometry":
            fixed["rho_a"] = float(nominal.rho_a)
            if coil:
                fixed["C"] = structure.coil_factor
        else:
            fixed["EI"] = float(nominal.EI)
    what = "f_1 (so kappa = EI/(rho a)) and zeta"
    if static is not None:
        note = (
            f"The vibration data determine {what}; the static test determines EI, so rho a"
            + (" and the coil factor C follow" if coil else " follows")
            + " from EI/kappa: both are reported as fitted."
        )
    elif pin == "geometry":
        note = (
            f"The vibration data determine only {what}. EI is derived as kappa * rho a with rho a "
            + (
                f"from the coil geometry (C = {structure.coil_factor:.4g} fixed, not fitted)"
                if coil
                else "from the section and density of the record"
            )
            + "; EI and C are not both identified without a static test or a material prior."
        )
    else:
        note = (
            f"The vibration data determine only {what}. EI is fixed at the record's material value "
            f"({float(nominal.EI):.4g} N m^2); rho a"
            + (" and C are" if coil else " is")
            + " derived from EI/kappa. EI and C are not both identified."
        )
    if nominal.tip_mass_kg > 0:
        note += (
            f" With the tip mass ({float(nominal.tip_mass_kg):.4g} kg) the mode ratios depend"
            " weakly on mu = M_t/(rho a l); mu was taken from the record."
            if static is None
            else ""
        )
    correlations = {"names": list(names), "matrix": np.round(np.nan_to_num(corr), 6).tolist()}
    return params, correlations, fixed, note


#: A recording fitted below this SNR (signal RMS over residual RMS, in dB) is a poor fit:
#: the model explains less than half of the signal's variance.
POOR_FIT_SNR_DB = 3.0


def _poor_fit_warnings(per_rec: list[dict]) -> list[str]:
    """A warning per recording that the fitted model leaves mostly unexplained."""
    return [
        f"poor fit of {r['name']}: the model explains little of the signal (SNR "
        f"{r['snr_db']:.3g} dB); check the time units (seconds), the observable and the "
        "excitation"
        for r in per_rec
        if not r["snr_db"] >= POOR_FIT_SNR_DB
    ]


def _per_recording(problem, unravel, flat, args, obs):
    theta = unravel(flat)
    w = _whisker(problem, theta)
    out, curves = [], []
    for spec, rec, d, o in zip(problem.specs, theta["recs"], args["recs"], obs, strict=True):
        D, g = _design_eval(problem, spec, w, rec, d)
        model_n = np.asarray(D @ rec["c"] + g)
        y_mean, y_std = float(np.mean(o.y)), float(np.std(o.y))
        model = model_n * y_std + y_mean
        r = o.y - model
        rc = r - r.mean()
        lag1 = float(np.sum(rc[1:] * rc[:-1]) / max(np.sum(rc**2), 1e-300))
        c = np.asarray(rec["c"])
        nm = problem.n_modes
        amps = np.hypot(c[2 : 2 + nm], c[2 + nm : 2 + 2 * nm]) * y_std
        info = {
            "name": o.name,
            "source": o.source,
            "excitation": o.excitation,
            "observable": o.observable,
            "n_samples": int(o.t.size),
            "t_start_s": float(o.t[0]),
            "rms_residual": float(np.sqrt(np.mean(r**2))),
            "rms_signal": y_std,
            "snr_db": float(20 * np.log10(y_std / max(np.sqrt(np.mean(r**2)), 1e-300))),
            "lag1_autocorr": lag1,
            "offset": float(c[0] * y_std + y_mean),
            "drift_per_s": float(c[1] * y_std / max(o.t[-1] - o.t[0], 1e-12)),
            "modal_amplitudes": [float(a) for a in amps],
        }
        if spec.excitation == "sine" and spec.forced == "known":
            info["start_time_s"] = float(rec["tau"])
        if spec.forced == "free":
            # amplitude of the forced response in observed units, relative to the nominal
            k = c[2 + 2 * nm :]
            info["forced_scale"] = float(np.hypot(*k)) if k.size == 2 else float(k[0])
            info["note"] = "gain and excitation amplitude appear only as a product"
        out.append(info)
        curves.append((o.t, o.y, model))
    return out, curves


def _updated_record(record, cal: Calibration, pin, static, obs, problem):
    from dataclasses import replace

    from .._version import __version__

    p = cal.params
    n = problem.n_modes
    if problem.zeta_per_mode:
        zeta = tuple(float(p[f"zeta_{i + 1}"]["value"]) for i in range(n))
        if record.n_modes > n:
            zeta = zeta + (zeta[-1],) * (record.n_modes - n)
    else:
        zeta = float(p["zeta"]["value"])
    structure = record.structure
    if cal.ok and "EI" in p and p["EI"]["source"] != "fit":
        ei = p["EI"]["value"]
        if isinstance(structure, UniformBeam):
            structure = replace(structure, youngs_modulus_pa=ei / structure.second_moment_m4)
        else:
            structure = replace(structure, shear_modulus_pa=ei / structure.polar_moment_m4)
    files = []
    for o in obs:
        if o.source and Path(o.source).exists():
            files.append({"path": str(o.source), "sha256": sha256_of(o.source), "name": o.name})
    if static is not None and static.source and Path(static.source).exists():
        files.append(
            {"path": static.source, "sha256": sha256_of(static.source), "name": "static test"}
        )
    import datetime

    fit = {
        "status": cal.status,
        "solver": cal.solver,
        "n_modes": n,
        "zeta_per_mode": problem.zeta_per_mode,
        "pin": "static test" if static is not None else pin,
        "identifiability": cal.note,
        "params": {
            k: {"value": v["value"], "std": v["std"], "source": v["source"]} for k, v in p.items()
        },
        "fixed": cal.fixed,
        "correlations": cal.correlations,
        "rms_residual": cal.diagnostics["rms_residual"],
        "reduced_chi2": cal.diagnostics["reduced_chi2"],
        "n_samples": cal.diagnostics["n_samples"],
        "recordings": [{k: v for k, v in r.items() if v is not None} for r in cal.per_recording],
        "data_files": files,
        "whiskerid_version": __version__,
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }
    if cal.warnings:
        fit["warnings"] = list(cal.warnings)
    extra = dict(record.extra)
    extra["fit"] = fit
    desc = record.description
    return record.replace(structure=structure, zeta=zeta, extra=extra, description=desc)


# --------------------------------------------------------------------------- windows
class WindowFits(eqx.Module):
    """Per-window damped-oscillation fits (leading axis: windows).

    Attributes:
        damped_frequency_hz: Fitted damped frequency ``f_d`` (Hz), as seen at the samples
            (an aliased frequency stays aliased).
        zeta: Damping ratio of the fitted oscillation.
        amplitude: Oscillation amplitude at the window's first sample (signal units).
        offset: Mean level (signal units).
        rms_residual: RMS of the residuals (signal units).
        ok: Whether the fit converged on finite data.
    """

    damped_frequency_hz: Float[Array, " windows"]
    zeta: Float[Array, " windows"]
    amplitude: Float[Array, " windows"]
    offset: Float[Array, " windows"]
    rms_residual: Float[Array, " windows"]
    ok: jax.Array


def _window_residuals(u, args):
    t, y = args
    fd = jnp.exp(u[0])
    zeta = _lsq.to_interval(u[1], 0.0, ZETA_MAX)
    wd = 2 * jnp.pi * fd
    sigma = zeta * wd / jnp.sqrt(1 - zeta**2)
    e = jnp.exp(-sigma * t)
    return u[4] + e * (u[2] * jnp.cos(wd * t) + u[3] * jnp.sin(wd * t)) - y


def window_model_residuals(u, args):
    """Residuals of the damped-oscillation window model, ``fn(params, (t, y))``.

    ``u = [log f_d, logit-ζ, a, b, offset]``; the model is
    ``offset + e^{−σt}(a cos ω_d t + b sin ω_d t)`` with ``σ = ζ ω_d/√(1−ζ²)``.
    Exposed for benchmarks and peers (SciPy, lmfit) that fit the same model.
    """
    return _window_residuals(u, args)


def window_start(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Start values ``u`` for :func:`window_model_residuals` from the data, batched.

    The better of :func:`_window_candidates` (smaller residual), with the linear
    coefficients ``(a, b, offset)`` solved by least squares there (variable projection).

    Returns:
        ``u = [log f_d, logit ζ, a, b, offset]`` per window, shape ``(windows, 5)``.
    """
    t = np.atleast_2d(np.asarray(t, dtype=float))
    y = np.atleast_2d(np.asarray(y, dtype=float))
    t = np.broadcast_to(t, y.shape)
    t = t - t[:, :1]
    st = _vp_best(jnp.asarray(_window_candidates(t, y)), jnp.asarray(t), jnp.asarray(y))
    return np.concatenate([np.asarray(st["u"]), np.asarray(st["coef"])], axis=1)


def _window_candidates(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Candidate ``(log f_d, logit ζ)`` per window (NumPy), shape ``(2, windows, 2)``.

    The frequency is the spectral peak (zero-padded ×4, parabolic sub-bin interpolation)
    once with a Hann window and once without: the Hann window suits steady oscillations but
    all but erases a decay that is over within the first tenth of the window, which the
    plain spectrum still sees. ζ from the RMS ratio of the first two quarters (logarithmic
    decrement; later quarters may hold only noise).
    """
    n, m = y.shape
    rate = 1.0 / np.median(np.diff(t, axis=1), axis=1)
    yc = y - y.mean(axis=1, keepdims=True)
    quarter = m // 4
    r1 = np.sqrt(np.mean(yc[:, :quarter] ** 2, axis=1))
    r2 = np.sqrt(np.mean(yc[:, quarter : 2 * quarter] ** 2, axis=1))
    dt_quarter = t[:, quarter] - t[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma = np.log(r1 / r2) / dt_quarter
    out = np.zeros((2, n, 2))
    for k, taper in enumerate((np.hanning(m), np.ones(m))):
        fd = _spectral_peak(yc * taper, rate)
        zeta = np.clip(np.nan_to_num(sigma / (2 * np.pi * fd), nan=0.02), 0.003, 0.5)
        out[k, :, 0] = np.log(fd)
        out[k, :, 1] = np.log(zeta / ZETA_MAX) - np.log1p(-zeta / ZETA_MAX)
    return out


def _spectral_peak(x: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """Largest spectral peak per row (Hz): zero-padded ×4, parabolic in log amplitude."""
    n, m = x.shape
    nfft = 4 * m
    spec = np.abs(np.fft.rfft(x, n=nfft, axis=1))
    spec[:, 0] = 0.0
    k = np.clip(np.argmax(spec, axis=1), 1, spec.shape[1] - 2)
    rows = np.arange(n)
    lo, mid, hi = (np.log(np.maximum(spec[rows, k + s], 1e-300)) for s in (-1, 0, 1))
    denom = lo - 2 * mid + hi
    shift = np.where(denom != 0, 0.5 * (lo - hi) / np.where(denom == 0, 1, denom), 0.0)
    return np.maximum((k + shift) * rate / nfft, rate / m)


# Variable projection. The window model is linear in (a, b, offset); only u = (log f_d,
# logit ζ) is nonlinear. Each evaluation solves the 3×3 linear least-squares problem exactly,
# so Levenberg–Marquardt runs on two parameters (Kaufman's Jacobian) and needs few steps
# from the spectral start. The functions below handle one window (samples on the last axis)
# and are ``vmap``-ed over windows; all small solves are unrolled (``_lsq.cholesky_small``)
# so that every operation is a vector operation across windows.
def _vp_eval(u, t, y):
    """One window at ``u = (log f_d, logit ζ)``: exact linear coefficients, residuals, cost."""
    wd = 2 * jnp.pi * jnp.exp(u[0])
    zeta = _lsq.to_interval(u[1], 0.0, ZETA_MAX)
    sigma = zeta * wd / jnp.sqrt(1 - zeta**2)
    e = jnp.exp(-sigma * t)
    c = e * jnp.cos(wd * t)
    s = e * jnp.sin(wd * t)
    m = jnp.asarray(t.shape[-1], dtype=t.dtype)
    gcc, gss = jnp.sum(c * c), jnp.sum(s * s)
    # A tiny ridge keeps the Gram matrix definite when sin ω_d t vanishes at every sample
    # (ω_d at the Nyquist frequency) or the oscillation has decayed to nothing.
    ridge = 1e-12 * (gcc + gss + m)
    gram = [[gcc + ridge], [jnp.sum(c * s), gss + ridge], [jnp.sum(c), jnp.sum(s), m + ridge]]
    L = _lsq.cholesky_small(gram)
    a, b, off = _lsq.cho_solve_small(L, [jnp.sum(c * y), jnp.sum(s * y), jnp.sum(y)])
    r = a * c + b * s + off - y
    return {"u": u, "c": c, "s": s, "L": L, "coef": jnp.stack([a, b, off]), "r": r,
            "cost": 0.5 * jnp.sum(r * r), "wd": wd, "zeta": zeta, "sigma": sigma}  # fmt: skip


@jax.jit
def _vp_best(cands, t, y):
    """The candidate ``u`` (leading axis) with the smaller residual per window, evaluated."""
    evaluate = jax.vmap(_vp_eval)
    best = evaluate(cands[0], t, y)
    for u in cands[1:]:
        new = evaluate(u, t, y)
        take = new["cost"] < best["cost"]
        best = jax.tree_util.tree_map(lambda x, z, m=take: _where_lane(m, z, x), best, new)
    return best


def _where_lane(mask, x, y):
    """``where(mask, x, y)`` with ``mask`` per window broadcast over trailing axes."""
    return jnp.where(mask.reshape(mask.shape + (1,) * (x.ndim - mask.ndim)), x, y)


def _vp_normal(st, t):
    """Gauss–Newton normal equations in ``u`` (Kaufman's variable-projection Jacobian).

    Returns ``(H, g, gradient test)``: the 2×2 ``JᵀJ`` (nested lists), ``Jᵀr``, and the
    largest cosine between ``r`` and a column of ``J`` (MINPACK's ``gtol`` measure).
    """
    a, b, _ = st["coef"]
    c, s, r = st["c"], st["s"], st["r"]
    wd, zeta, sigma = st["wd"], st["zeta"], st["sigma"]
    p = a * c + b * s  # the oscillation e^{−σt}(a cos + b sin)
    q = b * c - a * s  # ∂p/∂ω_d = t q,  ∂p/∂σ = −t p
    # ∂ω_d/∂u₀ = ω_d, ∂σ/∂u₀ = σ (ζ fixed); ∂σ/∂u₁ = ω_d ζ(1 − ζ/ζmax)/(1 − ζ²)^{3/2}
    ds_du1 = wd * zeta * (1 - zeta / ZETA_MAX) / (1 - zeta**2) ** 1.5
    d0 = t * (wd * q - sigma * p)
    d1 = -ds_du1 * t * p
    # J = (I − P_B) D with P_B the projector on the linear columns B = [c, s, 1]:
    # JᵀJ = DᵀD − (BᵀD)ᵀ (BᵀB)⁻¹ BᵀD, and Jᵀr = Dᵀr because r ⟂ B at the exact coefficients.
    bd0 = [jnp.sum(c * d0), jnp.sum(s * d0), jnp.sum(d0)]
    bd1 = [jnp.sum(c * d1), jnp.sum(s * d1), jnp.sum(d1)]
    x0 = _lsq.cho_solve_small(st["L"], bd0)
    x1 = _lsq.cho_solve_small(st["L"], bd1)
    h00 = jnp.sum(d0 * d0) - sum(i * j for i, j in zip(bd0, x0, strict=True))
    h01 = jnp.sum(d0 * d1) - sum(i * j for i, j in zip(bd0, x1, strict=True))
    h11 = jnp.sum(d1 * d1) - sum(i * j for i, j in zip(bd1, x1, strict=True))
    g0, g1 = jnp.sum(d0 * r), jnp.sum(d1 * r)
    rn = jnp.sqrt(2 * st["cost"])
    tiny = jnp.finfo(t.dtype).tiny
    gtest = jnp.maximum(
        jnp.abs(g0) / jnp.maximum(jnp.sqrt(jnp.abs(h00)) * rn, tiny),
        jnp.abs(g1) / jnp.maximum(jnp.sqrt(jnp.abs(h11)) * rn, tiny),
    )
    return (h00, h01, h11), (g0, g1), gtest


def _vp_trial(st, lam, t):
    """The damped Gauss–Newton step from ``st`` (Marquardt's diagonal scaling)."""
    (h00, h01, h11), (g0, g1), gtest = _vp_normal(st, t)
    a00, a11 = h00 * (1 + lam), h11 * (1 + lam)
    det = a00 * a11 - h01 * h01
    du0 = -(a11 * g0 - h01 * g1) / det
    du1 = -(a00 * g1 - h01 * g0) / det
    return st["u"] + jnp.stack([du0, du1]), gtest


@functools.partial(jax.jit, static_argnames=("max_steps",))
def _vp_fit(u0, t, y, *, max_steps: int = 40, rtol: float = 1e-10, gtol: float = 1e-6):
    """Variable-projection Levenberg–Marquardt over a batch of windows (leading axis).

    ``u0``: start values ``(log f_d, logit ζ)``, shape ``(windows, 2)``, or candidates of
    shape ``(k, windows, 2)`` of which each window starts from its best.

    All windows step together in one loop (no per-window ``while``) until every window has
    converged (relative cost change below ``rtol`` or gradient test below ``gtol``) or
    ``max_steps``. A window whose trial is worse or not finite keeps its point and raises
    its damping (×4; ÷3 after a success), so a NaN window only stalls itself.

    Returns:
        ``(u, coef, cost, ok, steps)``: nonlinear parameters ``(log f_d, logit ζ)``,
        linear ones ``(a, b, offset)``, half the residual sum of squares, convergence per
        window (finite, and MINPACK's gradient test below :data:`WINDOW_GTOL` or a residual
        at rounding level) and the number of loop steps taken.
    """
    evaluate = jax.vmap(_vp_eval)
    trial = jax.vmap(_vp_trial)
    st = _vp_best(u0[None] if u0.ndim == 2 else u0, t, y)
    n = t.shape[0]

    def cond(carry):
        k, _, _, done, _ = carry
        return (k < max_steps) & ~jnp.all(done)

    def body(carry):
        k, st, lam, done, _ = carry
        u_new, gtest = trial(st, lam, t)
        new = evaluate(u_new, t, y)
        better = jnp.isfinite(new["cost"]) & (new["cost"] < st["cost"]) & ~done
        small = st["cost"] - new["cost"] <= rtol * st["cost"]
        done = done | (better & small) | (gtest < gtol) | ~jnp.isfinite(st["cost"])
        st = jax.tree_util.tree_map(lambda x, z: _where_lane(better, z, x), st, new)
        lam = jnp.where(better, lam / 3, lam * 4)
        return k + 1, st, lam, done | (lam > 1e16), gtest

    init = (0, st, jnp.full(n, 1e-3), jnp.zeros(n, bool), jnp.full(n, jnp.inf))
    k, st, _, _, _ = jax.lax.while_loop(cond, body, init)
    _, gtest = trial(st, jnp.zeros(n), t)
    # Converged: residuals orthogonal to the Jacobian, or (noise-free data) residuals at
    # rounding level, where that cosine is a ratio of rounding errors.
    exact = st["cost"] <= 0.5 * 1e-16 * jnp.sum(y**2, axis=-1)
    ok = jnp.isfinite(st["cost"]) & jnp.all(jnp.isfinite(st["u"]), axis=-1)
    ok &= (gtest < WINDOW_GTOL) | exact
    return st["u"], st["coef"], st["cost"], ok, k


def fit_windows(
    windows: Float[np.ndarray, "windows samples"],
    *,
    rate_hz: float | None = None,
    t: np.ndarray | None = None,
    solver: str = "levenberg-marquardt",
    max_steps: int = 100,
) -> WindowFits:
    """Fit a damped oscillation to each window at once (``vmap``; for per-window features).

    Model per window: ``offset + A e^{−ζω t} cos(ω_d t + φ)`` (one mode), evaluated at the
    given sample times. Start values come from each window's spectral peak and RMS decay
    (:func:`window_start`). The default solver is Levenberg–Marquardt by variable
    projection: the amplitude terms and offset are solved exactly at every step, so only
    ``log f_d`` and ``logit ζ`` are iterated, all windows together in one compiled loop
    (:func:`_vp_fit`; for 1000 windows of 200 samples the solve is 25–60× faster than a
    SciPy loop from the same starts, the whole call 15–35×: ``benchmarks/calibrate.py``).
    A window of NaNs or garbage gets ``ok = False`` and leaves the others untouched.

    Args:
        windows: Samples, shape ``(windows, samples)``.
        rate_hz: Uniform sample rate (Hz); or give ``t``.
        t: Sample times (s), shape ``(samples,)`` shared or ``(windows, samples)``.
        solver: ``levenberg-marquardt`` (variable projection, default), or an optimistix
            solver on all five parameters, ``vmap``-ed: ``optimistix-lm``, ``dogleg``,
            ``gauss-newton`` (slower: a vmapped adaptive solver runs every window until the
            slowest stops).
        max_steps: Step limit per window.

    Returns:
        :class:`WindowFits` with one entry per window. ``ok`` needs finite data and a
        converged fit: the residuals orthogonal to every Jacobian column (cosine below
        ``1e-4``, MINPACK's gradient test) for the default solver, optimistix's own status
        for the others.
    """
    y = np.asarray(windows, dtype=float)
    if y.ndim != 2 or y.shape[1] < 8:
        raise CalibrationError(f"windows must have shape (windows, samples >= 8), got {y.shape}")
    n, m = y.shape
    if t is None:
        if rate_hz is None or not rate_hz > 0:
            raise CalibrationError("fit_windows needs rate_hz or t")
        t = np.arange(m) / float(rate_hz)
    t = np.broadcast_to(np.asarray(t, dtype=float), (n, m))
    t = t - t[:, :1]
    finite = np.all(np.isfinite(y), axis=1) & np.all(np.isfinite(t), axis=1)
    finite &= np.all(np.diff(t, axis=1) > 0, axis=1)
    y_safe = np.where(finite[:, None], y, 0.0)
    t_safe = np.where(finite[:, None], t, np.arange(m)[None, :] / 100.0)
    mean = y_safe.mean(axis=1, keepdims=True)
    std = y_safe.std(axis=1, keepdims=True)
    std = np.where(std > 0, std, 1.0)
    yn = (y_safe - mean) / std
    data = (jnp.asarray(t_safe), jnp.asarray(yn))
    cands = _window_candidates(t_safe, yn)
    if solver == "levenberg-marquardt":
        u_nl, coef, cost, ok_fit, _ = _vp_fit(jnp.asarray(cands), *data, max_steps=max_steps)
        u = np.concatenate([np.asarray(u_nl), np.asarray(coef)], axis=1)
    else:
        names = {"optimistix-lm": "levenberg-marquardt", "dogleg": "dogleg"}
        names["gauss-newton"] = "gauss-newton"
        if solver not in names:
            raise CalibrationError(
                "solver must be levenberg-marquardt, optimistix-lm, dogleg or gauss-newton; "
                f"got {solver!r}"
            )
        # rtol 1e-8 is ample for features and saves steps of the slowest lane
        u0 = window_start(t_safe, yn)
        res = _lsq.batch_least_squares(
            _window_residuals,
            jnp.asarray(u0),
            data,
            solver=_lsq.make_solver(names[solver], rtol=1e-8, atol=1e-10),
            max_steps=max_steps,
        )
        u, ok_fit, cost = np.asarray(res.value), np.asarray(res.ok), res.cost
    u = np.asarray(u)
    zeta = np.asarray(_lsq.to_interval(jnp.asarray(u[:, 1]), 0.0, ZETA_MAX))
    rms = np.sqrt(2 * np.asarray(cost) / m) * std[:, 0]
    ok = np.asarray(ok_fit) & finite & np.all(np.isfinite(u), axis=1)
    nan = np.where(ok, 1.0, np.nan)
    return WindowFits(
        damped_frequency_hz=jnp.asarray(np.exp(u[:, 0]) * nan),
        zeta=jnp.asarray(zeta * nan),
        amplitude=jnp.asarray(np.hypot(u[:, 2], u[:, 3]) * std[:, 0] * nan),
        offset=jnp.asarray((u[:, 4] * std[:, 0] + mean[:, 0]) * nan),
        rms_residual=jnp.asarray(rms * nan),
        ok=jnp.asarray(ok),
    )
