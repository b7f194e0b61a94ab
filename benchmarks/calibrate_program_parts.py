"""Benchmark: where a warm calibration's compiled program spends its time, part by part.

The program of ``wi.calibrate`` (module ``whiskerid.fit._linear._program``: start search, solver,
covariance and outputs) on the plucks of ``benchmarks/calibrate_many.py`` (coil whiskers,
10 s at 200 Hz read by the ADS1115, record 30 % off in f_1), and its parts compiled apart:
the start search alone (16 profiles of the model), the solver from that start, and the
solver from the optimum (its first pass and one step, what a solve costs at least). Each
figure is the median over ``--repeats`` calls of every whisker, with BLAS on one thread as
in a calibration; the solver's steps from the start are reported with them. The peer is
the program itself: the parts say which of its pieces a change moved.

Run: ``python benchmarks/calibrate_program_parts.py [--whiskers N] [--repeats R]`` (prints
JSON).
"""

import argparse
import functools
import json
import os
import statistics
import sys
import time
from pathlib import Path

import jax

import whiskerid as wi
from whiskerid.fit import FitProblem
from whiskerid.fit._linear._host_whisker import nominal_whisker
from whiskerid.fit._linear._program import fit_core, padded_problem, solve_masked
from whiskerid.fit._linear._start import start_from_grid, start_grid
from whiskerid.fit._numerics._threads import one_blas_thread

sys.path.insert(0, str(Path(__file__).parent))
from calibrate_many import _nominal, _whiskers


def _inputs(n: int):
    """``(padded problem, masks, start grid)`` of ``n`` whiskers' plucks, as calibrate
    builds them."""
    out = []
    for k, rec in enumerate(_whiskers(n, 0)):
        sim = wi.simulate(rec, excitation="decay", observable="adc", rate_hz=200,
                          duration_s=10.0, noise_db=30, seed=k, tip_deflection_m=2e-3)  # fmt: skip
        obs = wi.Observation(sim.t, sim.signal(), excitation="decay", observable="adc", gain=None)
        record = _nominal(rec)
        nominal = nominal_whisker(record, 2)
        problem = FitProblem.from_observations(record, [obs], n_modes=2, pin="geometry",
                                               nominal=nominal)  # fmt: skip
        padded, masks = padded_problem(problem)
        out.append((padded, masks, start_grid(problem, [obs], nominal)))
    return out


def _median_ms(fn, args, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        for a in args:
            t0 = time.perf_counter()
            jax.block_until_ready(fn(*a))
            times.append(time.perf_counter() - t0)
    return round(1e3 * statistics.median(times), 3)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--whiskers", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args()
    cases = _inputs(args.whiskers)
    lm = {"solver": "levenberg-marquardt", "max_steps": 400}
    program = jax.jit(functools.partial(fit_core, **lm))
    search = jax.jit(lambda p, m, g: p.flatten(start_from_grid(p, g, m, coefficients=False)))
    solver = jax.jit(lambda p, m, flat0: solve_masked(p, m, flat0, **lm))
    with one_blas_thread(jax_lapack=True):
        starts = [(p, m, search(p, m, g)) for p, m, g in cases]
        solved = [solver(*a) for a in starts]
        optima = [(p, m, s[0]) for (p, m, _), s in zip(starts, solved, strict=True)]
        for fn, a in ((program, cases), (search, cases), (solver, starts)):
            _median_ms(fn, a, 1)  # compiled and warm
        out = {
            "whiskers": args.whiskers,
            "program_ms": _median_ms(program, cases, args.repeats),
            "start_search_ms": _median_ms(search, cases, args.repeats),
            "solver_from_start_ms": _median_ms(solver, starts, args.repeats),
            "solver_from_optimum_ms": _median_ms(solver, optima, args.repeats),
            "solver_steps_from_start": [int(s[2]) for s in solved],
        }
    out["load_average_1min"] = round(os.getloadavg()[0], 2)
    out["jax"] = jax.__version__
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
