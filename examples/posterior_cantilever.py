"""ζ posteriors of the real aluminium cantilever: per recording and pooled per length (emcee).

Data: ``../shared/data/cantilever`` (plucked 50 × 2 mm aluminium beam, 30 cm and 50 cm,
five repeats each; acceleration in g at about 4 kHz with gaps). Records: the calibrated
``fits/cantilever-aluminium-<L>cm.toml`` (one mode, f_1 and ζ fitted, EI from the geometry).

To keep the run to a few minutes each recording is cut to ``--seconds`` after the release
and every k-th sample is kept (at most ``--max-samples``; the model is evaluated at the
kept timestamps, so nothing is resampled). The 1-mode model leaves structured residuals
(the second mode, nonlinearity, a non-exponential envelope): the white-noise likelihood then
gives intervals that are too narrow, and the spread of the per-recording medians across
repeats is the more honest measure of what is known about ζ.

Run length: each chain runs ``--steps`` (4000) and, while it is shorter than 50 τ, is
extended to 1.1 × the length the current τ asks for, up to ``--max-steps`` (12000); with
the default (differential-evolution) move pooled runs over the repeats need about 1200
steps (τ ≈ 24) and per-recording ones about 550 (τ ≈ 11). Every run reports τ, the steps
it ran, the steps 50 τ needs and whether it reached them (a run stopped by the cap says
``converged: false``). Prints one JSON object; writes corner/trace plots into ``--out``.

    .venv/bin/python examples/posterior_cantilever.py [--steps 4000] [--max-steps 12000]
        [--out DIR]
"""

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

import whiskerid as wi
from whiskerid import posterior as P
from whiskerid.fit import G0, release_time

ROOT = Path(__file__).resolve().parents[1]


def observation(path: Path, seconds: float, max_samples: int) -> wi.Observation:
    a = np.load(path)
    obs = wi.Observation(
        a[0], a[1] * G0, observable="acceleration", name=path.stem, source=str(path)
    )
    t0 = release_time(obs.t, obs.y)
    obs = obs.window(t0, t0 + seconds)
    step = max(1, int(np.ceil(obs.t.size / max_samples)))
    return wi.Observation(
        obs.t[::step], obs.y[::step], observable="acceleration", name=path.stem, source=str(path)
    )


def sample(record, obs, walkers: int, steps: int, max_steps: int, seed: int):
    """emcee run extended until 50 τ (τ re-estimated after each extension) or ``max_steps``."""
    prob = P.setup_posterior(record, obs)
    walkers = max(walkers, 2 * prob.z0.size)
    sampler = P.run_sampler(prob, walkers=walkers, steps=steps, seed=seed)
    post = P.summarize(prob, sampler, seed=seed)
    extensions = 0
    while not post.diagnostics["converged"] and post.diagnostics["steps"] < max_steps:
        done = post.diagnostics["steps"]
        needed = post.diagnostics["steps_needed"] or 2 * done
        target = min(max_steps, max(math.ceil(1.1 * needed), done + 500))
        sampler.run_mcmc(None, target - done)  # continues the chain and its random state
        post = P.summarize(prob, sampler, seed=seed)
        extensions += 1
    return post, extensions


def summary(post, extensions: int = 0) -> dict:
    z, f = post.params["zeta"], post.params["f1_hz"]
    d = post.diagnostics
    return {
        "zeta": {k: z[k] for k in ("median", "q16", "q84", "q2.5", "q97.5", "tau", "ess")},
        "f1_hz": {k: f[k] for k in ("median", "q16", "q84")},
        "acceptance": round(d["acceptance"], 3),
        "max_tau": round(d["max_tau"], 1),
        "converged": d["converged"],
        "steps": d["steps"],
        "steps_needed": d["steps_needed"],
        "extensions": extensions,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "cantilever")
    ap.add_argument("--fits", type=Path, default=ROOT / "fits")
    ap.add_argument("--out", type=Path, default=Path("posterior-cantilever"))
    ap.add_argument("--walkers", type=int, default=32)
    ap.add_argument("--steps", type=int, default=4000)
    ap.add_argument("--max-steps", type=int, default=12000)
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--max-samples", type=int, default=1500)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    if not args.data.exists():
        print(f"no data at {args.data}", file=sys.stderr)
        return 2
    from whiskerid.plot import plot_corner, plot_trace

    args.out.mkdir(parents=True, exist_ok=True)
    out = {"settings": {k: str(v) for k, v in vars(args).items()}, "lengths": {}}
    for length_cm in (30, 50):
        record = wi.load_record(args.fits / f"cantilever-aluminium-{length_cm}cm.toml")
        paths = sorted((args.data / f"{length_cm}cm").glob("*.npy"))
        obs = [observation(p, args.seconds, args.max_samples) for p in paths]
        per = {}
        run = {"walkers": args.walkers, "steps": args.steps, "max_steps": args.max_steps}
        for o in obs:
            post, ext = sample(record, o, seed=args.seed, **run)
            per[o.name] = summary(post, ext)
            print(f"{length_cm} cm {o.name}: {per[o.name]}", file=sys.stderr)
        pooled, ext = sample(record, obs, seed=args.seed, **run)
        stem = args.out / f"{length_cm}cm"
        plot_corner(f"{stem}-pooled-corner.png", pooled, names=("f1_hz", "zeta", "EI"))
        plot_trace(f"{stem}-pooled-trace.png", pooled)
        pooled.record.save(f"{stem}-pooled-posterior.toml")
        medians = [v["zeta"]["median"] for v in per.values()]
        out["lengths"][f"{length_cm}cm"] = {
            "per_recording": per,
            "pooled": summary(pooled, ext),
            "spread_of_medians": {"mean": float(np.mean(medians)), "sd": float(np.std(medians))},
        }
        print(f"{length_cm} cm pooled: {summary(pooled, ext)}", file=sys.stderr)
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
