"""The command line's calibration of a pluck, timed: cold and warm, against a SciPy script.

Used by ``benchmarks/calibrate.py --cli`` (see there). Every run is a fresh process, as a user
runs it: ``whiskerid calibrate`` with an empty compile cache (cold), then again (warm), then on
a recording of another length in the same shape bucket and in the next one; ``--model
nonlinear`` on the same file, cold and warm, next to the linear fit, and on the recording of
another length in the same bucket; the library from
a fresh interpreter (``wi.calibrate`` on the same file, the same cache); and the peer,
``benchmarks/scipy_pluck.py`` (NumPy and SciPy only, the same model and data), with the
fitted f_1, ζ and 1σ of each. One instrumented run (:data:`SPLIT`) says where a warm run's
time goes: interpreter start, imports, reading (release search included), loading the
compiled program (or tracing, lowering and compiling it), solving and checking, writing,
and the interpreter's exit.
"""

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
PAPER = HERE.parent / "fits" / "paper-whisker.toml"

#: A warm run taken apart (run in a child process; prints one JSON line on stderr).
SPLIT = r"""
import time, json, sys
T0 = time.perf_counter(); W0 = time.time(); C = {"start": time.process_time()}
from whiskerid.cli._cache import enable_compile_cache
enable_compile_cache()
import jax
ev = {}
def listen(event, d, **k):
    ev[event] = ev.get(event, 0.0) + d
jax.monitoring.register_event_duration_secs_listener(listen)
t = {"start": T0}
import whiskerid.fit, whiskerid.model
from whiskerid.fit._numerics import _aot as _aot
t["imports"] = time.perf_counter(); C["imports"] = time.process_time()
record = whiskerid.model.load_record(sys.argv[2])
obs = whiskerid.fit.observations_from_file(sys.argv[1], record)
t["read"] = time.perf_counter(); C["read"] = time.process_time()
load = [0.0]
inner = _aot._load_or_build
def timed(*a, **k):
    s = time.perf_counter(); out = inner(*a, **k); load[0] += time.perf_counter() - s
    return out
_aot._load_or_build = timed
cal = whiskerid.fit.calibrate(record, obs)
t["calibrate"] = time.perf_counter(); C["calibrate"] = time.process_time()
cal.record.save(sys.argv[3])
print(cal.report(), file=open("/dev/null", "w"))
t["write"] = time.perf_counter(); C["write"] = time.process_time()
out = {
    "imports_s": t["imports"] - T0,
    "read_s": t["read"] - t["imports"],
    "program_load_s": load[0],
    "fit_and_checks_s": t["calibrate"] - t["read"] - load[0],
    "write_s": t["write"] - t["calibrate"],
    "inside_s": t["write"] - T0,
    "end_wall": time.time(),
    "start_wall": W0,
    "jax_events_s": {k.rsplit("/", 1)[-1]: round(v, 4) for k, v in ev.items()},
    "cpu_s": {
        "to_imports_done": C["imports"],
        "read": C["read"] - C["imports"],
        "calibrate": C["calibrate"] - C["read"],
        "write": C["write"] - C["calibrate"],
    },
}
print("SPLIT " + json.dumps(out), file=sys.stderr)
"""

LIBRARY = r"""
import sys, time
t0 = time.perf_counter()
import whiskerid as wi
from whiskerid.fit import observations_from_file
record = wi.load_record(sys.argv[2])
cal = wi.calibrate(record, observations_from_file(sys.argv[1], record))
print(cal.params["f1_hz"]["value"], time.perf_counter() - t0)
"""


def _run(argv, env, repeats=1):
    """Median wall and CPU seconds of ``argv`` run ``repeats`` times, and the last output."""
    walls, cpus, out = [], [], None
    for _ in range(repeats):
        before = os.times()
        t0 = time.perf_counter()
        out = subprocess.run(argv, env=env, capture_output=True, text=True, check=True)
        walls.append(time.perf_counter() - t0)
        after = os.times()
        cpus.append(
            (after.children_user - before.children_user)
            + (after.children_system - before.children_system)
        )
    return statistics.median(walls), statistics.median(cpus), out


def _pluck(path: Path, duration_s: float) -> None:
    import whiskerid as wi

    sim = wi.simulate(wi.paper_record(), model="exact", excitation="decay", observable="adc",
                      rate_hz=200.0, duration_s=duration_s, noise_db=30.0, seed=1,
                      tip_deflection_m=2e-3)  # fmt: skip
    wi.write_csv(path, sim)


def _fitted(toml: Path) -> dict:
    import tomllib

    p = tomllib.loads(toml.read_text())["fit"]["params"]
    return {"f1_hz": p["f1_hz"]["value"], "f1_std": p["f1_hz"]["std"],
            "zeta": p["zeta"]["value"], "zeta_std": p["zeta"]["std"]}  # fmt: skip


def cli(repeats: int = 3) -> dict:
    """Cold and warm CLI calibration of a 1000-sample pluck, side by side with SciPy."""
    import whiskerid as wi

    exe = str(Path(sys.executable).with_name("whiskerid"))
    tmp = Path(tempfile.mkdtemp(prefix="whiskerid-bench-cli-"))
    env = {**os.environ, "WHISKERID_COMPILE_CACHE": str(tmp / "cache")}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    files = {d: tmp / f"pluck_{d:g}s.csv" for d in (5.0, 4.9, 6.0)}
    for d, path in files.items():
        _pluck(path, d)
    out = tmp / "fit.toml"

    def calibrate(path):
        return [exe, "calibrate", str(path), "--whisker", str(PAPER), "--out", str(out),
                "--force", "--quiet"]  # fmt: skip

    res = {"samples": 1000}
    res["cli_cold_s"], res["cli_cold_cpu_s"], _ = _run(calibrate(files[5.0]), env)
    res["cli_warm_s"], res["cli_warm_cpu_s"], _ = _run(calibrate(files[5.0]), env, repeats)
    res["cli"] = _fitted(out)
    # the nonlinear model on the same file, next to the linear fit (its programs are kept on
    # disk too, one per shape bucket), and on a recording of another length in its bucket
    nonlinear = [*calibrate(files[5.0]), "--model", "nonlinear"]
    res["cli_nonlinear_cold_s"] = _run(nonlinear, env)[0]
    res["cli_nonlinear_warm_s"], res["cli_nonlinear_warm_cpu_s"], _ = _run(nonlinear, env, repeats)
    res["cli_nonlinear_other_length_same_bucket_s"], res["cli_nonlinear_other_length_cpu_s"], _ = (
        _run([*calibrate(files[4.9]), "--model", "nonlinear"], env)
    )
    res["cli_other_length_same_bucket_s"] = _run(calibrate(files[4.9]), env)[0]
    res["cli_next_bucket_first_s"] = _run(calibrate(files[6.0]), env)[0]
    res["cli_next_bucket_warm_s"] = _run(calibrate(files[6.0]), env)[0]
    lib = [sys.executable, "-c", LIBRARY, str(files[5.0]), str(PAPER)]
    res["library_fresh_interpreter_s"], res["library_fresh_interpreter_cpu_s"], _ = _run(
        lib, env, repeats
    )
    # the library as fast as the command line (the same cache, the same work)
    res["library_over_cli_warm"] = res["library_fresh_interpreter_s"] / res["cli_warm_s"]
    res["library_over_cli_warm_cpu"] = (
        res["library_fresh_interpreter_cpu_s"] / res["cli_warm_cpu_s"]
    )
    w = wi.paper_record().whisker()
    f = np.asarray(w.natural_frequencies_hz)
    scipy = [sys.executable, str(HERE / "scipy_pluck.py"), str(files[5.0]),
             "--ratio", repr(float(f[1] / f[0])),
             "--conversion-s", repr(wi.paper_record().adc.conversion_time_s)]  # fmt: skip
    res["scipy_script_s"], res["scipy_script_cpu_s"], sp = _run(scipy, env, repeats)
    res["scipy"] = json.loads(sp.stdout)
    res["warm_over_scipy"] = res["cli_warm_s"] / res["scipy_script_s"]
    res["cold_over_scipy"] = res["cli_cold_s"] / res["scipy_script_s"]
    # Where a warm run's time goes (one instrumented run, and a bare interpreter's start).
    res["python_start_s"] = _run([sys.executable, "-c", "pass"], env, repeats)[0]
    wall, cpu, split = _run([sys.executable, "-c", SPLIT, str(files[5.0]), str(PAPER), str(out)],
                            env)  # fmt: skip
    line = next(x for x in split.stderr.splitlines() if x.startswith("SPLIT "))
    parts = json.loads(line[6:])
    parts["start_and_exit_s"] = wall - parts.pop("inside_s")
    parts.pop("end_wall"), parts.pop("start_wall")
    parts["cpu_s"] = {k: round(v, 3) for k, v in parts["cpu_s"].items()}
    res["warm_split"] = {k: (round(v, 3) if isinstance(v, float) else v)
                         for k, v in parts.items()}  # fmt: skip
    res["warm_split_wall_s"] = round(wall, 3)
    res["warm_split_cpu_s"] = round(cpu, 3)
    res["load_average_1min"] = round(os.getloadavg()[0], 2)
    return res
