"""The console report of a calibration, in the spirit of lmfit's ``fit_report``."""

import numpy as np

#: Correlations smaller than this in magnitude are left out of the report.
MIN_CORRELATION = 0.1


def fit_report(cal, *, min_correlation: float = MIN_CORRELATION) -> str:
    """A calibration as text: status, data and where each decay starts, values with 1σ and
    percentages, fixed values, correlations, fit statistics, failed checks, identifiability.

    Args:
        cal: A :class:`whiskerid.fit.Calibration`.
        min_correlation: Leave out correlations smaller than this in magnitude.
    """
    d = cal.diagnostics
    lines = [f"[[Calibration]] {cal.record.name}: status {cal.status}"]
    lines.append(
        f"    solver {cal.solver}, {d['steps']} steps, gradient cosine {d['gradient_cosine']:.2g}, "
        f"{d['n_samples']} samples, {d['n_params']} parameters"
    )
    lines.append("[[Data]]")
    for r in cal.per_recording:
        where = r.get("selection") or f"from {r['t_start_s']:.4g} s"
        lines.append(
            f"    {r['name']}: {r['excitation']}, {r['observable']}, {r['n_samples']} samples, "
            f"{where}"
        )
    lines.append(f"[[Values]] (1 sigma: {d['uncertainty']})")
    width = max(len(k) for k in cal.params)
    for name, p in cal.params.items():
        lines.append(f"    {name:<{width}} = {_value(p)}   {p['source']}")
    if cal.fixed:
        fixed = ", ".join(f"{k} = {v:.6g}" for k, v in cal.fixed.items())
        lines.append(f"[[Fixed]] {fixed}")
    corr = _correlations(cal.correlations, min_correlation)
    if corr:
        lines.append(f"[[Correlations]] (|r| > {min_correlation:g}, fitted quantities)")
        lines += [f"    C({a}, {b}) = {c:+.3f}" for a, b, c in corr]
    lines.append("[[Fit statistics]]")
    lines.append(
        f"    reduced chi-square {d['reduced_chi2']:.4g} (blocks weighted by their own scale)"
    )
    for r in cal.per_recording:
        peak = r.get("residual_peak")
        peak_text = f", residual line at {peak[0]:.4g} Hz" if peak else ""
        lines.append(
            f"    {r['name']}: RMS residual {r['rms_residual']:.4g}, SNR {r['snr_db']:.3g} dB, "
            f"lag-1 autocorrelation {r['lag1_autocorr']:.2f}{peak_text}"
        )
    if cal.warnings:
        lines.append("[[Warnings]]")
        lines += [f"    {w}" for w in cal.warnings]
    else:
        lines.append("[[Checks]] all passed")
    lines.append(f"[[Identifiability]] {cal.note}")
    return "\n".join(lines)


def _value(p: dict) -> str:
    v, s = p["value"], p["std"]
    if s is None:  # at a bound the user set: refused, as lmfit refuses it
        return f"{v:.6g} ± (refused: {p['source']})"
    if s == 0 and p["source"].startswith("fixed"):
        return f"{v:.6g} (fixed)"
    if not np.isfinite(s):
        return f"{v:.6g} ± ?"
    digits = max(2, int(np.ceil(-np.log10(s / abs(v)))) + 2) if s > 0 and v != 0 else 6
    pct = f" ({100 * s / abs(v):.2g} %)" if v != 0 else ""
    return f"{v:.{min(digits, 12)}g} ± {s:.2g}{pct}"


def _correlations(correlations: dict, min_correlation: float) -> list[tuple[str, str, float]]:
    """Pairs of fitted quantities (not derived ones such as f2, EI, E) with |r| above the cut,
    strongest first."""
    names = correlations["names"]
    m = np.asarray(correlations["matrix"])
    keep = [i for i, n in enumerate(names) if n in ("f1_hz", "zeta") or n.startswith("zeta_")]
    keep += [i for i, n in enumerate(names) if n in ("EI", "rho_a", "C") and i not in keep]
    out = []
    for a in range(len(keep)):
        for b in range(a + 1, len(keep)):
            i, j = keep[a], keep[b]
            if abs(m[i, j]) > min_correlation and abs(m[i, j]) < 0.9999995:
                out.append((names[i], names[j], float(m[i, j])))
    return sorted(out, key=lambda x: -abs(x[2]))
