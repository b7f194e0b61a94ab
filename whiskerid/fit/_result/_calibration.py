"""A calibration's result, and the steps after the solve that every fit shares.

:class:`Calibration` (what :func:`whiskerid.fit.calibrate` returns), its status from the
checks (:func:`fit_status`), its diagnostics (:func:`fit_diagnostics`), the per-recording
figures and curves (:func:`recording_diagnostics`), the residual blocks of the HAC
covariance (:func:`recording_blocks`) and the record with the fit written in
(:func:`record_with_fit`): shared by the linear, added-mass and nonlinear fits.
"""

import datetime
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..._version import __version__
from ...io import sha256_of
from ...model import RecordError, UniformBeam, WhiskerRecord
from .._checks import lag1 as lag1_autocorr
from .._checks import moments as recording_moments
from .._checks import residual_peak
from .._linear import FitProblem
from ._report import fit_report


# --------------------------------------------------------------------------- results
@dataclass
class Calibration:
    """Outcome of :func:`calibrate`.

    Attributes:
        status: ``"ok"`` or why not: ``"not converged"``, ``"non-finite"``, ``"poor fit"``
            (the model explains little of a recording) or ``"check"`` (converged, but a
            check in ``checks`` failed: correlated residuals, a line left in the residuals,
            ζ at a bound or implausible, f_1 far from the record's, or imprecise values).
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
        checks: The failed checks of a converged fit, name → sentence (see
            :mod:`whiskerid.fit._checks._checks`); empty for ``ok``.
        problem: The fitted :class:`whiskerid.fit.FitProblem` (each recording weighted by
            its own residual scale).
        optimum: The parameter pytree at the optimum (``problem.flatten(optimum)`` is the
            vector ``covariance`` refers to).
        covariance: ``s²(JᵀJ)⁻¹`` of the flat parameters at the optimum.
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
    checks: dict[str, str] = field(default_factory=dict)
    problem: FitProblem | None = field(default=None, repr=False)
    optimum: Any = field(default=None, repr=False)
    covariance: np.ndarray | None = field(default=None, repr=False)

    def report(self) -> str:
        """The console report (``whiskerid calibrate``): see :func:`whiskerid.fit.fit_report`."""
        return fit_report(self)

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
            "checks": self.checks,
        }


def fit_status(status: str, ok: bool, warnings: list[str], checks: dict[str, str]):
    """The status a converged fit reports and its warnings: ``poor fit`` when a recording
    fits poorly, else ``check`` when a check failed (each failed check is also a warning);
    shared by the linear, added-mass and nonlinear fits."""
    if ok and warnings:
        status = "poor fit"
    elif ok and checks:
        status = "check"
    return status, warnings + [f"{name}: {text}" for name, text in checks.items()]


def fit_diagnostics(per_rec, obs, res, resid, *, s2, gcos, uncertainty) -> dict:
    """The ``diagnostics`` of a calibration: residual sizes and correlation per recording,
    the solver's figures (``res``: its ``value`` and ``steps``) and which covariance the 1σ
    come from (shared by the linear, added-mass and nonlinear fits)."""
    return {
        "rms_residual": [r["rms_residual"] for r in per_rec],
        "reduced_chi2": s2,
        "gradient_cosine": gcos,
        "n_samples": int(sum(o.t.size for o in obs)),
        "n_params": int(res.value.size),
        "steps": int(res.steps),
        "lag1_autocorr": [r["lag1_autocorr"] for r in per_rec],
        "weighted_rms": float(np.sqrt(np.mean(resid**2))),
        "uncertainty": uncertainty,
    }


def recording_blocks(jac, resid, obs, correlated=True):
    """``(J, r, correlated)`` rows of each recording, then the static test's rows (if any),
    which are independent points."""
    out, start = [], 0
    for o in obs:
        stop = start + o.t.size
        out.append((jac[start:stop], resid[start:stop], correlated))
        start = stop
    if start < resid.size:
        out.append((jac[start:], resid[start:], False))
    return out


#: A recording fitted below this SNR (signal RMS over residual RMS, in dB) is a poor fit:
#: the model explains less than half of the signal's variance.
POOR_FIT_SNR_DB = 3.0


def poor_fit_warnings(per_rec: list[dict]) -> list[str]:
    """A warning per recording that the fitted model leaves mostly unexplained."""
    return [
        f"poor fit of {r['name']}: the model explains little of the signal (SNR "
        f"{r['snr_db']:.3g} dB); check the time units (seconds), the observable and the "
        "excitation"
        for r in per_rec
        if not r["snr_db"] >= POOR_FIT_SNR_DB
    ]


def recording_diagnostics(problem: FitProblem, optimum, obs, models, resid, peak_refs=None,
                   moments=None):  # fmt: skip
    """Nuisances and residual diagnostics per recording, the curves for plots, and the
    weighted residual vector (``models``: each recording's normalised model and its modal
    parts, from the compiled fit; ``peak_refs``: :func:`_checks.peak_reference` of each
    recording, ``moments``: :func:`_checks.moments`, when already computed)."""
    out, curves = [], []
    peak_refs = peak_refs or [None] * len(obs)
    moments = moments or recording_moments(obs)
    for spec, rec, (model_n, modal), o, ref, (y_mean, y_std) in zip(
        problem.recordings, optimum["recs"], models, obs, peak_refs, moments, strict=True
    ):
        model = model_n * y_std + y_mean
        r = o.y - model
        lag1 = lag1_autocorr(r)
        c = np.asarray(rec["c"])
        nm = problem.n_modes
        amps = np.hypot(c[2 : 2 + nm], c[2 + nm : 2 + 2 * nm]) * y_std
        modal_rms = [float(v) for v in np.sqrt(np.mean(modal**2, axis=0)) * y_std]
        rms = np.sqrt(np.mean(r**2))
        info = {
            "name": o.name,
            "source": o.source,
            "excitation": o.excitation,
            "observable": o.observable,
            "n_samples": int(o.t.size),
            "t_start_s": float(o.t[0]),
            "rms_residual": float(rms),
            "rms_signal": y_std,
            "snr_db": float(20 * np.log10(y_std / max(rms, 1e-300))),
            "lag1_autocorr": lag1,
            "residual_peak": residual_peak(o.t, r, o.y, data=ref),
            "selection": o.selection,
            "offset": float(c[0] * y_std + y_mean),
            "drift_per_s": float(c[1] * y_std / max(o.t[-1] - o.t[0], 1e-12)),
            "modal_amplitudes": [float(a) for a in amps],
            "modal_rms": modal_rms,
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
    return out, curves, np.asarray(resid)


def _plausible_structure(record, structure, cal: Calibration):
    """``structure`` if a record can hold it; else the record's own, and ``cal`` marked
    ``check`` (a fit far from the record, on an alias or from a wrong record, can imply a
    modulus no material has: the calibration says so instead of failing to write it)."""
    try:
        record.replace(structure=structure)
    except RecordError as err:
        text = (
            f"the fitted EI implies {err}; the record's structure is kept: check the record "
            "and the recording (an alias of f1?)"
        )
        cal.checks["implausible-structure"] = text
        cal.warnings.append(f"implausible-structure: {text}")
        if cal.status == "ok":
            cal.status = "check"
        return record.structure
    return structure


def record_with_fit(record, cal: Calibration, pin, static, obs, problem):
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
        structure = _plausible_structure(record, structure, cal)
    files = []
    for o in obs:
        if o.source and Path(o.source).exists():
            files.append({"path": str(o.source), "sha256": sha256_of(o.source), "name": o.name})
    if static is not None and static.source and Path(static.source).exists():
        files.append(
            {"path": static.source, "sha256": sha256_of(static.source), "name": "static test"}
        )

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


def reported_std(dcov: np.ndarray) -> np.ndarray:
    """The 1σ of reported quantities from their covariance (a rounding-negative variance is 0)."""
    return np.sqrt(np.maximum(np.diag(dcov), 0.0))


def correlation_table(names, dcov: np.ndarray, std: np.ndarray) -> dict:
    """A calibration's ``correlations``: the names and the correlation matrix of the reported
    quantities (covariance ``dcov``, 1σ ``std``), to 6 digits; shared by every fit."""
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = dcov / np.outer(std, std)
    return {"names": list(names), "matrix": np.round(np.nan_to_num(corr), 6).tolist()}
