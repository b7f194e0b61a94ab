"""New numbers never recompile: whisker, sensor and excitation numbers are traced leaves of
the fit problem, so calibrating (and sampling) other whiskers of the same structure and
shapes reuses the compiled functions."""

import jax
import numpy as np
import pytest

import whiskerid as wi
from whiskerid.model import CoilSpring

_COMPILES: list[str] = []


def _listen(event, duration, **kwargs):
    if event == "/jax/core/compile/backend_compile_duration":
        _COMPILES.append(event)


jax.monitoring.register_event_duration_secs_listener(_listen)


def _compiles(fn):
    """Run ``fn`` and return how many XLA compilations it caused."""
    before = len(_COMPILES)
    fn()
    return len(_COMPILES) - before


#: (length, wire radius, coil radius, coils, sensor x, sine f_b, tip mass): other whiskers
WHISKERS = [
    (0.060, 0.50e-3, 4.5e-3, 13, 0.005, 30.0, 0.0),
    (0.075, 0.45e-3, 4.0e-3, 15, 0.008, 22.0, 2e-4),
]


def _record(length, r_w, r_c, n, x_s, tip):
    coil = CoilSpring(length, r_w, r_c, n, 8050.0, 70e9)
    base = wi.paper_record()
    return base.replace(structure=coil, sensor_position_m=x_s, tip_mass_kg=tip)


def _recordings(record, fb):
    """A pluck read by the ADS1115 and a sine read as deflection: same shapes per whisker."""
    decay = wi.simulate(record, excitation="decay", observable="adc", rate_hz=200,
                        duration_s=2, noise_db=35, seed=1, tip_deflection_m=2e-3)  # fmt: skip
    sine = wi.simulate(record, excitation="sine", fb_hz=fb, hb_m=2e-4, observable="deflection",
                       rate_hz=1000, duration_s=0.5, noise_db=40, seed=2)  # fmt: skip
    return [
        wi.Observation(decay.t, decay.signal(), excitation="decay", observable="adc", gain=None),
        wi.Observation(
            sine.t, sine.signal(), excitation="sine", observable="deflection", fb_hz=fb, hb_m=2e-4
        ),
    ]


@pytest.mark.slow
def test_calibrating_other_whiskers_compiles_nothing_new():
    cals, counts = [], []
    for length, r_w, r_c, n, x_s, fb, tip in WHISKERS:
        record = _record(length, r_w, r_c, n, x_s, tip)
        obs = _recordings(record, fb)
        fit = lambda r=record, o=obs: cals.append(wi.calibrate(r, o, n_modes=1))
        counts.append(_compiles(fit))
    assert counts[0] > 0 and counts[1:] == [0] * (len(WHISKERS) - 1), counts
    for cal, (length, r_w, r_c, n, x_s, _, tip) in zip(cals, WHISKERS, strict=True):
        truth = float(_record(length, r_w, r_c, n, x_s, tip).whisker().natural_frequencies_hz[0])
        assert cal.ok and cal.params["f1_hz"]["value"] == pytest.approx(truth, rel=2e-3)


@pytest.mark.slow
def test_posterior_log_density_of_other_whiskers_compiles_nothing_new():
    counts = []
    for length, r_w, r_c, n, x_s, _, tip in WHISKERS[:2]:
        record = _record(length, r_w, r_c, n, x_s, tip)
        sim = wi.simulate(record, excitation="decay", observable="deflection", rate_hz=1000,
                          duration_s=0.3, noise_db=30, seed=0)  # fmt: skip
        obs = wi.Observation(sim.t, sim.signal(), excitation="decay", observable="deflection")
        prob = wi.setup_posterior(record, obs, n_modes=1)
        z = prob.z0 + 1e-6 * np.arange(prob.z0.size)
        counts.append(_compiles(lambda p=prob, z=z: p.log_prob(np.stack([p.z0, z]))))
        assert np.all(np.isfinite(prob.log_prob(prob.z0)))
    assert counts[1] == 0, counts


def test_window_fits_at_other_rates_compile_nothing_new():
    rng = np.random.default_rng(0)

    def fit(rate):
        t = np.arange(100) / rate
        y = np.exp(-0.3 * t) * np.cos(2 * np.pi * 0.21 * rate * t) + 0.01 * rng.standard_normal(
            (8, 100)
        )
        return wi.fit_windows(y, rate_hz=rate)

    fit(200.0)
    assert _compiles(lambda: fit(333.0)) == 0


# ------------------------------------------------------------------ shape buckets, the cache
def test_shape_buckets_are_at_most_a_quarter_longer_and_never_shorter():
    from whiskerid.fit._linear._program import bucket

    sizes = [bucket(n) for n in range(1, 20_000)]
    assert all(b >= n for n, b in enumerate(sizes, start=1))
    assert all(b <= max(64, 1.25 * n) for n, b in enumerate(sizes, start=1))
    assert sizes == sorted(sizes) and len(set(sizes)) < 40  # few programs for every length
    assert bucket(980) == bucket(1000) == 1024 and bucket(1200) == 1280


def _pluck(duration_s, seed=1):
    sim = wi.simulate(wi.paper_record(), excitation="decay", observable="adc", rate_hz=200,
                      duration_s=duration_s, noise_db=30, seed=seed,
                      tip_deflection_m=2e-3)  # fmt: skip
    return wi.Observation(sim.t, sim.signal(), excitation="decay", observable="adc", gain=None)


@pytest.mark.slow
def test_recordings_in_one_bucket_share_a_program_and_the_padding_counts_for_nothing():
    record = wi.paper_record()
    cals, counts = [], []
    for duration in (5.0, 4.9):  # 1000 and 980 samples: both padded to 1024
        obs = _pluck(duration)
        counts.append(_compiles(lambda o=obs: cals.append(wi.calibrate(record, o))))
    assert counts[1] == 0, counts
    for cal in cals:
        flat = cal.problem.flatten(cal.optimum)
        resid = np.asarray(cal.problem.residuals(cal.problem.unflatten(flat)))
        n = cal.diagnostics["n_samples"]
        assert resid.size == n  # the problem kept is the recording's own, unpadded
        s2 = np.sum(resid**2) / (n - flat.size)
        assert cal.diagnostics["reduced_chi2"] == pytest.approx(s2, rel=1e-6)
        assert cal.ok and cal.params["f1_hz"]["value"] == pytest.approx(46.0, rel=1e-3)


_FRESH = """
import importlib, pkgutil, sys
import jax.export
import whiskerid as wi
import whiskerid.fit

def refuse(*args, **kwargs):
    raise AssertionError("traced and lowered again")

traced = set()
def on_duration(event, duration, fun_name=None, **kwargs):
    if event == "/jax/core/compile/jaxpr_trace_duration":
        traced.add(fun_name)

if sys.argv[1] == "second":
    jax.export.export = refuse
    jax.monitoring.register_event_duration_secs_listener(on_duration)
sim = wi.simulate(wi.paper_record(), excitation="decay", observable="adc", rate_hz=200,
                  duration_s=3, noise_db=30, seed=1, tip_deflection_m=2e-3)
obs = wi.Observation(sim.t, sim.signal(), excitation="decay", observable="adc", gain=None)
cal = wi.calibrate(wi.paper_record(), obs, model="nonlinear")
print(cal.linear.params["f1_hz"]["value"], cal.params["f1_hz"]["value"])
# the fit package's jitted functions (jax.jit or equinox.filter_jit), by name
jitted = set()
for info in pkgutil.walk_packages(whiskerid.fit.__path__, "whiskerid.fit."):
    for name, obj in vars(importlib.import_module(info.name)).items():
        mine = str(getattr(obj, "__module__", "")).startswith("whiskerid.fit")
        if mine and (hasattr(obj, "lower") or type(obj).__name__ == "_JitWrapper"):
            jitted.add(name)
print("traced again:", sorted(traced & jitted), file=sys.stderr)
sys.exit(3 if traced & jitted else 0)
"""


@pytest.mark.slow
def test_a_fresh_interpreter_loads_the_calibration_without_tracing_it(tmp_path):
    """A second interpreter takes every program of a nonlinear calibration from the disk:
    the linear fit it starts from, the nonlinear solves, the reported values and the window
    fits. Nothing is exported again, none of the fit package's jitted functions is traced
    again (before, the nonlinear fit traced five of them, 5 s of every run), and the fit is
    the same."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "WHISKERID_COMPILE_CACHE": str(tmp_path)}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    argv = [[sys.executable, "-c", _FRESH, which] for which in ("first", "second")]
    out = [subprocess.run(a, env=env, capture_output=True, text=True, timeout=600) for a in argv]
    assert [o.returncode for o in out] == [0, 0], out[1].stderr[-2000:]
    assert out[0].stdout == out[1].stdout  # the same fits, from the programs on disk
    assert len(out[1].stdout.split()) == 2
    assert list((tmp_path / "programs").glob("*.jaxexport"))


_LIBRARY = r"""
import sys
import jax
import whiskerid as wi
from whiskerid.fit import observations_from_file
record = wi.load_record(sys.argv[2])
n = {"compiles": 0, "hits": 0}
def on_duration(event, duration, **kwargs):
    n["compiles"] += event == "/jax/core/compile/backend_compile_duration"
def on_event(event, **kwargs):
    n["hits"] += event == "/jax/compilation_cache/cache_hits"
jax.monitoring.register_event_duration_secs_listener(on_duration)
jax.monitoring.register_event_listener(on_event)
cal = wi.calibrate(record, observations_from_file(sys.argv[1], record))
print(cal.params["f1_hz"]["value"], n["compiles"] - n["hits"], n["hits"])
"""


@pytest.mark.slow
def test_the_library_in_a_fresh_interpreter_compiles_nothing_the_cache_holds(tmp_path):
    """``wi.calibrate`` and ``observations_from_file`` from a user's script: the second fresh
    interpreter takes every program, the small eager ones included, from whiskerid's cache
    (before, 26 of them were compiled afresh in every process)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    import whiskerid as wi

    sim = wi.simulate(wi.paper_record(), excitation="decay", observable="adc", rate_hz=200.0,
                      duration_s=3.0, noise_db=30.0, seed=1, tip_deflection_m=2e-3)  # fmt: skip
    wi.write_csv(tmp_path / "pluck.csv", sim)
    record = Path(__file__).resolve().parents[2] / "fits" / "paper-whisker.toml"
    env = {**os.environ, "WHISKERID_COMPILE_CACHE": str(tmp_path / "cache")}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    argv = [sys.executable, "-c", _LIBRARY, str(tmp_path / "pluck.csv"), str(record)]
    out = [subprocess.run(argv, env=env, capture_output=True, text=True, timeout=600)
           for _ in range(2)]  # fmt: skip
    assert [o.returncode for o in out] == [0, 0], out[-1].stderr[-2000:]
    first, second = (o.stdout.split() for o in out)
    assert first[0] == second[0]  # the same fit
    assert int(second[1]) == 0 and int(second[2]) > 10, second  # all from the cache
