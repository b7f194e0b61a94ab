"""Fitted contact features: do they add accuracy on contact-simulated terrains, speeds
held out? Prints one JSON object.

Per recording, the contact parameters (stiffness, preload, friction, roughness, slope) are
fitted through the contact simulator (:func:`whiskerid.terrain.fit_contact`; cached in an
NPZ), then a classifier is trained on the fitted window features with and without them
appended (each window gets its recording's fitted parameters), and evaluated on recordings
at speeds it never saw. Also: how the fitted values relate to the simulator's true ones
(each recording's metadata), and the cost per recording.

    whiskerid dataset synth --contact --out TRAIN --runs 2 --duration 20 --speeds 0.1 0.2 0.3
    whiskerid dataset synth --contact --out TEST --runs 2 --duration 20 --speeds 0.15 0.25 --seed 1
    .venv/bin/python benchmarks/contact_features.py TRAIN TEST --cache /tmp/fits.npz
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def _truth(meta: dict) -> dict:
    """True contact parameters from a recording's ``contact`` metadata, with the
    effective (tangent) stiffness at the static load."""
    kv = dict(item.split("=") for item in meta["contact"].split()[1:])
    k, n, d0 = float(kv["k"]), float(kv["n"]), float(kv["preload_m"])
    # static penetration: δ + flex·k δⁿ·lever = d₀ (tip flexibility 1/47.7 m/N, θ = −0.26)
    mu, th = float(kv["mu"]), float(kv["tilt_rad"])
    lever = np.cos(th) - mu * np.sin(th)
    lo, hi = 0.0, d0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        g = mid - d0 + np.cos(th) * lever * k * mid**n / 47.74
        lo, hi = (mid, hi) if g < 0 else (lo, mid)
    k_eff = n * k * max(lo, 1e-12) ** (n - 1)
    return {"k_eff": k_eff, "preload": d0, "friction": mu}


def fit_all(ws, cache: Path, lsb: float, amplifier: float) -> dict:
    from whiskerid.terrain import contact_twin, fit_contact
    from whiskerid.terrain._contact_fit import PRIOR_MEAN, PRIOR_SD

    done = dict(np.load(cache)) if cache.exists() else {}
    # the cheapest twin that still fits (one 3 s draw, 12 steps): the machine is shared
    twin = contact_twin(0.2, amplifier=amplifier, draws=1, duration_s=3.0)
    for r, name in enumerate(ws.sources):
        key = Path(name).name
        if key + ":params" in done:
            continue
        volts = ws.windows[ws.recording == r].reshape(-1) * lsb
        t0 = time.perf_counter()
        speed = float(ws.speeds[ws.recording == r][0])
        try:
            fit = fit_contact(volts, speed, twin=twin.at_speed(speed), max_steps=12)
            params, sd, chi2, steps = fit.params, fit.sd, fit.chi2, fit.steps
        except FloatingPointError:  # counted as failed; the features say "no information"
            params, sd, chi2, steps = PRIOR_MEAN, PRIOR_SD, np.nan, 0
        done[key + ":params"] = params
        done[key + ":sd"] = sd
        done[key + ":info"] = np.array([chi2, steps, time.perf_counter() - t0])
        np.savez(cache, **done)
        print(
            f"{key}: {np.round(params, 2)} chi2 {chi2:.1f} {time.perf_counter() - t0:.1f} s",
            file=sys.stderr,
            flush=True,
        )
    return done


def contact_columns(ws, fits: dict) -> np.ndarray:
    """Each window's recording's fitted parameters, shape ``(windows, 5)``."""
    rows = np.stack([fits[Path(n).name + ":params"] for n in ws.sources])
    return rows[ws.recording]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("train")
    ap.add_argument("test")
    ap.add_argument("--cache", default="/tmp/contact_fits.npz")
    ap.add_argument("--seeds", type=int, default=3, help="classifier seeds averaged")
    args = ap.parse_args()

    import whiskerid as wi
    from whiskerid.classify import default_config, default_spec, features_of, fit_on_features
    from whiskerid.classify._evaluate import evaluate_features
    from whiskerid.model import paper_record
    from whiskerid.terrain import PARAM_NAMES

    train = wi.load_dataset(args.train)
    test = wi.load_dataset(args.test, labels=train.label_names)
    lsb = paper_record().adc.lsb_v
    amp = float(train.metas[0].get("amplifier", 20))
    cache = Path(args.cache)
    fits = fit_all(train, cache, lsb, amp)
    fits.update(fit_all(test, cache, lsb, amp))
    info = np.stack([fits[Path(n).name + ":info"] for n in train.sources + test.sources])
    cost, failed = info[:, 2], int(np.isnan(info[:, 0]).sum())
    chi2 = info[~np.isnan(info[:, 0]), 0]

    spec = default_spec(train, "fitted")
    plain = {"train": features_of(train, spec), "test": features_of(test, spec)}
    extra = {"train": contact_columns(train, fits), "test": contact_columns(test, fits)}
    out = {}
    for mode in ("fitted", "fitted+contact", "contact only"):
        fused, win, rec = [], [], []
        for seed in range(args.seeds):
            cfg = default_config("fitted")
            cfg = type(cfg)(**{**cfg.__dict__, "seed": seed})

            def cols(part, mode=mode):
                if mode == "fitted":
                    return plain[part]
                if mode == "contact only":
                    return extra[part]
                return np.concatenate([plain[part], extra[part]], axis=1)

            model = fit_on_features(cols("train"), train, spec, cfg, context_s=3.0)
            rep = evaluate_features(model, cols("test"), test)
            fused.append(rep["accuracy"])
            win.append(rep["accuracy_per_window"])
            rec.append(rep["accuracy_per_recording"])
        out[mode] = {"accuracy_3s_context": round(float(np.mean(fused)), 4),
                     "accuracy_per_window": round(float(np.mean(win)), 4),
                     "accuracy_per_window_per_seed": [round(float(a), 4) for a in win],
                     "accuracy_per_recording": round(float(np.mean(rec)), 4)}  # fmt: skip

    # fitted against true values, over all recordings
    rel = {}
    names = train.sources + test.sources
    metas = train.metas + test.metas
    truth = [_truth(m) for m in metas]
    est = np.stack([fits[Path(n).name + ":params"] for n in names])
    sds = np.stack([fits[Path(n).name + ":sd"] for n in names])
    for j, key in ((0, "k_eff"), (1, "preload"), (2, "friction")):
        t = np.log([tr[key] for tr in truth])
        rel[PARAM_NAMES[j]] = {
            "spearman_with_truth": round(float(_spearman(est[:, j], t)), 3),
            "median_abs_ln_error": round(float(np.median(np.abs(est[:, j] - t))), 3),
            "median_sd": round(float(np.median(sds[:, j])), 3),
        }
    terr = [m["terrain"] for m in metas]
    by_terrain = {t: np.round(est[[x == t for x in terr]].mean(axis=0), 2).tolist()
                  for t in sorted(set(terr))}  # fmt: skip
    print(json.dumps({"benchmark": "contact_features", "train": args.train, "test": args.test,
                      "train_recordings": len(train.sources),
                      "test_recordings": len(test.sources), "accuracy": out,
                      "fit_vs_truth": rel, "mean_fit_by_terrain": by_terrain,
                      "param_names": list(PARAM_NAMES),
                      "fits_failed": failed,
                      "chi2_median": round(float(np.median(chi2)), 2),
                      "chi2_dof": 10 - 5,
                      "fit_s_per_recording_median": round(float(np.median(cost)), 2),
                      "fit_s_per_recording_max": round(float(np.max(cost)), 2),
                      "note": "shared, loaded 2-core machine"}, indent=1))  # fmt: skip


def _spearman(a, b) -> float:
    ra, rb = np.argsort(np.argsort(a)), np.argsort(np.argsort(b))
    return float(np.corrcoef(ra, rb)[0, 1])


if __name__ == "__main__":
    main()
