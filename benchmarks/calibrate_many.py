"""Benchmark: many whiskers calibrated in one process, each compiled once or not at all.

50 recordings of 50 different coil whiskers (random length, wire and coil radius, number of
coils, sensor position; the paper whisker's material), each a pluck read by the ADS1115 at
200 Hz for 10 s (SNR 30 dB), calibrated by :func:`whiskerid.calibrate` from a nominal record
30 % off in f_1. The whisker's numbers are traced leaves of the fit problem, so only the
first fit compiles. Reports the number of XLA compilations per fit (counted with
``jax.monitoring``), the first fit's time (compilation included), the warm time per fit,
the errors of f_1 and ζ, and the fits' statuses (a whisker whose f_1 is near the 100 Hz
Nyquist frequency is ``check``: its alias fits as well). The peer, measured in the same run,
is the same fit compiled anew for each whisker (JAX's caches cleared before each of
``--peer-fits`` fits), which is what a fit whose numbers are part of the compiled code's
cache key costs. A second peer is SciPy: ``benchmarks/scipy_pluck.py``'s fit (the same model:
offset, drift, two modes with f_2 tied to f_1, the ADS1115's conversion averaged; started at
the largest spectral peak below the Nyquist frequency) on the same recordings, with its time per
fit and its errors; both are counted right when f_1 is within 0.1 % of the truth. Each
round fits every whisker by us and then every whisker by SciPy, so that a drift of the
machine's speed reaches both alike over ``--rounds`` rounds; the warm pairs (a whisker's two
fits in one round; our first fit, which compiles or loads the program, is reported apart)
give ``warm_over_scipy``, the ratio of the two medians, and
``warm_over_scipy_paired_median``, the median of the pairs' ratios. (Fits alternated one by
one would not do: after a call SciPy's two BLAS threads spin for a while on the core our next
fit needs, and our CPU time counted them.)

Run: ``python benchmarks/calibrate_many.py [--whiskers N] [--duration S] [--rounds R]``
(prints JSON).
"""

import argparse
import json
import os
import platform
import statistics
import time
from dataclasses import replace

import jax
import numpy as np

import whiskerid as wi
from whiskerid.fit._numerics import _aot as _aot
from whiskerid.model import CoilSpring

_COMPILES: list[float] = []


def _listen(event, duration, **kwargs):
    if event == "/jax/core/compile/backend_compile_duration":
        _COMPILES.append(duration)


def _whiskers(n: int, seed: int):
    """``n`` random coil whiskers around the paper's (records with their true numbers)."""
    rng = np.random.default_rng(seed)
    base = wi.paper_record()
    out = []
    for _ in range(n):
        length = rng.uniform(0.045, 0.080)
        coil = CoilSpring(
            length_m=length,
            wire_radius_m=rng.uniform(0.4e-3, 0.6e-3),
            mean_coil_radius_m=rng.uniform(3.5e-3, 5.5e-3),
            n_coils=int(rng.integers(10, 17)),
            wire_density_kg_m3=8050.0,
            shear_modulus_pa=70e9,
        )
        x_s = rng.uniform(0.05, 0.15) * length
        out.append(base.replace(structure=coil, sensor_position_m=x_s))
    return out


def _nominal(record):
    """The record a user starts from: f_1 30 % high."""
    s = record.structure
    return record.replace(structure=replace(s, shear_modulus_pa=s.shear_modulus_pa * 1.3**2))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--whiskers", type=int, default=50)
    ap.add_argument("--duration", type=float, default=10.0, help="seconds per recording")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--peer-fits", type=int, default=3, help="fits compiled anew (the peer)")
    ap.add_argument(
        "--rounds", type=int, default=3, help="passes over the whiskers (ours, then SciPy's)"
    )
    args = ap.parse_args()
    jax.monitoring.register_event_duration_secs_listener(_listen)
    records = _whiskers(args.whiskers, args.seed)
    observations = []
    for k, rec in enumerate(records):
        sim = wi.simulate(rec, excitation="decay", observable="adc", rate_hz=200,
                          duration_s=args.duration, noise_db=30, seed=k,
                          tip_deflection_m=2e-3)  # fmt: skip
        observations.append(
            wi.Observation(sim.t, sim.signal(), excitation="decay", observable="adc", gain=None)
        )
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from scipy_pluck import fit as scipy_fit

    def ours(rec, obs):
        before = len(_COMPILES)
        t0, c0 = time.perf_counter(), time.process_time()
        cal = wi.calibrate(_nominal(rec), obs)
        return cal, time.perf_counter() - t0, time.process_time() - c0, len(_COMPILES) - before

    def scipy(rec, obs):
        f = np.asarray(rec.whisker().natural_frequencies_hz)
        t0, c0 = time.perf_counter(), time.process_time()
        sp = scipy_fit(obs.t, obs.y, ratio=float(f[1] / f[0]),
                       conversion_s=rec.adc.conversion_time_s)  # fmt: skip
        return sp, time.perf_counter() - t0, time.process_time() - c0

    # Rounds of our fits of every whisker, then SciPy's of every whisker: a drift of the
    # machine's speed (other processes, the clock) reaches both alike over the rounds, and
    # neither runs right after the other's fit (SciPy's two BLAS threads keep spinning for a
    # while after a call, on the core our fit would have).
    times, cpu, compiles, f1_err, zeta_err, ok, status = [], [], [], [], [], [], []
    scipy_times, scipy_cpu, scipy_f1_err, ratios = [], [], [], []
    pairs = list(zip(records, observations, strict=True))
    for rnd in range(args.rounds):
        ours_round = [ours(rec, obs) for rec, obs in pairs]
        scipy_round = [scipy(rec, obs) for rec, obs in pairs]
        for k, ((cal, dt, dc, n_comp), (sp, st, sc), (rec, _)) in enumerate(
            zip(ours_round, scipy_round, pairs, strict=True)
        ):
            compiles.append(n_comp)  # every round's: none after the first fit
            if rnd == 0:
                w = rec.whisker()
                f1_err.append(cal.params["f1_hz"]["value"] / float(w.natural_frequencies_hz[0]) - 1)
                zeta_err.append(cal.params["zeta"]["value"] / float(w.zeta[0]) - 1)
                ok.append(cal.ok)
                status.append(cal.status)
                scipy_f1_err.append(sp["f1_hz"] / float(w.natural_frequencies_hz[0]) - 1)
                if k == 0:  # our first fit compiles (or loads) its program: reported apart
                    first_fit_s = dt
                    continue
            times.append(dt)
            cpu.append(dc)
            scipy_times.append(st)
            scipy_cpu.append(sc)
            ratios.append(dt / st)
    peer_times, peer_compiles = [], []
    for rec, obs in list(zip(records, observations, strict=True))[1 : 1 + args.peer_fits]:
        jax.clear_caches()  # and the calibration's program, in memory and on disk:
        _aot._PROGRAMS.clear()
        _aot.cache_dir = lambda: None
        before = len(_COMPILES)
        t0 = time.perf_counter()
        wi.calibrate(_nominal(rec), obs)
        peer_times.append(time.perf_counter() - t0)
        peer_compiles.append(len(_COMPILES) - before)
    print(
        json.dumps(
            {
                "whiskers": args.whiskers,
                "samples_per_recording": int(observations[0].t.size),
                "compilations_first_fit": compiles[0],
                "compilations_later_fits": int(sum(compiles[1:])),
                "first_fit_s": round(first_fit_s, 3),
                "warm_pairs": len(times),
                "warm_fit_s_median": round(statistics.median(times), 4),
                "warm_fit_s_min": round(min(times), 4),
                "warm_fit_cpu_s_median": round(statistics.median(cpu), 4),
                "converged": int(sum(ok)),
                "peer_recompiled_fit_s_median": (
                    round(statistics.median(peer_times), 3) if peer_times else None
                ),
                "peer_compilations_per_fit": (
                    statistics.median(peer_compiles) if peer_compiles else None
                ),
                "f1_rel_error_median": float(np.median(np.abs(f1_err))),
                "f1_rel_error_max": float(np.max(np.abs(f1_err))),
                "statuses": {k: status.count(k) for k in sorted(set(status))},
                "f1_rel_error_max_status_ok": float(
                    max(
                        (abs(e) for e, s in zip(f1_err, status, strict=True) if s == "ok"),
                        default=float("nan"),
                    )
                ),
                "zeta_rel_error_median": float(np.median(np.abs(zeta_err))),
                "f1_within_0.1%": int(np.sum(np.abs(f1_err) < 1e-3)),
                "scipy_fit_s_median": round(statistics.median(scipy_times), 4),
                "scipy_fit_cpu_s_median": round(statistics.median(scipy_cpu), 4),
                "scipy_f1_within_0.1%": int(np.sum(np.abs(scipy_f1_err) < 1e-3)),
                "warm_over_scipy": round(
                    statistics.median(times) / statistics.median(scipy_times), 3
                ),
                "warm_over_scipy_paired_median": round(statistics.median(ratios), 3),
                "warm_over_scipy_cpu": round(
                    statistics.median(cpu) / statistics.median(scipy_cpu), 3
                ),
                "load_average_1min": round(os.getloadavg()[0], 2),
                "jax": jax.__version__,
                "cpu": platform.processor() or platform.machine(),
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
