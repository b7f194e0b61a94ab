"""Benchmark: a whisker's f1 and ζ from driving data (no pluck), and how soon a 3 % drop is flagged.

Two kinds of drive, each of ``--minutes`` one-minute runs at mixed terrains and speeds:

* ``terrain``: the project's terrain simulator (:func:`whiskerid.terrain.synthesize_runs`: the
  exact modal model driven by the base motion of the seven terrains, the Hall sensor and the
  ADS1115 at 200 Hz), terrain ``k mod 7`` for run ``k`` at one of the five nominal speeds, of a
  whisker drawn at random (the paper's coil with its shear modulus times a factor that moves
  f1 by −7 … +5 %, ζ uniform in 0.025–0.06);
* ``independent``: a drive written here with numpy/SciPy alone, not with the project's
  simulator or its parameters: a random road profile (slope of its spectrum, level), a robot
  of two or three axles (random wheelbase and weights), a *triangular* contact patch of random
  length (its nulls are sinc⁴, not the box patch's sinc²), a ground spring of random corner,
  a motor tone at a random ratio to the speed with a harmonic, chassis noise; the whisker a
  single mode integrated by :func:`scipy.signal.lsim` (not FFT filtering), a Hall sensor with a
  quadratic term, the ADC's 5 ms average, its noise and 16-bit codes. Speeds 0.08–0.35 m/s.

:func:`whiskerid.fleet.identify_driving` starts from the paper record's f1 and ζ (terrain) or
from f1 a random −4 … +4 % off and ζ 0.04 (independent): a whisker that changed since its
calibration. Printed (JSON): per drive the truth, the estimates, their 1σ, the errors and the
pulls; per kind the largest errors, how many drives meet f1 within 1 % and ζ within 15 %, and
the pulls' standard deviations (near 1 when the 1σ is honest).

``--detect W``: W whiskers (terrain drives), each driven ``--sessions`` times, half of them
with f1 3 % lower (``--drop``) from drive ``--first`` on; every drive is a session of the
health log and :func:`whiskerid.fleet.check_fleet` reads them: the detection rate, the drives
it took, and the false alarms per healthy whisker-session.

``--save-blocks FILE`` appends each drive with its blocks' values (JSON lines): how the blocks
are combined can then be studied without fitting again.

Run: ``python benchmarks/fleet_driving.py [--drives 10 --independent 10 --detect 10]``; the
detection fleet can be split over processes (``--whiskers 0 1 2 --save-rows a.json`` in each,
then ``--load-rows a.json b.json``).
"""

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

RATE = 200.0


def terrain_drive(seed: int, factor: float, zeta: float, minutes: int = 10):
    """``(f1, zeta, signals)`` of a drive of the terrain simulator (see the docstring)."""
    from whiskerid.model import paper_record
    from whiskerid.terrain import SPEEDS_MPS, TERRAINS, RunSpec, synthesize_runs

    rec = paper_record()
    s = rec.structure
    rec = rec.replace(structure=replace(s, shear_modulus_pa=s.shear_modulus_pa * factor**2),
                      zeta=zeta)  # fmt: skip
    rng = np.random.default_rng(seed)
    specs = [RunSpec(TERRAINS[i % 7], float(rng.choice(SPEEDS_MPS)), seed * 100 + i)
             for i in range(minutes)]  # fmt: skip
    runs = synthesize_runs(specs, record=rec, duration_s=60.0, seed=seed)
    signals = [(f"{s.terrain}@{s.speed_mps:g}", r.columns["adc"].astype(float))
               for s, r in zip(specs, runs, strict=True)]  # fmt: skip
    return float(rec.whisker().natural_frequencies_hz[0]), float(rec.zeta), signals


def _profile_acc(rng, v, n, fs):
    """Base acceleration (m/s²) of a robot driving a random road at ``v`` (see the docstring)."""
    dx = 5e-4
    nx = int(v * n / fs / dx) + 4000
    k = np.fft.rfftfreq(nx, dx)  # cycles per metre
    slope = rng.uniform(1.5, 2.6)
    spec = (rng.standard_normal(k.size) + 1j * rng.standard_normal(k.size)) * np.where(
        k > 0, (np.maximum(k, 0.5) / 10.0) ** (-slope / 2), 0.0
    )
    patch = rng.uniform(0.002, 0.025)  # a triangular patch: a box convolved with itself
    spec *= np.sinc(k * patch / 2) ** 4
    z = np.fft.irfft(spec, nx) * 1e-4 * rng.lognormal(0, 0.5)
    x = np.arange(nx) * dx
    axles = [0.0, *sorted(rng.uniform(0.1, 0.4, size=rng.integers(1, 3)))]
    weights = rng.dirichlet(np.full(len(axles), 3.0))
    pos = 0.5 + v * np.arange(n) / fs
    height = sum(w * np.interp(pos + a, x, z) for w, a in zip(weights, axles, strict=True))
    f = np.fft.rfftfreq(n, 1 / fs)
    fg, zg = rng.uniform(8, 60), rng.uniform(0.1, 0.6)
    ground = (fg**2 + 2j * zg * fg * f) / (fg**2 - f**2 + 2j * zg * fg * f)
    acc = np.fft.irfft(-((2 * np.pi * f) ** 2) * ground * np.fft.rfft(height), n)
    t = np.arange(n) / fs
    tone_hz = v * rng.uniform(150, 260)
    level = np.std(acc) * rng.uniform(0.05, 0.5)
    acc += level * (np.sin(2 * np.pi * tone_hz * t) + 0.4 * np.sin(4 * np.pi * tone_hz * t + 1))
    return acc + np.std(acc) * rng.uniform(0.01, 0.1) * rng.standard_normal(n)


def independent_drive(rng: np.random.Generator, f1: float, zeta: float, minutes: int = 10):
    """Signals (ADC codes at 200 Hz) of a drive written with numpy/SciPy alone."""
    from scipy.signal import lsim

    fs, m = 2000.0, 10  # simulated at 2 kHz, each code the mean of one 5 ms conversion
    n = int(60 * fs)
    w1 = 2 * np.pi * f1
    t = np.arange(n) / fs
    out = []
    for k in range(minutes):
        v = rng.uniform(0.08, 0.35)
        acc = _profile_acc(rng, v, n, fs)
        # x'' + 2ζω₁x' + ω₁²x = −a_base: the tip's deflection relative to its base
        _, x, _ = lsim(([-1.0], [1.0, 2 * zeta * w1, w1**2]), acc, t)
        x = x / np.std(x)
        volts = 0.4 * (x + rng.uniform(-0.05, 0.05) * x**2)
        volts = volts.reshape(-1, m).mean(axis=1) + 2.5e-4 * rng.standard_normal(n // m)
        codes = np.clip(np.round(volts / (4.096 / 32768)), -32768, 32767)
        out.append((f"run-{k}@{v:.2f}", codes))
    return out


def _entry(kind, seed, f1, zeta, fit, seconds):
    return {
        "kind": kind, "seed": seed, "f1_true": f1, "zeta_true": zeta, "status": fit.status,
        "f1_hz": fit.f1_hz, "f1_std": fit.f1_std, "zeta": fit.zeta, "zeta_std": fit.zeta_std,
        "f1_error_pct": 100 * (fit.f1_hz / f1 - 1), "zeta_error_pct": 100 * (fit.zeta / zeta - 1),
        "f1_pull": (fit.f1_hz - f1) / fit.f1_std, "zeta_pull": (fit.zeta - zeta) / fit.zeta_std,
        "blocks_used": sum(b["status"] == "ok" for b in fit.blocks),
        "identify_s": round(seconds, 1),
    }  # fmt: skip


def _summary(entries):
    ok = [d for d in entries if d["status"] == "ok"]
    e1 = np.array([d["f1_error_pct"] for d in ok])
    ez = np.array([d["zeta_error_pct"] for d in ok])
    p1 = np.array([d["f1_pull"] for d in ok])
    pz = np.array([d["zeta_pull"] for d in ok])
    return {
        "drives": len(entries), "ok": len(ok),
        "f1_within_1pct": int(np.sum(np.abs(e1) < 1)),
        "zeta_within_15pct": int(np.sum(np.abs(ez) < 15)),
        "max_abs_f1_error_pct": float(np.max(np.abs(e1))),
        "rms_f1_error_pct": float(np.sqrt(np.mean(e1**2))),
        "max_abs_zeta_error_pct": float(np.max(np.abs(ez))),
        "rms_zeta_error_pct": float(np.sqrt(np.mean(ez**2))),
        "median_f1_std_pct": float(np.median([100 * d["f1_std"] / d["f1_true"] for d in ok])),
        "median_zeta_std_pct": float(np.median([100 * d["zeta_std"] / d["zeta_true"] for d in ok])),
        "f1_pull_sd": float(np.std(p1, ddof=1)), "zeta_pull_sd": float(np.std(pz, ddof=1)),
        # with a bias the pulls' root mean square is what a z-score sees
        "f1_pull_rms": float(np.sqrt(np.mean(p1**2))),
        "zeta_pull_rms": float(np.sqrt(np.mean(pz**2))),
        "f1_pull_mean": float(np.mean(p1)), "zeta_pull_mean": float(np.mean(pz)),
        "f1_pulls_beyond_3": int(np.sum(np.abs(p1) > 3)),
        "zeta_pulls_beyond_3": int(np.sum(np.abs(pz) > 3)),
    }  # fmt: skip


def _print(entry, fit, args):
    print(json.dumps(entry), flush=True)
    if args.save_blocks:  # each drive's blocks, to study how they are combined
        with open(args.save_blocks, "a") as fh:
            fh.write(json.dumps({**entry, "blocks": fit.blocks}) + "\n")


def accuracy(args, f1_start, zeta_start):
    from whiskerid.fleet import identify_driving

    out = []
    for k in range(args.drives):
        rng = np.random.default_rng(1000 + k + 1)  # drive k + 1: its whisker
        f1, zeta, signals = terrain_drive(k + 1, rng.uniform(0.93, 1.05), rng.uniform(0.025, 0.06),
                                          args.minutes)  # fmt: skip
        t0 = time.perf_counter()
        fit = identify_driving(signals, RATE, f1_start, zeta_start)
        out.append(_entry("terrain", k + 1, f1, zeta, fit, time.perf_counter() - t0))
        _print(out[-1], fit, args)
    for k in range(args.independent):
        rng = np.random.default_rng(5000 + k)
        f1, zeta = rng.uniform(30, 70), rng.uniform(0.02, 0.07)
        signals = independent_drive(rng, f1, zeta, args.minutes)
        t0 = time.perf_counter()
        fit = identify_driving(signals, RATE, f1 * rng.uniform(0.96, 1.04), 0.04)
        out.append(_entry("independent", 5000 + k, f1, zeta, fit, time.perf_counter() - t0))
        _print(out[-1], fit, args)
    kinds = [k for k in ("terrain", "independent") if any(d["kind"] == k for d in out)]
    return {kind: _summary([d for d in out if d["kind"] == kind]) for kind in kinds}


def _upper95(k: int, n: int) -> float:
    """One-sided 95 % upper bound (Clopper–Pearson) on a rate seen k times in n."""
    from scipy.stats import beta

    return float(beta.ppf(0.95, k + 1, n - k)) if n > k else 1.0


def detection(args, f1_start, zeta_start):
    """Health logs of ``--detect`` whiskers checked by :func:`whiskerid.fleet.check_fleet`."""
    from whiskerid.fleet import check_fleet, health_row, identify_driving

    rows, damaged = [], {}
    for w in range(args.detect):
        if w % 2:
            damaged[f"w{w:02d}"] = args.first
    for path in args.load_rows:  # the rows of earlier runs (several processes at once)
        rows += json.loads(Path(path).read_text())
    done = {r["whisker"] for r in rows}
    for w in args.whiskers or range(args.detect):
        if f"w{w:02d}" in done:
            continue
        rng = np.random.default_rng(9000 + w)
        factor, zeta = rng.uniform(0.95, 1.03), rng.uniform(0.025, 0.06)
        for d in range(args.sessions):
            drop = 1 - args.drop if (w % 2 and d >= args.first) else 1.0
            seed = 10_000 + 100 * w + d
            _, _, signals = terrain_drive(seed, factor * drop, zeta, args.minutes)
            fit = identify_driving(signals, RATE, f1_start, zeta_start)
            row = health_row(f"w{w:02d}", f"drive-{d:02d}", fit, [])
            rows.append({**row, "source": "drive"})
        print(f"whisker {w + 1}/{args.detect} driven", flush=True)
    if args.save_rows:
        Path(args.save_rows).write_text(json.dumps(rows))
    result = check_fleet(rows)
    events = {e["whisker"]: e for e in result.events if e["parameter"] == "f1_hz"}
    flagged = {(f["whisker"], f["session"]) for f in result.flags}  # either parameter
    checked = {(c["whisker"], c["session"]) for c in result.changes if c["parameter"] == "f1_hz"}
    healthy = {(w, s) for w, s in checked
               if w.split()[0] not in damaged or int(s[-2:]) < damaged[w.split()[0]]}  # fmt: skip
    delays = []  # drives after the damage (incl.) until the one that *found* the change
    for w, first in damaged.items():
        found_at = [int(e["detected"][-2:]) for ww, e in events.items() if ww.split()[0] == w]
        delays.append(found_at[0] - first + 1 if found_at and found_at[0] >= first else None)
    located = sum(
        int(e["began"][-2:]) == damaged[w.split()[0]]
        for w, e in events.items()
        if w.split()[0] in damaged
    )
    found = [d for d in delays if d is not None]
    return {
        "whiskers": args.detect, "damaged": len(damaged), "sessions": args.sessions,
        "first_damaged_drive": args.first, "drop": args.drop, "minutes_per_drive": args.minutes,
        "detected": len(found), "detection_rate": len(found) / max(len(damaged), 1),
        "drives_to_detection": delays,
        "detected_in_first_drive": sum(d == 1 for d in found),
        "healthy_sessions_checked": len(healthy),
        "false_alarms": len(flagged & healthy),
        "false_alarm_rate": len(flagged & healthy) / max(len(healthy), 1),
        "false_alarm_rate_95pct_upper": _upper95(len(flagged & healthy), len(healthy)),
        "located_where_it_began": located,
        "f1_events": {w: {k: e.get(k) for k in ("began", "detected", "size_pct", "rule")}
                      for w, e in events.items()},
    }  # fmt: skip


def main() -> None:
    from whiskerid.model import paper_record

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drives", type=int, default=10, help="terrain-simulator drives")
    ap.add_argument("--independent", type=int, default=10, help="drives written with numpy")
    ap.add_argument("--minutes", type=int, default=10, help="one-minute runs per drive")
    ap.add_argument("--detect", type=int, default=0, help="whiskers of the detection fleet")
    ap.add_argument("--sessions", type=int, default=6, help="drives per whisker (detection)")
    ap.add_argument("--first", type=int, default=3, help="first drive with the drop (0-based)")
    ap.add_argument("--drop", type=float, default=0.03, help="relative f1 drop (detection)")
    ap.add_argument("--whiskers", type=int, nargs="*", help="only these whiskers (detection)")
    ap.add_argument("--save-blocks", help="append each drive with its blocks (JSON lines)")
    ap.add_argument("--save-rows", help="write the detection fleet's health rows (JSON)")
    ap.add_argument("--load-rows", nargs="*", default=[], help="rows of earlier runs (JSON)")
    args = ap.parse_args()
    paper = paper_record()
    f1_start = float(paper.whisker().natural_frequencies_hz[0])
    zeta_start = float(paper.zeta)
    out = {"accuracy": accuracy(args, f1_start, zeta_start)}
    if args.detect:
        out["detection"] = detection(args, f1_start, zeta_start)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
