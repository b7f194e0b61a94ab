"""The stages of ``whiskerid demo``, which runs the main job end to end on embedded defaults.

The demo orchestrates every layer of the library, so its stages live with the command line:

1. the paper's whisker: equivalent-beam values and natural frequencies;
2. the paper's modal analysis (Eq. 1 and the exact modal model) at h_b = 0.1/0.3 mm and
   f_b = 100/300 Hz, 1 s at 20 kHz, with dominant spectral peaks;
3. what the Pi records (Hall sensor + ADS1115 at 200 Hz) for a 30 Hz sine and a pluck;
4. calibration of a simulated pluck from a record 30 % off;
5. the posterior of ζ (and f_1) of that pluck with emcee: median, 68 % interval, τ,
   convergence, corner and trace plots;
6. terrain classification: a small simulated dataset, trained and tested by recording;
7. the Pi's online loop on an emulated ADS1115: sample, classify every 0.5 s, record.
"""

import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ..fit import dominant_peaks
from ..io import write_csv
from ..model import harmonic_steady_state, observe, paper_eq1, paper_record, simulate
from ._common import interrupts
from ._common import progress_step as _progress_step

#: Seconds each stage took in the last run (its name → s), for the summary.
_STAGES: dict[str, float] = {}
_CLOCK: list = []


def progress_step(name: str) -> None:
    """Start the stage ``name``: on the status line, and timed for the summary."""
    now = time.perf_counter()
    if _CLOCK:
        _STAGES[_CLOCK[0][0]] = round(now - _CLOCK[0][1], 2)
        _CLOCK.clear()
    _CLOCK.append((name, now))
    _progress_step(name)


MODAL_CASES = [(hb, fb) for fb in (100.0, 300.0) for hb in (1e-4, 3e-4)]


def run_demo(out: Path, *, plots: bool = True, say=print) -> dict:
    """Run every stage, writing CSVs and PNGs under ``out``; returns a JSON-able summary."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    _STAGES.clear(), _CLOCK.clear()
    record = paper_record()
    whisker = record.whisker()
    coil = record.structure
    f_n = [float(f) for f in whisker.natural_frequencies_hz]
    progress_step("[1] the paper's whisker")
    say(
        f"[1] {record.name}: EI = {coil.EI:.4g} N m^2, C = {coil.coil_factor:.4g}, "
        f"rho*a = {coil.rho_a:.4g} kg/m"
    )
    say("      natural frequencies (Hz): " + ", ".join(f"{f:.1f}" for f in f_n))

    progress_step("[2] modal analysis")
    say("[2] modal analysis, 1 s at 20 kHz, sensor at x_s = 5 mm (peaks in Hz)")
    t = np.arange(20_000) / 20_000.0
    modal = []
    cases = {"paper": [], "exact": []}
    for hb, fb in MODAL_CASES:
        y_paper = np.asarray(paper_eq1(whisker, jnp.asarray(t), fb_hz=fb, hb_m=hb))
        state = harmonic_steady_state(whisker, jnp.asarray(t), fb_hz=fb, hb_m=hb)
        y_exact = np.asarray(observe(whisker, state))
        row = {"hb_m": hb, "fb_hz": fb}
        for name, y in (("paper", y_paper), ("exact", y_exact)):
            peaks = [round(p.frequency_hz, 2) for p in dominant_peaks(t, y, n=3)]
            row[name] = {"peaks_hz": peaks, "max_abs_m": float(np.abs(y).max())}
            cases[name].append({"t": t, "y": y, "hb_m": hb, "fb_hz": fb, "model": name})
        modal.append(row)
        say(
            f"      h_b = {hb * 1e3:.1f} mm, f_b = {fb:.0f} Hz: "
            f"paper Eq. 1 {row['paper']['peaks_hz']}, exact steady state {row['exact']['peaks_hz']}"
        )

    progress_step("[3] what the Pi records")
    say("[3] what the Pi records: Hall sensor + ADS1115 (475 SPS) polled at 200 Hz, 5 s")
    recordings = {}
    for label, kwargs in (
        ("sine30hz", {"excitation": "sine", "fb_hz": 30.0, "hb_m": 2e-4}),
        ("pluck", {"excitation": "decay", "tip_deflection_m": 2e-3}),
    ):
        sim = simulate(
            record, model="exact", observable="adc", rate_hz=200.0, duration_s=5.0, seed=1, **kwargs
        )
        path = write_csv(out / f"{label}_adc.csv", sim)
        # Peaks under 5 % of the largest are window ripple of the short pluck, not modes.
        found = dominant_peaks(sim.t, sim.signal(), n=2, min_separation_hz=10.0, min_relative=0.05)
        peaks = [round(p.frequency_hz, 2) for p in found]
        recordings[label] = {"csv": str(path), "peaks_hz": peaks}
        say(
            f"      {label}: {path} peaks {peaks} Hz (f_1 = {f_n[0]:.1f} Hz; f_2 = {f_n[1]:.1f} "
            f"Hz folds to {abs(f_n[1] - 200 * round(f_n[1] / 200)):.1f} Hz at 200 Hz)"
        )
        if plots:
            from ..plot import plot_signal_and_spectrum

            png = plot_signal_and_spectrum(
                out / f"{label}_adc.png",
                sim.t,
                sim.signal(),
                label="ADS1115 code",
                title=f"{record.name}: {label}",
            )
            recordings[label]["png"] = str(png)

    summary = {
        "whisker": record.name,
        "EI_Nm2": coil.EI,
        "C": coil.coil_factor,
        "rho_a_kg_m": coil.rho_a,
        "natural_frequencies_hz": f_n,
        "modal_analysis": modal,
        "recordings": recordings,
    }
    if plots:
        from ..plot import plot_modal_analysis

        for name, rows in cases.items():
            png = plot_modal_analysis(out / f"modal_analysis_{name}.png", rows)
            summary[f"modal_analysis_{name}_png"] = str(png)
        say(f"      plots: {out}/modal_analysis_paper.png, modal_analysis_exact.png, *_adc.png")
    summary["calibration"], calibrated = _calibration_stage(out, record, plots=plots, say=say)
    summary["posterior"] = _posterior_stage(out, *calibrated, plots=plots, say=say)
    summary["classification"] = _classification_stage(out, plots=plots, say=say)
    summary["stream"] = _stream_stage(out, Path(summary["classification"]["model"]), say=say)
    progress_step("done")
    summary["stage_s"] = dict(_STAGES)
    return summary


def _calibration_stage(out: Path, record, *, plots: bool, say) -> dict:
    """Simulate a pluck as the Pi records it and calibrate the whisker from it (f_1, ζ, EI)."""
    from dataclasses import replace

    from ..fit import Observation, calibrate

    progress_step("[4] calibration")
    say("[4] calibration: a pluck recorded by the ADS1115 at 200 Hz (10 s, SNR 30 dB), fitted")
    say("    from a nominal record 30 % off (start values from the data)")
    sim = simulate(
        record,
        model="exact",
        excitation="decay",
        observable="adc",
        rate_hz=200.0,
        duration_s=10.0,
        noise_db=30.0,
        seed=2,
        tip_deflection_m=2e-3,
    )
    coil = record.structure
    nominal = record.replace(
        structure=replace(coil, shear_modulus_pa=coil.shear_modulus_pa * 1.69), zeta=0.052
    )
    obs = Observation(sim.t, sim.signal(), observable="adc", gain=None, name="pluck")
    cal = calibrate(nominal, obs)
    path = cal.record.save(out / "calibrated-whisker.toml")
    p = cal.params
    truth = record.whisker()
    say(
        f"      {cal.status}: f1 = {p['f1_hz']['value']:.3f} ± {p['f1_hz']['std']:.3f} Hz "
        f"(true {float(truth.natural_frequencies_hz[0]):.3f}), zeta = {p['zeta']['value']:.4f} "
        f"± {p['zeta']['std']:.4f} (true 0.04), EI = {p['EI']['value']:.4g} N m^2 "
        f"(C fixed by the coil geometry); wrote {path}"
    )
    summary = {
        "status": cal.status,
        "record": str(path),
        **{k: {"value": v["value"], "std": v["std"]} for k, v in p.items()},
    }
    if plots:
        from ..plot import plot_calibration

        summary["png"] = str(plot_calibration(out / "calibration.png", cal))
    return summary, (cal.record, obs)


def _posterior_stage(out: Path, record, obs, *, plots: bool, say) -> dict:
    """emcee posterior of the calibrated pluck's ζ and f_1 (a short, converged run)."""
    from ..posterior import sample_posterior

    progress_step("[5] posterior (emcee)")
    say("[5] posterior of zeta with emcee: the calibrated pluck, 32 walkers x 1000 steps")
    # 1000 steps: tau is about 11 steps here with the default (differential-evolution)
    # move, and 50 tau is the convergence criterion.
    # A signal stops the run between two steps (never inside emcee's log-probability).
    with interrupts().deferred() as policy:
        post = sample_posterior(
            record, obs, walkers=32, steps=1000, seed=0, stop=policy.stop_requested
        )
    z, f = post.params["zeta"], post.params["f1_hz"]
    d = post.diagnostics
    say(
        f"      zeta = {z['median']:.4f} (68 %: {z['q16']:.4f} to {z['q84']:.4f}; true 0.04), "
        f"f1 = {f['median']:.3f} Hz (68 %: {f['q16']:.3f} to {f['q84']:.3f}); "
        f"max tau = {d['max_tau']:.1f} steps, acceptance {d['acceptance']:.2f}"
    )
    say(f"      {d['message']}")
    path = post.record.save(out / "posterior-whisker.toml")
    summary = {
        "zeta": {k: z[k] for k in ("median", "q16", "q84", "q2.5", "q97.5", "tau", "ess")},
        "f1_hz": {k: f[k] for k in ("median", "q16", "q84")},
        "max_tau": d["max_tau"],
        "acceptance": d["acceptance"],
        "converged": d["converged"],
        "steps": d["steps"],
        "steps_needed": d["steps_needed"],
        "record": str(path),
    }
    if plots:
        from ..plot import plot_corner, plot_trace

        summary["corner_png"] = str(plot_corner(out / "posterior_corner.png", post))
        summary["trace_png"] = str(plot_trace(out / "posterior_trace.png", post))
        say(f"      wrote {path}, {out}/posterior_corner.png, posterior_trace.png")
    return summary


def _stream_stage(out: Path, model_dir: Path, *, say, terrain: str = "brick") -> dict:
    """10 s of the Pi's loop on an emulated ADS1115 (virtual clock): sample, classify, record."""
    from .. import hw
    from ..classify import ClassifierModel
    from ..hw import OnlineClassifier, open_recorder, run_stream, terrain_source

    progress_step("[7] online stream")
    say(f"[7] online stream: emulated ADS1115 fed by the simulator on {terrain} at 0.2 m/s, 10 s")
    clock = hw.FakeClock()
    timing = {"clock": clock.now_ns, "sleep": clock.sleep}
    source = terrain_source(paper_record(), terrain, 0.2, 12.0, seed=5)
    adc = hw.ADS1115(hw.EmulatedADS1115(source, seed=5, **timing), **timing)
    sampler = hw.Sampler(adc, 200.0, **timing)
    online = OnlineClassifier(ClassifierModel.load(model_dir), hop_s=0.5, speed_mps=0.2)
    online.warm_up()
    path = out / "stream.csv"
    path.unlink(missing_ok=True)
    recorder = open_recorder(path, rate_hz=200.0, meta={"terrain": terrain, "source": "demo"})
    # Virtual clock: nothing waits, so the model runs inline rather than on a worker thread.
    samples = sampler.samples(duration_s=10.0)
    result = run_stream(samples, online, recorder=recorder, background=False)
    summary = result.to_dict(truth=terrain)
    say(f"      {summary['samples']} samples, {summary['windows']} windows: "
        f"{summary['label_counts']}; {summary['fraction_correct']:.0%} labelled {terrain}; "
        f"latency p50 {summary['latency_ms']['p50']:.2f} ms; recorded to {path}")  # fmt: skip
    return summary


def _classification_stage(out: Path, *, plots: bool, say) -> dict:
    """Small synthetic terrain dataset (7 terrains, 0.2 m/s), trained and tested by recording."""
    from ..classify import evaluate_classifier as evaluate
    from ..classify import format_confusion, load_dataset, split_by_recording, train_classifier
    from ..plot import plot_confusion
    from ..terrain import synthesize_dataset

    progress_step("[6] terrain classification")
    say("[6] terrain classification: 7 simulated terrains at 0.2 m/s, 16 runs x 6 s each")
    # Many short runs rather than a few long ones: what the network needs to see is the
    # run-to-run variation of each terrain (6 runs: 0.68 on held-out runs, 16: 0.94).
    # A re-run into the same --out replaces the demo's own recordings (and nothing else).
    synthesize_dataset(
        out / "terrain", speeds=(0.2,), runs=16, duration_s=6.0, seed=0, replace_synthetic=True
    )
    train, test = split_by_recording(load_dataset(out / "terrain"), 0.34, seed=0)
    model = train_classifier(train)
    model.save(out / "terrain-model")
    res = evaluate(model, test)
    say(format_confusion(res["confusion"], res["labels"]))
    say(f"      accuracy on held-out recordings: {res['accuracy']:.3f} ({res['n_windows']} "
        f"windows; labels resting on {model.context_s:g} s; each window on its own "
        f"{res['accuracy_per_window']:.3f}; whole recordings "
        f"{res['accuracy_per_recording']:.3f} of {res['n_recordings']})")  # fmt: skip
    if plots:
        res["png"] = str(
            plot_confusion(out / "terrain_confusion.png", res["confusion"], res["labels"])
        )
    return {
        "accuracy": res["accuracy"],
        "accuracy_per_window": res["accuracy_per_window"],
        "accuracy_per_recording": res["accuracy_per_recording"],
        "context_s": model.context_s,
        "per_class": res["per_class"],
        "model": str(out / "terrain-model"),
    }


def summary_lines(summary: dict, out: Path) -> list[str]:
    """The demo's results in a few lines (printed on stdout at the end)."""
    f = summary["natural_frequencies_hz"]
    cal, post = summary["calibration"], summary["posterior"]
    cls, stream = summary["classification"], summary["stream"]
    z = post["zeta"]
    return [
        f"whiskerid demo: {summary['whisker']}, outputs in {out}/",
        f"  natural frequencies: {', '.join(f'{x:.1f}' for x in f[:3])} Hz",
        f"  calibration ({cal['status']}): f1 = {cal['f1_hz']['value']:.3f} "
        f"± {cal['f1_hz']['std']:.3f} Hz, zeta = {cal['zeta']['value']:.4f} "
        f"± {cal['zeta']['std']:.4f}",
        f"  posterior: zeta = {z['median']:.4f} (68 %: {z['q16']:.4f} to {z['q84']:.4f}), "
        f"{'converged' if post['converged'] else 'not converged'}",
        f"  terrain classifier: accuracy {cls['accuracy']:.3f} on held-out recordings",
        f"  online stream: {stream['fraction_correct']:.0%} of {stream['windows']} windows "
        "labelled right",
    ]
