"""Window health: clean windows wrongly refused a terrain, and dead inputs caught.

Trains two classifiers on the simulated set (``dataset synth``: 7 terrains at 0.1, 0.2 and
0.3 m/s, ``--runs`` runs of 15 s, seed 0): one on the raw signal, one whisker-aware
(``train --whisker``, the paper whisker). Then counts, per window,

* the **false-rejection rate** (a ``sensor-fault`` or ``unknown`` label) on clean held-out
  windows: recordings of another dataset seed (7), the same terrains read through the
  emulated ADS1115 (register level, 0.1 mV of input noise), and, for the whisker-aware
  model, recordings of two other whiskers (f1 x0.7 and x1.3) read with their records
  (there the mode check is off; ``below_mode_floor`` says what it would refuse at that
  whisker's mode);
* the **detection rate** on dead inputs through the emulated chip: a flat 1.65 V plus 1, 2
  or 3 mV of noise, white noise alone, a chip toggling between two codes, a chip stuck at
  one code, an input pinned at full scale, and electrical noise coloured by a filter (moving
  averages of 3 to 40 samples, AR(1) and 1/f noise, 50 Hz hum plus noise; 10 codes RMS);

with the mode check alone (one window, and over three windows together, in time order per
recording as ``classify`` runs it) as well as with every check. Prints one JSON object.

    .venv/bin/python benchmarks/window_health.py [--runs 3]
"""

import argparse
import dataclasses
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from whiskerid.hw import terrain_source

from whiskerid import hw
from whiskerid.classify import WhiskerResponse, load_dataset, train_classifier
from whiskerid.io._health_context import ModeContext
from whiskerid.io._health_modes import mode_prominence, whisker_mode, white_prominence
from whiskerid.model import paper_record
from whiskerid.terrain import AMPLIFIER, TERRAINS, synthesize_dataset

RATE, LEVEL_V = 200.0, 1.65


def chip_windows(source, seconds: float = 10.0, *, noise_v=1e-4, stuck=None) -> np.ndarray:
    """1 s windows of what the emulated ADS1115 reads from ``source`` at 200 Hz."""
    clock = hw.FakeClock()
    timing = {"clock": clock.now_ns, "sleep": clock.sleep}
    chip = hw.EmulatedADS1115(source, seed=3, noise_v=noise_v, **timing)
    chip.stuck_code = stuck
    sampler = hw.Sampler(hw.ADS1115(chip, **timing), RATE, **timing)
    codes = np.array([s[1] for s in sampler.samples(duration_s=seconds)], float)
    return codes[: len(codes) // 200 * 200].reshape(-1, 200)


def coloured(x: np.ndarray, codes: float = 10.0):
    """A source reading noise ``x`` (one value per sample at 200 Hz) scaled to ``codes``
    RMS (1 code = 125 µV) around 1.65 V: electrical noise coloured by some filter."""
    x = codes * 125e-6 * (x - x.mean()) / x.std()
    return lambda t: LEVEL_V + x[np.round(np.asarray(t) * RATE).astype(int) % x.size]


def ar1(rng, a: float, n: int) -> np.ndarray:
    e, x = rng.standard_normal(n), np.zeros(n)
    for i in range(1, n):
        x[i] = a * x[i - 1] + e[i]
    return x


def dead_inputs(rng) -> dict[str, np.ndarray]:
    flat = lambda t: np.full(np.shape(t), LEVEL_V)
    n = 7000
    ma = lambda k: np.convolve(rng.standard_normal(n + k), np.ones(k) / k, "same")[:n]
    f = np.fft.rfftfreq(n)
    pink = np.fft.rfft(rng.standard_normal(n)) / np.sqrt(np.maximum(f, f[1]))
    hum = np.sin(2 * np.pi * 50 * np.arange(n) / RATE) + 0.3 * rng.standard_normal(n)
    colour = {f"moving average {k} (10 codes)": ma(k) for k in (3, 5, 10, 20, 30, 40)}
    colour |= {f"AR(1) {a} (10 codes)": ar1(rng, a, n) for a in (0.5, 0.9, 0.99)}
    colour |= {"1/f (10 codes)": np.fft.irfft(pink, n), "50 Hz hum + noise (10 codes)": hum}
    white = lambda t: LEVEL_V + 0.05 * rng.standard_normal(np.shape(t))
    toggle = lambda t: LEVEL_V + 1.25e-4 * (np.floor(np.asarray(t) * RATE + 0.5) % 2)
    return {
        "flat + 1 mV": chip_windows(flat, 30, noise_v=1e-3),
        "flat + 2 mV": chip_windows(flat, 30, noise_v=2e-3),
        "flat + 3 mV": chip_windows(flat, 30, noise_v=3e-3),
        "white noise": chip_windows(white, 30, noise_v=0.0),
        "two codes": chip_windows(toggle, 30, noise_v=0.0),
        "stuck": chip_windows(flat, 30, stuck=13_000),
        "pinned": chip_windows(lambda t: np.full(np.shape(t), 5.0), 30),
    } | {k: chip_windows(coloured(x), 30, noise_v=0.0) for k, x in colour.items()}


def in_order(model, windows: np.ndarray, groups) -> list:
    """Each window's ``(label, reason)`` or None, in time order within each group (a
    recording), the check over several windows included (as ``classify`` runs it)."""
    out, ctx, last = [], ModeContext(), None
    for i, w in enumerate(windows):
        if groups[i] != last:
            ctx.reset()
        last, fault = groups[i], model.window_health(w)
        if fault is not None and fault[0] != "unknown":
            ctx.reset()
        else:
            why = ctx.check(w, float(i + 1), 1.0, model.health_in_use)
            fault = fault or (None if why is None else ("unknown", why))
        out.append(fault)
    return out


def rates(model, windows: np.ndarray, modes=None, groups=None) -> dict:
    """Share of windows refused a terrain, by any check and by the mode check alone (one
    window, and over several), and below the mode threshold at ``modes`` (the model's by
    default); ``groups``: the recording of each window (None: one recording)."""
    groups = np.zeros(len(windows), int) if groups is None else np.asarray(groups)
    h = in_order(model, windows, groups)
    over = sum(f is not None and "over the last" in f[1] for f in h)
    mode = sum(f is not None and f[1].startswith("no whisker response") for f in h)
    modes = model.health.modes_hz if modes is None else modes
    prom = mode_prominence(windows, RATE, modes).max(axis=1)
    floor = white_prominence(windows.shape[-1], RATE, tuple(modes))
    return {"windows": len(windows), "refused": round(sum(f is not None for f in h) / len(h), 5),
            "refused_by_mode_check": round((mode - over) / len(h), 5),
            "refused_over_several_windows": round(over / len(h), 5),
            "below_mode_floor": round(float(np.mean(prom < floor)), 5),
            "min_prominence": round(float(prom.min()), 3)}  # fmt: skip


def variant(ratio: float):
    base = paper_record()
    s = dataclasses.replace(base.structure, shear_modulus_pa=base.structure.shear_modulus_pa
                            * ratio**2)  # fmt: skip
    return base.replace(name=f"whisker-f1x{ratio}", structure=s)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=3, help="training runs per terrain and speed")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    out: dict = {"machine_note": "timings on a shared, loaded machine"}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        synthesize_dataset(tmp / "train", runs=args.runs, duration_s=15.0, seed=0)
        synthesize_dataset(tmp / "test", runs=2, duration_s=15.0, seed=7)
        ws, test = load_dataset(tmp / "train"), load_dataset(tmp / "test")
        whisker = WhiskerResponse(paper_record(), AMPLIFIER)
        models = {"raw": train_classifier(ws), "whisker": train_classifier(ws, whisker=whisker)}
        emu = np.concatenate([chip_windows(terrain_source(paper_record(), t, v, 12, seed=11))
                              for t in TERRAINS for v in (0.1, 0.2, 0.3)])  # fmt: skip
        dead = dead_inputs(np.random.default_rng(5))
        for name, m in models.items():
            h = m.health
            res = {"modes_hz": h.modes_hz, "mode_floor": h.mode_floor,
                   "mode_noise_caught": h.mode_noise_caught,
                   "train_rejection": h.train_rejection,
                   "context_floor": h.context_floor,
                   "held_out_seed_7": rates(m, test.windows, groups=test.recording),
                   "emulated_chip": rates(m, emu, groups=np.arange(len(emu)) // 12),
                   "dead": {k: rates(m, w) for k, w in dead.items()}}  # fmt: skip
            out[name] = res
        m = models["whisker"]
        for ratio in (0.7, 1.3):
            rec = variant(ratio)
            synthesize_dataset(tmp / f"v{ratio}", record=rec, runs=1, duration_s=15.0, seed=9)
            other = WhiskerResponse(rec, AMPLIFIER)
            m.use_whisker(other)
            modes = (whisker_mode(other, RATE, m.window),)  # where the mode check would look
            res = {"mode_hz": modes,
                   "held_out": rates(m, load_dataset(tmp / f"v{ratio}").windows, modes),
                   "dead": {k: rates(m, w, modes) for k, w in dead.items()},
                   "gain_ratio": m._other_health.rms_gain}  # fmt: skip
            held = load_dataset(tmp / f"v{ratio}").windows
            absurd = (held - np.median(held)) * 1e3 + np.median(held)
            res["x1000 amplitude"] = rates(m, absurd, modes)
            out[f"whisker on f1 x{ratio}"] = res
    out["elapsed_s"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
