"""Is a fit's residual larger than the sensor's own noise? A test against an independent floor.

A model that misses part of the signal (an amplitude-dependent frequency or damping, a mode
left out, a decay started in the wrong place) leaves residuals larger than the noise. Their
size alone cannot tell: the fit's residual scale is what the 1σ are built from. A stretch of
the same recording where the whisker is still (the hold before the release, or the rest after
the decay) measures the noise without any model of the decay.

**The floor.** On the quiet stretch ``q_1 … q_m`` the noise variance is estimated from second
differences, ``σ̂² = Σ(Δ²q)²/(6(m−2))``: a held deflection's offset, slow drift and a hand's
tremor (8–12 Hz, suppressed by ``(2 − 2cos 2πf/f_s)² ≤ 0.01`` at 200 Hz) do not enter it, and
what little does makes the floor larger, never smaller. Second differences beyond :data:`TRIM`
robust standard deviations (the kinks of the hand's ramp, a knock) are left out; the stretch
ends one period of the decay's frequency before its first sample (a tap's impact). For
Gaussian noise the estimate has ``Var σ̂² = 2·70σ⁴/(36(m−2))`` (the second differences'
autocovariances are ``6σ², −4σ², σ²``),
the variance of a χ² estimate with ``ν = 36(m−2)/70 ≈ 0.51(m−2)`` degrees of freedom. Samples
quantised to a step ``q`` (ADC codes, or volts on a lattice of codes, detected from the
samples) add the rounding of a moving signal, ``q²/12``, to what the decay's residuals can
hold; a quiet stretch inside one code shows none of it, so the floor is ``σ̂² + q²/12`` (when
the noise spans many codes this counts the rounding twice: conservative).

**The test.** The recording's residual variance ``s² = RSS/(n − p)`` (``p`` its share of the
fitted parameters) against the floor: under a model that describes the decay,
``F = s²/σ̂²_floor`` is at most an ``F(n − p, ν)`` variable, so ``P(F > F_{1−α}) ≤ α`` with
``α =`` :data:`P_FALSE` per recording, the floor's own uncertainty included through ``ν``.
A rejection also needs the excess to matter, a residual RMS at least :data:`MIN_RATIO` times
the floor's (what the model misses is then at least ``√(MIN_RATIO² − 1) ≈ 1.1`` times the
noise; smaller misfits, such as the higher modes a two-mode fit leaves out of a flick, pass). It is
reported as the check ``above-noise-floor``. Recordings without a quiet stretch of
:data:`MIN_QUIET` samples are not tested (``diagnostics["noise_floor"]`` says so).
"""

import numpy as np

from .._numerics import f_sf

#: False-alarm probability of the test per recording, under a model that describes the decay.
P_FALSE = 1e-4
#: A rejection also needs the residual RMS at least this many times the floor's.
MIN_RATIO = 1.5
#: Fewest quiet samples the floor is measured on.
MIN_QUIET = 32
#: Samples left out next to the release (the hand lets go between two samples).
MARGIN = 2
#: Second differences of the quiet stretch beyond this many robust σ are not noise.
TRIM = 5.0


def quiet_stretch(t, y, decays, k: int) -> np.ndarray | None:
    """The quiet samples of decay ``k`` of a recording: the hold before its release (after
    the previous decay's end, and ending one period of its frequency plus :data:`MARGIN`
    samples before its first sample, so that a tap's impact stays out), else, for the last
    decay, the samples after its end; None when neither has :data:`MIN_QUIET` samples. A
    decay whose release is not seen (the recording starts in it, or it starts after clipped
    samples) has no stretch before it."""
    t, y = np.asarray(t), np.asarray(y)
    d = decays[k]
    dt = float(np.median(np.diff(t)))
    period = int(np.ceil(1.0 / max(d.frequency_hz * dt, 1e-9))) if d.frequency_hz > 0 else 0
    lo = 0 if k == 0 else int(np.searchsorted(t, decays[k - 1].end_s, side="right")) + MARGIN
    hi = int(np.searchsorted(t, d.start_s)) - MARGIN - min(period, 64)
    if hi - lo >= MIN_QUIET and not d.from_start and d.clipped_until_s is None:
        return y[lo:hi].copy()
    if k == len(decays) - 1:
        after = y[int(np.searchsorted(t, d.end_s, side="right")) + MARGIN :]
        if after.size >= MIN_QUIET:
            return after.copy()
    return None


def lattice_step(y) -> float:
    """The step of a quantised signal (ADC codes, or volts on a lattice of codes), 0 when the
    samples are not on a lattice."""
    values = np.unique(np.asarray(y, dtype=float))
    if values.size < 3:
        return 0.0
    d = np.diff(values)
    q = float(d.min())
    if not q > 0:
        return 0.0
    k = d / q
    if np.all(np.abs(k - np.rint(k)) < 1e-4 * np.maximum(k, 1.0)):
        return q
    return 0.0


def noise_floor(quiet, q: float = 0.0) -> dict:
    """The floor of a quiet stretch: ``sigma`` (its RMS, rounding included), ``nu`` (its
    degrees of freedom), ``m`` (samples), ``sigma_noise`` (without the rounding) and
    ``trimmed`` (second differences left out).

    Second differences beyond :data:`TRIM` robust standard deviations (from their median
    absolute value, never below the step ``q``) are left out: the kinks of a hand's ramp and
    a tap's impact, which are not noise. For Gaussian noise that removes a fraction 6e-7.
    """
    x = np.asarray(quiet, dtype=float)
    d2 = np.diff(x, n=2)
    robust = max(1.4826 * float(np.median(np.abs(d2))), q, 1e-300)
    kept = d2[np.abs(d2) <= TRIM * robust]
    var = float(np.mean(kept**2) / 6.0) if kept.size else 0.0
    return {
        "sigma": float(np.sqrt(var + q**2 / 12.0)),
        "sigma_noise": float(np.sqrt(var)),
        "quantum": q,
        "nu": 36.0 * kept.size / 70.0,
        "m": int(x.size),
        "trimmed": int(d2.size - kept.size),
    }


def floor_test(per_rec: list[dict], obs, n_params: int) -> dict:
    """The test of each recording with a quiet stretch (see the module docstring).

    Returns:
        ``{"recordings": [...], "rejects": [names], "message": str}``; each tested recording
        has its residual RMS, the floor, their ratio, the degrees of freedom and the p-value.
    """
    out, rejects, worst = [], [], None
    p_each = n_params / max(len(obs), 1)
    for r, o in zip(per_rec, obs, strict=True):
        quiet = getattr(o, "quiet", None)
        if quiet is None or np.size(quiet) < MIN_QUIET:
            out.append({"name": o.name, "tested": False, "why": "no quiet stretch"})
            continue
        floor = noise_floor(quiet, lattice_step(np.concatenate([np.asarray(o.y), quiet])))
        if not floor["sigma"] > 0:  # an exactly constant stretch, no converter step known
            out.append({"name": o.name, "tested": False, "why": "a quiet stretch with no noise"})
            continue
        n = int(o.t.size)
        dof = max(n - p_each, 1.0)
        s2 = r["rms_residual"] ** 2 * n / dof
        # in NumPy: a residual far above a tiny floor gives inf, not an OverflowError
        with np.errstate(over="ignore"):
            ratio2 = float(np.float64(s2) / np.float64(floor["sigma"]) ** 2)
        ratio = float(np.sqrt(ratio2))
        p = float(f_sf(ratio2, dof, floor["nu"]))
        row = {"name": o.name, "tested": True, "rms_residual": float(np.sqrt(s2)),
               "floor": floor["sigma"], "floor_noise": floor["sigma_noise"],
               "quantum": floor["quantum"], "quiet_samples": floor["m"], "nu": floor["nu"],
               "ratio": ratio, "p_value": p}  # fmt: skip
        row["rejects"] = bool(p < P_FALSE and ratio >= MIN_RATIO)
        out.append(row)
        if row["rejects"]:
            rejects.append(o.name)
            if worst is None or ratio > worst["ratio"]:
                worst = row
    message = ""
    if worst is not None:
        message = (
            f"the residuals of {worst['name']} (RMS {worst['rms_residual']:.3g}) are "
            f"{worst['ratio']:.2f} times the noise measured on its quiet stretch "
            f"({worst['floor']:.3g} over {worst['quiet_samples']} samples, rounding included; "
            f"p = {worst['p_value']:.1g}): the model leaves signal in the residuals"
        )
    return {"recordings": out, "rejects": rejects, "message": message}


def check_noise_floor(cal, obs, advice: str) -> None:
    """Run :func:`floor_test` on a converged calibration and mark it ``check``
    (``above-noise-floor``, the message ending with ``advice``) when a recording rejects."""
    if not cal.ok or not cal.per_recording:
        return
    if not any(getattr(o, "quiet", None) is not None for o in obs):
        return
    test = floor_test(cal.per_recording, obs, int(cal.diagnostics.get("n_params", 0)))
    cal.diagnostics["noise_floor"] = test
    if not test["rejects"]:
        return
    text = f"{test['message']}; {advice}"
    cal.checks["above-noise-floor"] = text
    cal.warnings.append(f"above-noise-floor: {text}")
    if cal.status == "ok":
        cal.status = "check"
    fit = cal.record.extra.get("fit")
    if isinstance(fit, dict):
        fit["status"] = cal.status
        fit["warnings"] = list(cal.warnings)
