"""Benchmark: the same calibration model and data fitted by optimistix, SciPy and lmfit.

Model: the damped oscillation ``offset + e^{−σt}(a cos ω_d t + b sin ω_d t)`` that
:func:`whiskerid.fit_windows` fits (``whiskerid.fit.window_model_residuals``; five
parameters: log f_d, logit ζ, a, b, offset), on

* one recording: the paper whisker plucked, exact model, 10 s at 200 Hz, SNR 30 dB
  (deflection at the Hall sensor), fitted by optimistix Levenberg–Marquardt (jitted),
  ``scipy.optimize.least_squares(method="lm")`` and lmfit (``leastsq``), all on the same five
  parameters from the same data-derived start values (:func:`whiskerid.fit.window_start`)
  and with the same relative tolerance 1e-8 on parameters and cost (calibrate()'s, and
  again at 1e-10, the solver's default): compile time, warm time per fit, steps or function
  evaluations, and the fitted values;
* 1000 windows (1 s at 200 Hz, random f_d 20–80 Hz and ζ 0.01–0.06, SNR 30 dB) fitted by
  :func:`whiskerid.fit_windows`' solver (variable-projection Levenberg–Marquardt, all windows
  in one compiled ``vmap``-ed loop), by one ``vmap``-ed optimistix call
  (``whiskerid.fit._numerics._lsq.batch_least_squares``) and by a SciPy loop, from the same
  start values.

And with ``--cli``, the command line as a user runs it (module ``_calibrate_cli``): ``whiskerid
calibrate`` of a 5 s pluck at 200 Hz (1000 samples) with an empty compile cache (cold) and
again (warm), on recordings of other lengths, and ``wi.calibrate`` from a fresh interpreter,
each side by side with ``benchmarks/scipy_pluck.py`` (the same fit in NumPy and SciPy), their
fitted f_1, ζ and 1σ, and where a warm run's time goes.

Run: ``python benchmarks/calibrate.py [--windows N] [--cli] [--cli-only]`` (prints one JSON
object).
"""

import argparse
import json
import platform
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

import whiskerid as wi
from whiskerid.fit import ZETA_MAX
from whiskerid.fit._linear._windows import (
    _vp_fit,
    _window_candidates,
    window_model_residuals,
    window_start,
)
from whiskerid.fit._numerics import _lsq as _lsq

TOL = 1e-8  # relative tolerance on parameters and cost, for all three solvers


def _np_residuals(u, t, y):
    fd = np.exp(u[0])
    zeta = ZETA_MAX / (1 + np.exp(-u[1]))
    wd = 2 * np.pi * fd
    sigma = zeta * wd / np.sqrt(1 - zeta**2)
    e = np.exp(-sigma * t)
    return u[4] + e * (u[2] * np.cos(wd * t) + u[3] * np.sin(wd * t)) - y


def _timeit(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _decode(u):
    u = np.asarray(u)
    return {"fd_hz": float(np.exp(u[0])), "zeta": float(ZETA_MAX / (1 + np.exp(-u[1])))}


def single(repeats: int) -> dict:
    import lmfit
    import scipy.optimize

    rec = wi.paper_record()
    sim = wi.simulate(
        rec,
        excitation="decay",
        observable="deflection",
        rate_hz=200.0,
        duration_s=10.0,
        noise_db=30.0,
        seed=1,
        tip_deflection_m=2e-3,
    )
    t = sim.t - sim.t[0]
    y = sim.signal()
    y = (y - y.mean()) / y.std()
    # Start values from the data (spectral peak, log decrement, linear least squares).
    u0 = window_start(t, y)[0]
    tj, yj = jnp.asarray(t), jnp.asarray(y)
    solver = _lsq.make_solver(rtol=TOL, atol=TOL * 1e-2)

    @jax.jit
    def fit(u):
        r = _lsq.least_squares(window_model_residuals, u, (tj, yj), solver=solver)
        return r.value, r.ok, r.steps

    t0 = time.perf_counter()
    jax.block_until_ready(fit(jnp.asarray(u0)))
    first = time.perf_counter() - t0
    warm = _timeit(lambda: jax.block_until_ready(fit(jnp.asarray(u0))), repeats)
    val, ok, steps = fit(jnp.asarray(u0))
    out = {
        "optimistix_lm": {
            "compile_plus_first_s": first,
            "warm_s": warm,
            "ok": bool(ok),
            "steps": int(steps),
            **_decode(val),
        }
    }

    def scipy_fit():
        return scipy.optimize.least_squares(
            _np_residuals, u0, args=(t, y), method="lm", xtol=TOL, ftol=TOL
        )

    res = scipy_fit()
    out["scipy_least_squares_lm"] = {
        "warm_s": _timeit(scipy_fit, repeats),
        "ok": bool(res.success),
        "nfev": int(res.nfev),
        **_decode(res.x),
    }

    params = lmfit.Parameters()
    for i, v in enumerate(u0):
        params.add(f"u{i}", value=float(v))

    def lm_resid(p):
        return _np_residuals(np.array([p[f"u{i}"].value for i in range(5)]), t, y)

    def lmfit_fit():
        return lmfit.minimize(lm_resid, params, method="leastsq", xtol=TOL, ftol=TOL)

    r = lmfit_fit()
    out["lmfit_leastsq"] = {
        "warm_s": _timeit(lmfit_fit, repeats),
        "ok": bool(r.success),
        "nfev": int(r.nfev),
        **_decode([r.params[f"u{i}"].value for i in range(5)]),
    }
    # The same three-way comparison at the solver's tighter default tolerance
    # (optimistix rtol 1e-10, atol 1e-12; SciPy xtol = ftol = 1e-10).
    tight = _lsq.make_solver()

    @jax.jit
    def fit_tight(u):
        r = _lsq.least_squares(window_model_residuals, u, (tj, yj), solver=tight)
        return r.value, r.steps

    val_t, steps_t = jax.block_until_ready(fit_tight(jnp.asarray(u0)))

    def scipy_tight():
        return scipy.optimize.least_squares(
            _np_residuals, u0, args=(t, y), method="lm", xtol=1e-10, ftol=1e-10
        )

    res_t = scipy_tight()
    out["tolerance_1e-10"] = {
        "optimistix_warm_s": _timeit(
            lambda: jax.block_until_ready(fit_tight(jnp.asarray(u0))), repeats
        ),
        "optimistix_steps": int(steps_t),
        "optimistix_fd_hz": _decode(val_t)["fd_hz"],
        "scipy_warm_s": _timeit(scipy_tight, repeats),
        "scipy_nfev": int(res_t.nfev),
        "scipy_fd_hz": _decode(res_t.x)["fd_hz"],
    }
    out["start"] = _decode(u0)
    w = rec.whisker()
    out["truth"] = {"fd_hz": float(w.damped_frequencies_hz[0]), "zeta": float(w.zeta[0])}
    out["speedup_warm_vs_scipy"] = out["scipy_least_squares_lm"]["warm_s"] / warm
    out["speedup_warm_vs_lmfit"] = out["lmfit_leastsq"]["warm_s"] / warm
    return out


def batch(n: int, n_scipy: int) -> dict:
    import scipy.optimize

    rng = np.random.default_rng(0)
    m = 200
    t = np.arange(m) / 200.0
    fd = rng.uniform(20, 80, n)
    zeta = rng.uniform(0.01, 0.06, n)
    wd = 2 * np.pi * fd[:, None]
    clean = np.exp(-zeta[:, None] * wd * t) * np.cos(wd * t + rng.uniform(0, 6, (n, 1)))
    y = clean + clean.std(axis=1, keepdims=True) / 10**1.5 * rng.standard_normal((n, m))
    y = (y - y.mean(axis=1, keepdims=True)) / y.std(axis=1, keepdims=True)
    tb = np.broadcast_to(t, (n, m))
    # The same start information for every solver: the two spectral candidates per window,
    # and for the five-parameter solvers the better one with its linear coefficients.
    cands = jnp.asarray(_window_candidates(tb, y))
    u0 = window_start(tb, y)
    args = (jnp.asarray(tb), jnp.asarray(y))
    out = {"windows": n, "samples_per_window": m}

    def run_vp():
        u, _, _, ok, steps = _vp_fit(cands, *args, max_steps=100)
        return jax.block_until_ready(u), ok, steps

    t0 = time.perf_counter()
    run_vp()
    out["varpro_vmap_compile_plus_first_s"] = time.perf_counter() - t0
    out["varpro_vmap_warm_s"] = warm_vp = _timeit(run_vp, 5)
    u_vp, ok_vp, steps = run_vp()
    out["varpro_steps"] = int(steps)
    fd_vp = np.exp(np.asarray(u_vp)[:, 0])
    out["varpro_ok_fraction"] = float(np.mean(ok_vp))
    out["varpro_median_abs_fd_error_hz"] = float(np.median(np.abs(fd_vp - fd)))
    out["varpro_abs_fd_error_above_0.1hz"] = int(np.sum(np.abs(fd_vp - fd) > 0.1))
    # fit_windows end to end: start values (NumPy) + the same solve + unpacking
    wi.fit_windows(y, rate_hz=200.0)
    out["fit_windows_warm_s"] = _timeit(lambda: wi.fit_windows(y, rate_hz=200.0), 5)

    def run_optx():
        solver = _lsq.make_solver(rtol=1e-8, atol=1e-10)
        r = _lsq.batch_least_squares(
            window_model_residuals, jnp.asarray(u0), args, solver=solver, max_steps=100
        )
        return jax.block_until_ready(r.value), r.ok

    t0 = time.perf_counter()
    run_optx()
    out["optimistix_vmap_compile_plus_first_s"] = time.perf_counter() - t0
    out["optimistix_vmap_warm_s"] = warm_optx = _timeit(run_optx, 1)
    val, ok = run_optx()
    out["optimistix_ok_fraction"] = float(np.mean(np.asarray(ok)))
    out["optimistix_median_abs_fd_error_hz"] = float(
        np.median(np.abs(np.exp(np.asarray(val)[:, 0]) - fd))
    )

    t0 = time.perf_counter()
    sc = [
        scipy.optimize.least_squares(
            _np_residuals, u0[i], args=(t, y[i]), method="lm", xtol=TOL, ftol=TOL
        )
        for i in range(n_scipy)
    ]
    scipy_s = (time.perf_counter() - t0) * n / n_scipy
    sc_fd = np.exp(np.array([s.x[0] for s in sc]))
    out["scipy_loop_s"] = scipy_s
    out["scipy_loop_timed_windows"] = n_scipy
    out["scipy_ok_fraction"] = float(np.mean([s.success for s in sc]))
    out["scipy_median_abs_fd_error_hz"] = float(np.median(np.abs(sc_fd - fd[:n_scipy])))
    out["speedup_varpro_vs_scipy_loop"] = scipy_s / warm_vp
    out["speedup_optimistix_vs_scipy_loop"] = scipy_s / warm_optx
    out["max_fd_diff_varpro_vs_scipy_hz"] = float(np.max(np.abs(fd_vp[:n_scipy] - sc_fd)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", type=int, default=1000)
    ap.add_argument("--scipy-windows", type=int, default=1000, help="windows timed in the loop")
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--cli", action="store_true", help="also time the command line")
    ap.add_argument("--cli-only", action="store_true", help="only time the command line")
    a = ap.parse_args()
    if a.cli or a.cli_only:
        import sys

        sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
        from _calibrate_cli import cli

        cli_result = cli()
        if a.cli_only:
            print(json.dumps({"benchmark": "calibrate --cli", "cli": cli_result}, indent=2))
            return
    out = {
        "benchmark": "calibrate",
        "machine": {
            "platform": platform.platform(),
            "cpus": __import__("os").cpu_count(),
            "jax": jax.__version__,
            "backend": jax.default_backend(),
        },
        "single_fit": single(a.repeats),
        "batch": batch(a.windows, min(a.scipy_windows, a.windows)),
    }
    if a.cli:
        out["cli"] = cli_result
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
