"""emcee posteriors: lmfit's ``Minimizer.emcee`` vs whiskerid's vectorised sampler, one run.

Same model, data and sampler settings for both: a one-mode free decay (paper record,
f_1 = 48 Hz, ζ = 0.02, 500 samples at 1 kHz, noise 0.05; normalised units as in the
calibration), Gaussian likelihood with unknown σ, the four linear nuisances (offset, drift,
cos and sin amplitudes) *sampled* (lmfit cannot marginalise them), flat priors (log κ, ζ on
(0, 0.95), the nuisances, log σ), emcee's stretch move, 32 walkers × 5000 steps, seed 0.
lmfit calls a jitted JAX residual of the same model walker by walker (``vectorize`` is not
available through lmfit), its four amplitudes passed as a NumPy vector (``jnp.asarray`` of a
Python list would add ≈ 136 µs per call, more than the residual: an earlier version of this
benchmark did that and reported 18.3× where 11.9× was right). Ours evaluates all walkers of a
half-ensemble in one jitted, vmapped call (the free decay on a grid of its near-uniform
timestamps, the data packed into one argument: see ``whiskerid/_posterior.py``). Both use
emcee's stretch move, lmfit's only choice. A third line runs ours as shipped: nuisances
marginalised analytically and emcee's differential-evolution move (``move="de"``, the
default of :func:`whiskerid.sample_posterior`). Effective samples per second use ζ's
integrated autocorrelation time, ESS = walkers (steps − 2τ)/τ, for every run alike. Prints
one JSON object.

Both run on the same CPUs, one by default (``--cpus 1``; ``--cpus 0``: all the process may
use). The affinity is set before JAX starts, so XLA's thread pool has that many threads:
on a small, shared machine, XLA splitting each 16 × 500 loop across threads costs more in
hand-offs than it gains (measured: 3-5× slower sin/exp loops on 2 busy cores), and lmfit's
walker-by-walker calls are single-threaded anyway.

Where a step's time goes (ours, one CPU): emcee's own work ≈ 350-400 µs (two proposals, the
acceptance loop, the random-state copy, the in-memory backend; measured with a NumPy
log-probability), paid by lmfit too, so that even a free log-probability could be at most
(lmfit's step) / (emcee's step) ≈ 8.5 ms / 0.39 ms ≈ 22× faster with the same settings;
and per half-ensemble call (two per step) JAX's dispatch and runtime (≈ 70 µs of the step
even for a trivial jitted function, emcee's NumPy code running slower after it included),
a hand-off to XLA's worker thread (XLA runs computations above 1000 flops on a worker; on
one CPU that is two context switches, ≈ 20 µs) and ≈ 20 µs of compiled code.
``--sync-dispatch`` turns JAX's asynchronous CPU dispatch off for the whole process
(``jax_cpu_enable_async_dispatch``, read once when JAX creates its CPU client, so it cannot
be scoped to the sampler): it removes the hand-off for both samplers, lmfit's 32 calls per
step included; the JSON says which was used (``jax_async_dispatch``).

    .venv/bin/python benchmarks/posterior.py [--walkers 32] [--steps 5000] [--lmfit-steps N]
        [--cpus 1] [--sync-dispatch]
"""

# ruff: noqa: E402  (the CPU affinity must be set before JAX starts)
import argparse
import json
import math
import os
import platform
import sys
import time


def _pin_cpus(argv: list[str]) -> list[int]:
    """Restrict this process to the first ``--cpus`` allowed CPUs (before JAX starts)."""
    n = 1
    for i, a in enumerate(argv):
        if a == "--cpus" and i + 1 < len(argv):
            n = int(argv[i + 1])
        elif a.startswith("--cpus="):
            n = int(a.split("=", 1)[1])
    allowed = sorted(os.sched_getaffinity(0))
    if n > 0:
        os.sched_setaffinity(0, allowed[:n])
    return sorted(os.sched_getaffinity(0))


if __name__ == "__main__":
    _CPUS = _pin_cpus(sys.argv[1:])

import emcee
import jax

if __name__ == "__main__" and "--sync-dispatch" in sys.argv[1:]:
    # Read when JAX creates its CPU client, i.e. before the first computation.
    jax.config.update("jax_cpu_enable_async_dispatch", False)
import jax.numpy as jnp
import numpy as np

import whiskerid as wi
from whiskerid import posterior as P
from whiskerid.fit import ZETA_MAX, from_interval, recording_design, to_interval
from whiskerid.posterior import _likelihood as L

F1, ZETA, NOISE, N = 48.0, 0.02, 0.05, 500


def decay(seed: int = 0) -> wi.Observation:
    rng = np.random.default_rng(seed)
    t = np.arange(N) / 1000.0 + rng.uniform(0, 2e-4, N)
    w = 2 * np.pi * F1
    y = 0.3 + np.exp(-ZETA * w * t) * np.cos(
        w * math.sqrt(1 - ZETA**2) * t + rng.uniform(0, 2 * np.pi)
    )
    return wi.Observation(t, y + NOISE * rng.standard_normal(N), name="decay")


def ess_of(chain_1d: np.ndarray) -> tuple[float, float]:
    """(τ, ESS) of one coordinate's chain (steps, walkers)."""
    tau = float(emcee.autocorr.integrated_time(chain_1d[:, :, None], quiet=True)[0])
    steps, walkers = chain_1d.shape
    return tau, walkers * max(steps - 2 * tau, 0) / tau


def run_ours(prob, walkers, steps, zeta_index, move):
    sampler = P.run_sampler(prob, walkers=walkers, steps=1, seed=0, move=move)  # compile
    t0, c0 = time.perf_counter(), time.process_time()
    sampler = P.run_sampler(prob, walkers=walkers, steps=steps, seed=0, move=move)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    z = sampler.get_chain()[:, :, zeta_index]
    tau, ess = ess_of(0.95 / (1 + np.exp(-z)))
    evals = walkers * (steps + 1)
    zeta = 0.95 / (1 + np.exp(-sampler.get_chain()[steps // 5 :, :, zeta_index]))
    return {
        "move": move,
        "zeta_median": float(np.median(zeta)),
        "wall_s": round(wall, 2),
        "cpu_s": round(cpu, 2),
        "steps": steps,
        "log_prob_evals_per_s": round(evals / wall, 1),
        "log_prob_evals_per_cpu_s": round(evals / cpu, 1),
        "tau_zeta": round(tau, 1),
        "ess_zeta": round(ess, 1),
        "ess_per_s": round(ess / wall, 2),
        "acceptance": round(float(np.mean(sampler.acceptance_fraction)), 3),
    }


def run_lmfit(prob, walkers, steps):
    import lmfit

    m = prob.model
    problem = prob.args["problem"]
    rec = problem.recordings[0]
    theta0 = L._unravel(problem, m.marginal)(jnp.asarray(prob.z0[: m.n_theta]))

    @jax.jit
    def resid(log_kappa, zeta, c):
        u = from_interval(zeta, 0.0, ZETA_MAX)
        theta = {"log_kappa": log_kappa, "zeta_u": u, "recs": [{"c": c}]}
        w = problem.whisker(theta)
        D, g = recording_design(rec, w, theta["recs"][0])
        return D @ c + g - rec.y

    def fcn(params):
        v = params.valuesdict()
        # A NumPy vector, not jnp.asarray of a list: JAX builds an array from a Python list
        # element by element (≈ 136 µs here, more than the residual itself).
        c = np.array([v[f"c{i}"] for i in range(4)])
        return np.array(resid(v["log_kappa"], v["zeta"], c))  # writable: lmfit scales it

    params = lmfit.Parameters()
    params.add("log_kappa", value=float(theta0["log_kappa"]))
    zeta0 = float(to_interval(theta0["zeta_u"], 0.0, ZETA_MAX))
    params.add("zeta", value=zeta0, min=0.0, max=ZETA_MAX)
    for i, ci in enumerate(np.asarray(theta0["recs"][0]["c"])):
        params.add(f"c{i}", value=float(ci))
    params.add("__lnsigma", value=float(prob.z0[-1]), min=math.log(1e-6), max=math.log(10.0))
    fcn(params)  # compile
    mini = lmfit.Minimizer(fcn, params)
    t0, c0 = time.perf_counter(), time.process_time()
    res = mini.emcee(
        steps=steps, nwalkers=walkers, burn=0, thin=1, is_weighted=False, seed=0, progress=False
    )
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    names = list(res.var_names)
    tau, ess = ess_of(res.chain[:, :, names.index("zeta")])
    return {
        "wall_s": round(wall, 2),
        "cpu_s": round(cpu, 2),
        "steps": steps,
        "log_prob_evals_per_s": round(walkers * steps / wall, 1),
        "log_prob_evals_per_cpu_s": round(walkers * steps / cpu, 1),
        "tau_zeta": round(tau, 1),
        "ess_zeta": round(ess, 1),
        "ess_per_s": round(ess / wall, 2),
        "acceptance": round(float(np.mean(res.acceptance_fraction)), 3),
        "zeta_median": float(np.median(res.chain[steps // 5 :, :, names.index("zeta")])),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--walkers", type=int, default=32)
    ap.add_argument("--steps", type=int, default=5000)
    ap.add_argument("--lmfit-steps", type=int, help="fewer steps for lmfit (rates compared)")
    ap.add_argument("--cpus", type=int, default=1, help="CPUs to run on (0: all allowed)")
    ap.add_argument(
        "--sync-dispatch",
        action="store_true",
        help="run JAX computations inline (jax_cpu_enable_async_dispatch off), for both",
    )
    args = ap.parse_args(argv)
    import lmfit

    rec, obs = wi.paper_record(), decay(0)
    sampled = P.setup_posterior(rec, obs, n_modes=1, marginalize=False)
    marginal = P.setup_posterior(rec, obs, n_modes=1)
    zi = sampled.names.index("logit_zeta")
    out = {
        "problem": f"one-mode decay, {N} samples; {sampled.z0.size} sampled parameters",
        "settings": {"walkers": args.walkers, "steps": args.steps, "seed": 0},
        "cpus": sorted(os.sched_getaffinity(0)),
        "jax_async_dispatch": bool(jax.config.read("jax_cpu_enable_async_dispatch")),
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "versions": {
            "emcee": emcee.__version__,
            "lmfit": lmfit.__version__,
            "jax": jax.__version__,
            "python": platform.python_version(),
        },
        "lmfit_emcee": run_lmfit(sampled, args.walkers, args.lmfit_steps or args.steps),
        "whiskerid_same_model": run_ours(sampled, args.walkers, args.steps, zi, "stretch"),
        "whiskerid_as_shipped": run_ours(
            marginal, args.walkers, args.steps, marginal.names.index("logit_zeta"), "de"
        ),
    }
    lm, ours = out["lmfit_emcee"], out["whiskerid_same_model"]
    out["speedup_evals_per_s"] = round(ours["log_prob_evals_per_s"] / lm["log_prob_evals_per_s"], 1)
    out["speedup_evals_per_cpu_s"] = round(
        ours["log_prob_evals_per_cpu_s"] / lm["log_prob_evals_per_cpu_s"], 1
    )
    out["speedup_ess_per_s"] = round(ours["ess_per_s"] / max(lm["ess_per_s"], 1e-12), 1)
    out["speedup_ess_per_s_as_shipped"] = round(
        out["whiskerid_as_shipped"]["ess_per_s"] / max(lm["ess_per_s"], 1e-12), 1
    )
    out["target_20x_met"] = out["speedup_evals_per_s"] >= 20
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
