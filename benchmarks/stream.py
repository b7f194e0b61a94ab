"""Stream benchmark: the Sampler on the emulated ADS1115 with the real clock.

Runs the full Pi-side read path (Sampler -> ADS1115 driver -> smbus2-shaped bus) against
:class:`whiskerid.hw.EmulatedADS1115` fed by a sine, in real time, and prints one JSON object:
achieved rate and drift, inter-sample jitter, gaps, overruns, memory growth and CPU share.

    python benchmarks/stream.py --duration 20
    python benchmarks/stream.py --duration 600 --model MODEL --terrain brick
    python benchmarks/stream.py --duration 60 --inputs A0,A1 --model MODEL

With ``--inputs A0,A1`` the inputs are read round-robin (one single-shot conversion each, the
data rate chosen to fit a slot); jitter and drift are then per slot of ``1 / (inputs rate)``,
and the JSON gains each input's achieved rate and the interleave offset between inputs.

With ``--model`` (a folder from ``whiskerid train``) every sample also goes through the
online classifier (ring buffer, a window every ``--hop`` s, features + MLP) as
``whiskerid stream`` runs it: windows cut in the sampling loop, the model on a worker thread
(``--inline`` runs it in the sampling loop instead, for comparison). The source is then the
terrain simulator on ``--terrain`` instead of a sine, and the JSON gains the window-to-label
latency and the fraction of windows labelled with the true terrain.

The emulated bus answers instantly, so this measures the scheduling and Python overhead on
this machine, not I2C transfer times (about 0.1 ms per transfer at 400 kHz on a Pi).
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import os
import platform
import resource
import sys
import time

import numpy as np
from whiskerid.hw import (
    ADS1115,
    Config,
    EmulatedADS1115,
    InputScan,
    Sampler,
    data_rate_for,
    parse_inputs,
)


def rss_kib() -> float:
    """Current resident set size in KiB (VmRSS), or the peak where /proc is unavailable."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return float(line.split()[1])
    except OSError:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 1024 if sys.platform == "darwin" else float(peak)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=600.0, help="seconds to stream (600)")
    p.add_argument("--rate", type=float, default=200.0, help="sampling rate in Hz (200)")
    p.add_argument("--data-rate", type=int, default=475, help="ADS1115 data rate in SPS (475)")
    p.add_argument("--signal-hz", type=float, default=12.5, help="sine frequency in Hz")
    p.add_argument("--amplitude", type=float, default=1.0, help="sine amplitude in volts")
    p.add_argument("--noise", type=float, default=1e-4, help="input noise in volts RMS")
    p.add_argument("--clock-error", type=float, default=0.03, help="oscillator error fraction")
    p.add_argument("--spin", type=float, default=0.0, help="busy-wait before deadlines (s)")
    p.add_argument("--inputs", default="A0", help="inputs read round-robin (A0 or A0,A1)")
    p.add_argument("--model", help="trained model folder: classify online as well")
    p.add_argument("--terrain", default="brick", help="simulated terrain fed with --model")
    p.add_argument("--speed", type=float, default=0.2, help="robot speed with --model (m/s)")
    p.add_argument("--hop", type=float, default=0.5, help="seconds between windows")
    p.add_argument("--inline", action="store_true", help="run the model in the sampling loop")
    p.add_argument(
        "--extra-model-ms",
        type=float,
        default=0.0,
        help="busy Python work added to every window (ms), as a slower CPU such as a Pi's "
        "would spend on features + MLP",
    )
    args = p.parse_args(argv)

    def sine(t):
        return 1.65 + args.amplitude * np.sin(2 * np.pi * args.signal_hz * np.asarray(t))

    online = worker = None
    if args.model:
        from whiskerid.hw import BackgroundClassifier, OnlineClassifier, terrain_source

        from whiskerid import ClassifierModel, paper_record

        online = OnlineClassifier(ClassifierModel.load(args.model), hop_s=args.hop,
                                  speed_mps=args.speed)  # fmt: skip
        online.warm_up()
        sine = terrain_source(paper_record(), args.terrain, args.speed, args.duration + 2.0)
        terrain_index = list(online.model.labels).index(args.terrain)
        if args.extra_model_ms > 0:
            online.model = _Slower(online.model, args.extra_model_ms * 1e-3)
    # Labels go into preallocated arrays, so that memory growth shows the stream's own.
    max_windows = math.ceil(args.duration / args.hop) + 8
    latency_s = np.zeros(max_windows)
    correct = np.zeros(max_windows, dtype=bool)
    n_labels = 0

    def on_label(w) -> None:
        nonlocal n_labels
        if n_labels < max_windows:
            latency_s[n_labels] = w.latency_s
            correct[n_labels] = w.label == online.model.labels[terrain_index]
            n_labels += 1

    if online is not None and not args.inline:
        worker = BackgroundClassifier(online, on_label).start()

    # A short transfer log: the emulator's log is test equipment, not part of the Pi's path.
    inputs = parse_inputs(args.inputs)
    n_in = len(inputs)
    # Every input gets the same signal, delayed by a quarter period per input.
    sources = [(lambda t, j=j: sine(np.asarray(t) + j / (4 * args.signal_hz))) for j in range(n_in)]
    emu = EmulatedADS1115(
        sources, noise_v=args.noise, clock_error=args.clock_error, seed=0, log_limit=64
    )
    data_rate = args.data_rate if n_in == 1 else data_rate_for(1 / (n_in * args.rate))
    cfg = Config(mux=inputs[0].mux, fsr_v=4.096, data_rate_sps=data_rate)
    if n_in == 1:
        adc = ADS1115(emu, config=cfg)
        driver = adc
    else:
        adc = InputScan(emu, inputs, config=cfg)
        driver = adc.chips[0]
    capacity = math.ceil(args.duration * args.rate * n_in) + 16
    read_ns = np.zeros(capacity, dtype=np.int64)

    class TimedADC:
        """Times each read (the conversion wait plus the driver's overhead)."""

        calls = 0
        n_inputs = n_in

        def read(self) -> int:
            return self.read_input(0)

        def read_input(self, j: int) -> int:
            t0 = time.monotonic_ns()
            try:
                return adc.read_input(j) if n_in > 1 else adc.read()
            finally:
                if self.calls < capacity:
                    read_ns[self.calls] = time.monotonic_ns() - t0
                self.calls += 1

        to_volts = staticmethod(adc.to_volts)

    timed = TimedADC()
    sampler = Sampler(timed, args.rate, spin_s=args.spin)

    # Preallocate and touch every page, so the stream loop itself allocates nothing that
    # lives on: growth then shows leaks in the read path, not the benchmark's bookkeeping.
    t = np.zeros(capacity)
    codes = np.zeros(capacity, dtype=np.int64)
    chan = np.zeros(capacity, dtype=np.int64)
    t.fill(1.0)
    codes.fill(1)
    chan.fill(1)
    n = 0
    warmup = min(capacity, round(args.rate))  # memory baseline after the first second too
    rss_warm = blocks_warm = None
    # RSS every 10 s of samples: growth that stops after the start-up is not a leak; growth
    # over the second half of the run is.
    trace_every = round(10 * args.rate)
    rss_trace = np.zeros(capacity // trace_every + 2)
    n_trace = 0

    gc.collect()
    rss_start, blocks_start = rss_kib(), sys.getallocatedblocks()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for sample in sampler.samples(duration_s=args.duration):
        if n < capacity:
            t[n], codes[n], chan[n] = sample.t_s, sample.code, sample.channel
            n += 1
        if sample.channel != 0:
            continue
        if online is not None and (w := online.cut(sample.t_s, sample.code)) is not None:
            if worker is not None:
                worker.submit(w)
            else:
                on_label(online.classify(w))
        if n == warmup and rss_warm is None:
            rss_warm, blocks_warm = rss_kib(), sys.getallocatedblocks()
        if n % trace_every == 0 and n_trace < rss_trace.size:
            rss_trace[n_trace] = rss_kib()
            n_trace += 1
    if worker is not None:
        worker.close()
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    gc.collect()
    rss_end, blocks_end = rss_kib(), sys.getallocatedblocks()
    read_ms = read_ns[: min(timed.calls, capacity)] * 1e-6

    t, codes, chan = t[:n], codes[:n], chan[:n]
    period = 1.0 / (args.rate * n_in)  # one slot
    slots = np.rint(t / period).astype(np.int64)
    consecutive = np.diff(slots) == 1
    dt = np.diff(t)[consecutive]
    jitter_us = np.abs(dt - period) * 1e6
    # Drift: slope of timestamp against slot index, relative to the nominal period.
    slope = np.polyfit(slots, t, 1)[0] if n > 2 else float("nan")
    lateness_us = (t - slots * period) * 1e6
    volts = codes * (cfg.fsr_v / 32768)
    stats = sampler.stats
    result = {
        "benchmark": "stream",
        "device": "EmulatedADS1115 + ADS1115 driver, real clock",
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "duration_s": args.duration,
        "wall_s": round(wall, 3),
        "nominal_rate_hz": args.rate,
        "achieved_rate_hz": round(n / args.duration, 4),
        "inputs": [i.name for i in inputs],
        "data_rate_sps": data_rate,
        "achieved_rate_per_input_hz": [
            round(int(np.count_nonzero(chan == j)) / args.duration, 4) for j in range(n_in)
        ],
        "interleave_ms": _interleave(t, slots, n_in),
        "schedule_rate_hz": round(1.0 / slope, 6) if n > 2 else None,
        "drift_fraction": float(f"{slope / period - 1.0:.3e}") if n > 2 else None,
        "samples": n,
        "expected_samples": math.ceil(args.duration * args.rate) * n_in,
        "jitter_us": {
            "p50": round(float(np.percentile(jitter_us, 50)), 2) if dt.size else None,
            "p99": round(float(np.percentile(jitter_us, 99)), 2) if dt.size else None,
            "max": round(float(jitter_us.max()), 2) if dt.size else None,
        },
        "read_midpoint_after_deadline_us": {
            "p50": round(float(np.percentile(lateness_us, 50)), 1) if n else None,
            "p99": round(float(np.percentile(lateness_us, 99)), 1) if n else None,
        },
        "gaps": stats.gaps,
        "timeouts": stats.timeouts,
        "overruns": stats.overruns,
        "skipped_slots": stats.skipped_slots,
        "driver": {"reads": driver.stats.reads, "i2c_errors": driver.stats.i2c_errors},
        "read_ms": {
            "p50": round(float(np.percentile(read_ms, 50)), 3) if read_ms.size else None,
            "p99": round(float(np.percentile(read_ms, 99)), 3) if read_ms.size else None,
            "max": round(float(read_ms.max()), 3) if read_ms.size else None,
        },
        "memory_kib": {
            "rss_start": rss_start,
            "rss_end": rss_end,
            "growth": rss_end - rss_start,
            "growth_after_first_second": None if rss_warm is None else rss_end - rss_warm,
            "growth_over_second_half": (
                float(rss_trace[n_trace - 1] - rss_trace[n_trace // 2]) if n_trace >= 4 else None
            ),
            "every_10s": rss_trace[:n_trace].tolist(),
        },
        "python_heap_blocks_growth_after_first_second": (
            None if blocks_warm is None else blocks_end - blocks_warm
        ),
        "python_heap_blocks_growth": blocks_end - blocks_start,
        "cpu_share": round(cpu / wall, 4),
        "signal_check": {
            "peak_to_peak_v": round(float(volts.max() - volts.min()), 4) if n else None,
            "source_peak_to_peak_after_sinc_v": round(
                2
                * args.amplitude
                * abs(np.sinc(args.signal_hz / (args.data_rate * (1 + args.clock_error)))),
                4,
            ),
        },
        "classifier": None if online is None else ("inline" if worker is None else "thread"),
        "extra_model_ms": args.extra_model_ms,
        "window_to_label_latency_ms": _latency(latency_s[:n_labels]),
        "windows": n_labels,
        "skipped_windows": None if online is None else online.skipped_windows,
        "dropped_windows": None if worker is None else worker.dropped,
        "fraction_correct": round(float(correct[:n_labels].mean()), 4) if n_labels else None,
        "note": "window_to_label_latency_ms and fraction_correct need --model (a trained "
        "classifier; the source is then the terrain simulator on --terrain); jitter is "
        "|interval - period| between consecutive samples, timestamps being read "
        "midpoints; read_ms is one single-shot read (conversion wait included); the emulated "
        "bus has no I2C transfer time.",
    }
    print(json.dumps(result))
    return 0


class _Slower:
    """A model that spends ``extra_s`` more per window, busy in Python (holding the GIL)."""

    def __init__(self, model, extra_s: float):
        self._model, self._extra_s = model, extra_s

    def __getattr__(self, name):
        return getattr(self._model, name)

    def window_proba(self, samples, speed=None):
        end = time.perf_counter() + self._extra_s
        while time.perf_counter() < end:
            pass
        return self._model.window_proba(samples, speed)


def _interleave(t: np.ndarray, slots: np.ndarray, n_in: int) -> dict | None:
    """Time from input 0 to input 1 within a round (ms), where both were read."""
    if n_in < 2:
        return None
    first = {int(s) // n_in: x for s, x in zip(slots, t, strict=True) if s % n_in == 0}
    gaps = [x - first[int(s) // n_in] for s, x in zip(slots, t, strict=True)
            if s % n_in == 1 and int(s) // n_in in first]  # fmt: skip
    ms = np.array(gaps) * 1e3
    if not ms.size:
        return None
    return {
        q: round(float(np.percentile(ms, v)), 3) for q, v in (("p1", 1), ("p50", 50), ("p99", 99))
    }


def _latency(seconds: np.ndarray) -> dict | None:
    if not seconds.size:
        return None
    ms = seconds * 1e3
    return {q: round(float(np.percentile(ms, v)), 3) for q, v in (("p50", 50), ("p99", 99))}


if __name__ == "__main__":
    raise SystemExit(main())
