"""Checks of the emcee posteriors: interval coverage over seeded synthetic datasets, and
agreement with an independent sampler (numpyro NUTS) on one problem. Prints one JSON object.

Synthetic problem: a one-mode free decay of the paper whisker's record, f_1 = 48 Hz,
ζ = 0.02, 500 samples at 1 kHz with jittered timestamps, white noise σ = 0.05 (amplitude 1,
offset 0.3, random phase). Gaussian likelihood, linear nuisances marginalised, default priors.

    .venv/bin/python benchmarks/posterior_checks.py coverage [--datasets 100] [--first 0]
    .venv/bin/python benchmarks/posterior_checks.py nuts [--steps 5000]
"""

import argparse
import json
import math
import sys
import time

import numpy as np

import whiskerid as wi
from whiskerid import posterior as P
from whiskerid.posterior import _likelihood as L

F1, ZETA, NOISE, N = 48.0, 0.02, 0.05, 500


def decay(seed: int) -> wi.Observation:
    rng = np.random.default_rng(seed)
    t = np.arange(N) / 1000.0 + rng.uniform(0, 2e-4, N)
    w = 2 * np.pi * F1
    y = 0.3 + np.exp(-ZETA * w * t) * np.cos(
        w * math.sqrt(1 - ZETA**2) * t + rng.uniform(0, 2 * np.pi)
    )
    return wi.Observation(t, y + NOISE * rng.standard_normal(N), name=f"decay-{seed}")


def coverage(n: int, walkers: int, steps: int, first: int = 0) -> dict:
    levels = {"68": (16, 84), "90": (5, 95), "95": (2.5, 97.5)}
    hits = {k: {"zeta": 0, "f1_hz": 0} for k in levels}
    converged, t0 = 0, time.perf_counter()
    for i in range(n):
        post = P.sample_posterior(
            wi.paper_record(),
            decay(1000 + first + i),
            n_modes=1,
            walkers=walkers,
            steps=steps,
            seed=first + i,
        )
        converged += post.diagnostics["converged"]
        for name, truth in (("zeta", ZETA), ("f1_hz", F1)):
            x = post.samples[:, post.names.index(name)]
            for k, (lo, hi) in levels.items():
                a, b = np.percentile(x, [lo, hi])
                hits[k][name] += int(a < truth < b)
        print(f"{i + 1}/{n}", file=sys.stderr, end="\r")
    return {
        "datasets": n,
        "first_seed": first,
        "walkers": walkers,
        "steps": steps,
        "converged_runs": converged,
        "rates": {k: {p: v / n for p, v in h.items()} for k, h in hits.items()},
        "nominal": {k: int(k) / 100 for k in levels},
        "wall_s": round(time.perf_counter() - t0, 1),
    }


def nuts(walkers: int, steps: int, nuts_samples: int) -> dict:
    import jax
    from numpyro.infer import MCMC, NUTS

    prob = P.setup_posterior(wi.paper_record(), decay(7), n_modes=1)
    t0 = time.perf_counter()
    post = P.summarize(prob, P.run_sampler(prob, walkers=walkers, steps=steps, seed=0), seed=0)
    t_emcee = time.perf_counter() - t0

    def potential(z):
        return -L.log_prob_one(prob.model, z, prob.args)

    t0 = time.perf_counter()
    mcmc = MCMC(
        NUTS(potential_fn=potential),
        num_warmup=2000,
        num_samples=nuts_samples,
        num_chains=1,
        progress_bar=False,
    )
    mcmc.run(jax.random.PRNGKey(0), init_params=jax.numpy.asarray(prob.z0))
    z = np.asarray(mcmc.get_samples())
    t_nuts = time.perf_counter() - t0
    vals, names = P.derived_quantities(prob, z)
    out = {"emcee": {}, "nuts": {}, "diff_in_sd": {}}
    for name in ("zeta", "f1_hz"):
        x = vals[:, names.index(name)]
        e = post.params[name]
        out["emcee"][name] = {"mean": e["mean"], "sd": e["std"], "ess": e["ess"]}
        out["nuts"][name] = {"mean": float(x.mean()), "sd": float(x.std())}
        out["diff_in_sd"][name] = {
            "mean": abs(e["mean"] - x.mean()) / e["std"],
            "sd": abs(e["std"] - x.std()) / e["std"],
        }
    out["ok_within_0.1_sd"] = all(v < 0.1 for d in out["diff_in_sd"].values() for v in d.values())
    out["emcee_settings"] = {"walkers": walkers, "steps": steps, "wall_s": round(t_emcee, 1)}
    out["emcee_converged"] = post.diagnostics["converged"]
    out["nuts_settings"] = {"warmup": 2000, "samples": nuts_samples, "wall_s": round(t_nuts, 1)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("check", choices=("coverage", "nuts"))
    ap.add_argument("--datasets", type=int, default=100)
    ap.add_argument("--walkers", type=int, default=32)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--first", type=int, default=0, help="first dataset seed (more batches)")
    ap.add_argument("--nuts-samples", type=int, default=20000)
    args = ap.parse_args(argv)
    if args.check == "coverage":
        res = coverage(args.datasets, args.walkers, args.steps, args.first)
    else:
        res = nuts(args.walkers, args.steps, args.nuts_samples)
    print(json.dumps({"check": args.check, **res}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
