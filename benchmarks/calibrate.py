"""Benchmark: the same calibration model and data fitted by optimistix, SciPy and lmfit.

Model: the damped oscillation ``offset + e^{−σt}(a cos ω_d t + b sin ω_d t)`` that
:func:`whiskerid.fit_windows` fits (``whiskerid._calibrate.window_model_residuals``; five
parameters: log f_d, logit ζ, a, b, offset), on

* one recording: the paper whisker plucked, exact model, 10 s at 200 Hz, SNR 30 dB
  (deflection at the Hall sensor), fitted by optimistix Levenberg–Marquardt (jitted),
  ``scipy.optimize.least_squares(method="lm")`` and lmfit (``leastsq``) from the same
  data-derived start values: compile time, warm time per fit, and the fitted values;
* 1000 windows (1 s at 200 Hz, random f_d 20–80 Hz and ζ 0.01–0.06, SNR 30 dB) fitted in one
  ``vmap``-ed optimistix call (``whiskerid._lsq.batch_least_squares``) against a SciPy loop.

Run: ``python benchmarks/calibrate.py [--windows N]`` (prints one JSON object).
"""

import argparse
import json
import platform
import statistics
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import whiskerid as wi
from whiskerid import _lsq
from whiskerid._calibrate import (
    ZETA_MAX,
    batched_lm,
    envelope_zeta,
    spectral_peaks,
    window_model_residuals,
    window_start,
)


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
    # Start values from the data as calibrate() makes them: spectral peak, envelope decay.
    fd0 = spectral_peaks(t, y)[0][0]
    z0 = envelope_zeta(t, y, fd0, fd0) or 0.02
    wd0 = 2 * np.pi * fd0
    e = np.exp(-z0 * wd0 * t)
    basis = np.stack([e * np.cos(wd0 * t), e * np.sin(wd0 * t), np.ones_like(t)], axis=1)
    lin = np.linalg.lstsq(basis, y, rcond=None)[0]
    u0 = np.array([np.log(fd0), np.log(z0 / (ZETA_MAX - z0)), *lin])
    tj, yj = jnp.asarray(t), jnp.asarray(y)
    solver = _lsq.make_solver()

    @eqx.filter_jit
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
            _np_residuals, u0, args=(t, y), method="lm", xtol=1e-10, ftol=1e-10
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
        return lmfit.minimize(lm_resid, params, method="leastsq", xtol=1e-10, ftol=1e-10)

    r = lmfit_fit()
    out["lmfit_leastsq"] = {
        "warm_s": _timeit(lmfit_fit, repeats),
        "ok": bool(r.success),
        "nfev": int(r.nfev),
        **_decode([r.params[f"u{i}"].value for i in range(5)]),
    }
    w = rec.whisker()
    out["truth"] = {"fd_hz": float(w.damped_frequencies_hz[0]), "zeta": float(w.zeta[0])}
    out["speedup_warm_vs_scipy"] = out["scipy_least_squares_lm"]["warm_s"] / warm
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
    u0 = window_start(tb, y)
    args = (jnp.asarray(tb), jnp.asarray(y))

    def run():
        solver = _lsq.make_solver(rtol=1e-8, atol=1e-10)  # as fit_windows uses it
        r = _lsq.batch_least_squares(
            window_model_residuals, jnp.asarray(u0), args, solver=solver, max_steps=100
        )
        return jax.block_until_ready(r.value), r.ok

    t0 = time.perf_counter()
    run()
    first = time.perf_counter() - t0
    warm = _timeit(run, 3)
    val, ok = run()
    fd_fit = np.exp(np.asarray(val)[:, 0])

    def run_fixed():
        r = batched_lm(window_model_residuals, jnp.asarray(u0), args, iterations=15)
        return jax.block_until_ready(r[0]), r[1]

    t0 = time.perf_counter()
    run_fixed()
    first_fixed = time.perf_counter() - t0
    warm_fixed = _timeit(run_fixed, 3)
    val_f, ok_f = run_fixed()

    t0 = time.perf_counter()
    sc = [
        scipy.optimize.least_squares(
            _np_residuals, u0[i], args=(t, y[i]), method="lm", xtol=1e-10, ftol=1e-10
        )
        for i in range(n_scipy)
    ]
    scipy_s = (time.perf_counter() - t0) * n / n_scipy
    sc_fd = np.exp(np.array([s.x[0] for s in sc]))
    return {
        "windows": n,
        "samples_per_window": m,
        "optimistix_vmap_compile_plus_first_s": first,
        "optimistix_vmap_warm_s": warm,
        "optimistix_ok_fraction": float(np.mean(np.asarray(ok))),
        "batched_lm_vmap_compile_plus_first_s": first_fixed,
        "batched_lm_vmap_warm_s": warm_fixed,
        "batched_lm_ok_fraction": float(np.mean(np.asarray(ok_f))),
        "batched_lm_median_abs_fd_error_hz": float(
            np.median(np.abs(np.exp(np.asarray(val_f)[:, 0]) - fd))
        ),
        "speedup_batched_lm_vs_scipy_loop": scipy_s / warm_fixed,
        "scipy_loop_s": scipy_s,
        "scipy_loop_timed_windows": n_scipy,
        "speedup_optimistix_vs_scipy_loop": scipy_s / warm,
        "median_abs_fd_error_hz": float(np.median(np.abs(fd_fit - fd))),
        "max_fd_diff_vs_scipy_hz": float(np.max(np.abs(fd_fit[:n_scipy] - sc_fd))),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", type=int, default=1000)
    ap.add_argument("--scipy-windows", type=int, default=1000, help="windows timed in the loop")
    ap.add_argument("--repeats", type=int, default=20)
    a = ap.parse_args()
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
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
