"""``whiskerid stream``: classify terrain online from an ADS1115 (real or emulated)."""

import contextlib
import dataclasses
import json
import math
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np

from ._cache import CACHE_ENV, cache_dir, use_compile_cache
from ._common import (
    WATCH,
    CommandError,
    HelpFormatter,
    Interrupted,
    check_outputs,
    interrupts,
    json_safe,
    model_folder,
    record_or_paper,
    say,
)
from ._prestart import discard, take


def add_parser(sub) -> None:
    """Register ``stream`` on the CLI's subparsers."""
    p = sub.add_parser(
        "stream",
        help="classify terrain online from an ADS1115 stream (Pi, or emulated)",
        description=(
            "Sample an ADS1115 at --rate (200 Hz) on a drift-free schedule, classify every "
            "--hop seconds the last window with a trained model, and optionally record the "
            "stream to CSV (fsync every second: a crash or power cut loses at most the last "
            "second). Either a real chip on an I2C bus (--i2c-bus, needs smbus2: pip install "
            "'whiskerid[pi]'), a register-level emulated chip fed by the terrain simulator "
            "(--simulate TERRAIN), or a recording replayed through the emulated chip "
            "(--replay). A window the sensor or the bus cannot vouch for is labelled "
            "sensor-fault or no-data with its reason, never a terrain; each fault episode is "
            "logged once. Ctrl-C or SIGTERM stop cleanly and print a summary."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument("--model", type=Path, required=True, help="trained model (whiskerid train)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--i2c-bus", type=int, help="I2C bus number of a real ADS1115 (1 on a Pi)")
    src.add_argument(
        "--simulate",
        metavar="TERRAIN",
        help="emulate the chip, fed by the terrain simulator on this terrain (fresh terrain "
        "for ever without --duration)",
    )
    src.add_argument(
        "--replay",
        type=Path,
        metavar="REC",
        help="emulate the chip, fed by this recording (volts or ADC codes) for its length "
        "or --duration: a model checked on your own data exactly as it runs online",
    )
    p.add_argument(
        "--address",
        type=lambda s: int(s, 0),
        default="0x48",  # converted by type; --help shows it as written, not as 72
        help="I2C address (ADDR pin: GND 0x48, VDD 0x49, SDA 0x4A, SCL 0x4B)",
    )
    p.add_argument(
        "--inputs",
        default="A0",
        help="inputs read round-robin (A0,A1; A0-A1 differential; 0x49:A0 on a second "
        "chip); the first is classified, all are recorded",
    )
    p.add_argument(
        "--speed",
        type=float,
        help="robot speed (m/s) when --speed-from is not given (default: the replayed "
        "recording's speed_mps, else 0.2)",
    )
    p.add_argument(
        "--speed-from",
        metavar="SOURCE",
        help='live robot speed as JSON lines ({"speed_mps": 0.3}): - for standard input, '
        "udp:PORT on localhost, or an odometry CSV (t, speed_mps) with --replay",
    )
    p.add_argument(
        "--labels-to",
        metavar="SINK",
        help="write each window's label as a JSON line (t_s, label, confidence, speed_mps, "
        "reason): - for standard output, or udp:PORT on localhost",
    )
    p.add_argument(
        "--stopped-below",
        type=float,
        default=3.0,
        metavar="CODES",
        help="a window varying by less than this many ADC codes RMS is a whisker at rest: "
        "labelled stopped (0: never)",
    )
    p.add_argument(
        "--duration",
        type=float,
        help="stop after this many seconds (default: run until Ctrl-C or SIGTERM)",
    )
    p.add_argument("--rate", type=float, default=200.0, help="sampling rate (Hz)")
    p.add_argument("--hop", type=float, default=0.5, help="seconds between classified windows")
    p.add_argument(
        "--record",
        type=Path,
        help="write the stream to this CSV (never overwrites: a taken name gets -1, -2, ...)",
    )
    p.add_argument("--whisker", type=Path, help="whisker record for --simulate (the paper's)")
    p.add_argument(
        "--fast",
        action="store_true",
        help="with --simulate or --replay: run on a virtual clock, as fast as possible",
    )
    p.add_argument(
        "--compile-cache",
        metavar="DIR",
        help=f"JAX's persistent compilation cache, which also keeps the model's traced "
        f"program: a restart reuses both instead of tracing and compiling again "
        f"(default ${CACHE_ENV}, else ~/.cache/whiskerid/jax; 'none' turns it off)",
    )
    p.add_argument(
        "--priority",
        choices=("auto", "realtime", "nice", "none"),
        default="auto",
        help="priority of the sampling process, so that it keeps its schedule on a busy "
        "machine: auto tries real time (SCHED_FIFO, where permitted: root, or LimitRTPRIO in "
        "a systemd unit), then a raised nice value; the one granted is in the summary",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated terrain")
    p.add_argument("--quiet", action="store_true", help="no line per window on stderr")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=run)


def run(args) -> dict:
    """Stream until --duration, Ctrl-C or SIGTERM; returns the JSON summary.

    A signal only raises a flag (never an exception inside whatever runs when it lands):
    the stream stops at the next sample, prints its summary and exits 130 or 143.
    """
    policy = interrupts()
    try:
        with policy.deferred():
            out = _stream(args, policy)
    finally:
        discard(args)  # a sampling process started early that the stream did not take
    if policy.signum is not None:
        if args.json:
            print(json.dumps(json_safe({"command": "stream", **out}), indent=2, allow_nan=False))
        record = out.get("record")
        WATCH.notes.append(lambda: "summary printed" + (f"; recorded to {record}" if record
                                                        else ""))  # fmt: skip
        raise Interrupted(policy.signum)
    return out


def _stream(args, policy) -> dict:
    from .. import hw

    _check_numbers(args)
    # --record never replaces a file (a taken name gets -1, -2, ...), but it must not
    # land inside what the stream reads.
    check_outputs({"--record": args.record},
                  {"--model": model_folder(args.model), "--whisker": args.whisker,
                   "--replay": args.replay},
                  force=True)  # fmt: skip
    if args.fast and args.simulate is None and args.replay is None:
        raise CommandError("--fast needs --simulate or --replay (a real chip runs in real time)")
    if args.labels_to == "-" and args.json:
        raise CommandError("--labels-to - and --json both write to standard output; use one")
    try:
        inputs = hw.parse_inputs(args.inputs, default_address=args.address)
        labels_to = args.labels_to and hw.parse_endpoint(args.labels_to, "--labels-to")
    except ValueError as e:
        raise CommandError(str(e)) from None
    cache = _cache_folder(args.compile_cache)
    if args.simulate is not None:  # the simulator needs JAX, and the model's labels first
        model = _load_model(args, cache)
    else:  # JAX, the classifier and the model load while the recording is read, sampling
        model = _ModelLoader(args, cache)  # starts and the first window fills
    replayed = None if args.replay is None else _read_replay(args)
    try:
        cfg = hw.stream_config(inputs, args.rate)
    except ValueError as e:
        raise CommandError(f"--inputs {args.inputs} at --rate {args.rate:g}: {e}") from None
    speed = _speed(args, replayed)
    with tempfile.TemporaryDirectory(prefix="whiskerid-stream-") as tmp:
        return _stream_from(hw, args, policy, inputs, cfg, speed, replayed, model, cache,
                            labels_to, Path(tmp))  # fmt: skip


def _stream_from(hw, args, policy, inputs, cfg, speed, replayed, model, cache, labels_to, tmp):
    """Start the sampler, load the model, stream; ``tmp`` holds a simulated terrain."""
    spec = hw.SamplerSpec(inputs=args.inputs, address=args.address, rate_hz=args.rate,
                          duration_s=args.duration, i2c_bus=args.i2c_bus,
                          replay=None if args.replay is None else str(args.replay),
                          seed=args.seed, priority=args.priority)  # fmt: skip
    child = not args.fast and (args.simulate is None or _up_front(args))
    sources = None
    if child and args.simulate is not None:
        # The terrain is made now (JAX, here) and played by the sampling process.
        spec = dataclasses.replace(spec, replay=_save_terrain(hw, inputs, args, tmp))
    else:
        # Made here even when a sampling process replays the recording itself: a recording
        # without the inputs' columns is then refused at once, before anything starts.
        sources = _sources(hw, args, inputs, replayed)
    sampler = bus = samples = None
    if child:
        # Sampling starts now, in a process of its own: the first window fills while JAX
        # starts and the model loads, and the model never holds up the sampling schedule.
        samples = hw.SamplingProcess(spec, process=take(args))
    sink = recorder = None
    try:
        warm = isinstance(model, _ModelLoader)
        # The loader's errors are raised here, where a load's always were.
        model, engine = model.result() if warm else model
        if not args.quiet:
            print("stream: labelling with " + ("NumPy (this model's features need no JAX)"
                  if engine["engine"] == "numpy" else f"JAX: {engine['why']}"),
                  file=sys.stderr)  # fmt: skip
        volts = getattr(model, "channel", None) in ("voltage", "volts")
        lsb = cfg.fsr_v / 32768 if volts else 1.0
        limits = (-cfg.fsr_v, cfg.fsr_v) if volts else (-32768, 32767)
        quiet = args.stopped_below * lsb if args.stopped_below > 0 else None
        online = hw.OnlineClassifier(model, hop_s=args.hop, speed_mps=speed, limits=limits,
                                     quiet_std=quiet)  # fmt: skip
        if not warm:
            online.warm_up(cache)  # compile (or load from the cache) before the first window
        if samples is None:
            # Sampled here (the endless simulator lives here; a virtual clock never waits):
            # the chip is made now, after the warm-up, so that its time starts with the
            # sampler's and the simulated terrain is played from its start.
            clock = hw.FakeClock() if args.fast else None
            timing = {} if clock is None else {"clock": clock.now_ns, "sleep": clock.sleep}
            sampler, bus, _, _ = hw.open_sampler(spec, sources=sources, **timing)
            samples = sampler.samples(duration_s=args.duration, gaps=True)
        # Opened once the model is ready, so a model that fails leaves no file behind.
        recorder = _open_recorder(hw, args, inputs, _meta(args, inputs, speed, cfg))
        sink = None if labels_to is None else hw.LabelSink(labels_to)
        summary = hw.StreamSummary()
        try:
            stats = _run(hw, args, samples, online, recorder, sink, summary, policy)
        except hw.SamplingError as e:
            raise CommandError(f"{_source_name(args)}: {e}") from None
    finally:
        if isinstance(samples, hw.SamplingProcess):
            samples.close()
        if recorder is not None:
            with contextlib.suppress(OSError, ValueError):
                recorder.close()  # run_stream closes it; here for a failure before it ran
        for closing in (sink, speed if isinstance(speed, hw.SpeedFeed) else None, bus):
            if closing is not None:
                closing.close()
    return _report(args, samples, sampler, stats, summary, policy, engine)


def _report(args, samples, sampler, stats, summary, policy, engine) -> dict:
    """The summary on stderr, and as the command's JSON."""
    summary.samples, summary.duration_s = stats.samples, stats.duration_s
    summary.skipped_windows, summary.dropped_windows = stats.skipped_windows, stats.dropped_windows
    summary.record, summary.stopped_by = stats.record, stats.stopped_by
    summary.record_stopped = stats.record_stopped
    st = samples.stats if sampler is None else sampler.stats
    summary.gaps, summary.overruns = st.gaps, st.overruns
    summary.bus_errors = {"timeouts": st.timeouts, "other_errors": st.other_errors,
                          "last_error": st.last_error}  # fmt: skip
    out = summary.to_dict(truth=args.simulate)
    out["classifier"] = engine
    if sampler is None:
        out["sampling"] = {"process": True, "priority": samples.priority,
                           "skipped_slots": st.skipped_slots,
                           "handoff": samples.handoff}  # fmt: skip
    else:
        out["sampling"] = {"process": False, "skipped_slots": st.skipped_slots}
    faults = sum(summary.fault_counts.values())
    majority = out["majority_label"] or (
        f"none ({out['unlabelled_windows']} of the moving windows got no terrain)"
        if out["unlabelled_windows"]
        else "none"
    )
    print(f"stream: {out['samples']} samples, {out['windows']} windows, majority "
          f"{majority}, gaps {out['gaps']}, overruns {out['overruns']}, "
          f"fault windows {faults} in {out['fault_episodes']} episode(s), "
          f"dropped {out['dropped_windows']}"
          + _right(out, args.simulate)
          + (f", recorded to {out['record']}" if out["record"] else "")
          + (f"; {out['record_stopped']}" if out["record_stopped"] else "")
          + (f"; {summary.stale_speed_windows} window(s) labelled without a fresh speed"
             if summary.stale_speed_windows else ""),
          file=sys.stderr)  # fmt: skip
    if summary.all_failed and policy.signum is None:
        reasons = "; ".join(f"{k} ({v})" for k, v in out["faults"].items())
        raise CommandError(f"no window got a terrain: {reasons}")
    return out


def _run(hw, args, samples, online, recorder, sink, summary, policy):
    """Feed the samples to the classifier; labels go to the sink, the summary and stderr."""

    def show(w):
        if sink is not None:
            sink(w)
        episode = summary.add(w)
        if episode == "start":
            print(f"t = {w.t_end_s:8.2f} s  {w.label}: {w.reason}", file=sys.stderr)
        elif episode == "end":
            print(f"t = {w.t_end_s:8.2f} s  the fault is over", file=sys.stderr)
        elif not args.quiet and not w.fault:
            alone = "" if w.window_label in ("", w.label) else f"  [window alone: {w.window_label}]"
            print(f"t = {w.t_end_s:8.2f} s  {w.label:<12s} p = {w.confidence:.2f}  "
                  f"({w.latency_s * 1e3:.2f} ms){alone}", file=sys.stderr)  # fmt: skip

    # The summary is counted in show(): run_stream gets a throwaway one, so no double count.
    # A virtual clock never waits, so a worker thread would only fall behind: run inline.
    if policy.stop_requested():  # a signal during the start-up: nothing is streamed
        return hw.StreamSummary(stopped_by="signal")
    return hw.run_stream(samples, online, recorder=recorder, on_label=show,
                         background=not args.fast, stop=policy.stop_requested,
                         on_note=lambda note: print(note, file=sys.stderr))  # fmt: skip


def _cache_folder(option: str | None) -> Path | None:
    """The folder of JAX's persistent compilation cache (created), or None when it is off."""
    folder = None if option is not None and option.lower() == "none" else (
        Path(option) if option else cache_dir())  # fmt: skip
    if folder is None:
        return None
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise CommandError(f"--compile-cache {folder}: cannot create it ({e.strerror}); give "
                           "another folder, or 'none'") from None  # fmt: skip
    return folder


class _ModelLoader:
    """The model, loaded and warmed up (:meth:`whiskerid.hw.OnlineClassifier.warm_up`) on a
    thread of its own, started at once.

    A model whose features NumPy computes is run in NumPy (:func:`load_numpy_classifier`):
    loading it takes milliseconds. Otherwise importing JAX and the classifier and loading
    the model's compiled program take seconds (about 1.5 s of CPU, three times that in wall
    time on a busy machine); the stream reads its recording and starts its sampling process
    meanwhile. The thread only loads: a failure is kept and raised by :meth:`result`, in the
    main thread, where the load's errors have always been raised (a command that fails
    earlier never asks for it).
    """

    def __init__(self, args, cache: Path | None):
        self._model = self._error = None
        self._thread = threading.Thread(target=self._load, args=(args, cache), daemon=True,
                                        name="whiskerid-model-load")  # fmt: skip
        self._thread.start()

    def _load(self, args, cache: Path | None) -> None:
        try:
            from .. import hw

            model, engine = _load_model(args, cache)
            hw.OnlineClassifier(model).warm_up(cache)  # the model is warm for any hop
            self._model = model, engine
        except BaseException as e:  # raised again in the main thread
            self._error = e

    def result(self):
        """The warm model and how it runs (see :func:`_load_model`); the load's error, if it
        failed."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._model


def load_numpy_classifier(path: Path):
    """:func:`whiskerid.hw._numpy_classifier.load_numpy_classifier` (imported when called)."""
    from ..hw._numpy_classifier import load_numpy_classifier as load

    return load(path)


def _load_model(args, cache: Path | None):
    """The model, and how it runs: ``{"engine": "numpy"}`` for a model whose features
    NumPy computes (no JAX imported), else ``{"engine": "jax", "why": ...}``, loaded with
    JAX's compilation cache set up. Refuses a model that cannot serve."""
    from ..io._rate import RATE_TOLERANCE

    model, why = load_numpy_classifier(args.model)
    engine = {"engine": "numpy"} if model is not None else {"engine": "jax", "why": why}
    if model is None:
        use_compile_cache(cache)
        from ..classify import ClassifierModel

        model = ClassifierModel.load(args.model)
    if args.simulate is not None and args.simulate not in model.labels:
        raise CommandError(f"--simulate {args.simulate!r} is not a terrain of this model; "
                            f"its labels are {', '.join(model.labels)}")  # fmt: skip
    if args.rate < model.rate_hz * (1 - RATE_TOLERANCE):
        # Resampling up cannot add what lies between the two Nyquist limits: every window
        # would be refused or misread, so refuse before any window is read.
        raise CommandError(
            f"--rate {args.rate:g} Hz is below the {model.rate_hz:g} Hz this model was trained "
            f"at: stream at {model.rate_hz:g} Hz or more, or train a model at {args.rate:g} Hz "
            "(whiskerid train --rate)"
        )
    return model, engine


def _speed(args, replayed):
    """The speed the classifier uses: a number, or a callable of the stream time."""
    from .. import hw

    if args.speed_from is None:
        if args.speed is not None:
            return args.speed
        own = None if replayed is None else replayed.meta.get("speed_mps")
        return float(own) if own is not None else 0.2  # checked by _read_replay
    if args.speed_from in ("-",) or args.speed_from.startswith("udp:"):
        try:
            return hw.SpeedFeed(hw.parse_endpoint(args.speed_from, "--speed-from"))
        except OSError as e:
            raise CommandError(f"--speed-from {args.speed_from}: {e.strerror or e}") from None
    if args.replay is None:
        raise CommandError("--speed-from with an odometry file needs --replay (its times are "
                           "the recording's)")  # fmt: skip
    return hw.odometry_speed(args.speed_from)


def _sources(hw, args, inputs, replayed) -> list | None:
    """What the emulated chip's inputs play (the simulator's terrain or the replayed
    recording), or None for a real chip."""
    if args.i2c_bus is not None:
        return None
    names = [i.name for i in inputs]
    if replayed is not None:
        try:
            return hw.replay_sources(replayed, names)
        except ValueError as e:
            raise CommandError(str(e)) from None
    record = record_or_paper(args.whisker)
    # Up front for a short run; in chunks of fresh terrain for a long or endless one.
    horizon = args.duration + 2.0 if _up_front(args) else None
    return [hw.terrain_source(record, args.simulate, _nominal(args), horizon,
                              seed=args.seed + j) for j in range(len(inputs))]  # fmt: skip


def _up_front(args) -> bool:
    """Whether the simulated terrain is made before the stream starts (a short run)."""
    return args.duration is not None and args.duration <= MAX_UP_FRONT_S


def _save_terrain(hw, inputs, args, folder: Path) -> str:
    """The simulated terrain of every input, saved as a recording (volts) for the sampling
    process to play; its path."""
    record = record_or_paper(args.whisker)
    columns, t0 = {}, None
    for j, inp in enumerate(inputs):
        t, v = hw.terrain_signal(record, args.simulate, _nominal(args), args.duration + 2.0,
                                 seed=args.seed + j)  # fmt: skip
        t0 = t if t0 is None else t0
        columns[inp.name] = np.interp(t0, t, v)
    path = folder / "terrain.npz"
    np.savez(path, t=t0, meta_units="V", **columns)
    return str(path)


def _read_replay(args):
    """The recording to replay, refused when its timestamps cannot be this stream's (not in
    seconds, or slower than --rate) or its speed is not plausible."""
    from ..io import RATE_METADATA_TOLERANCE, RecordingError, read_recording, recording_rate

    rec = read_recording(args.replay)
    try:
        own = recording_rate(rec)
    except RecordingError as e:
        raise CommandError(str(e)) from None
    if own < args.rate * (1 - RATE_METADATA_TOLERANCE):
        hint = " (is the time column in seconds?)" if own < args.rate / 50 else ""
        raise CommandError(
            f"--replay {args.replay}: sampled at {own:.4g} Hz{hint}, below the --rate "
            f"{args.rate:g} Hz it would be streamed at: write its times in seconds, or "
            f"stream it at --rate {own:.4g}"
        )
    if "speed_mps" in rec.meta and args.speed is None and args.speed_from is None:
        try:
            from .. import hw

            hw.check_speed_mps(rec.meta["speed_mps"], f"--replay {args.replay} speed_mps")
        except ValueError as e:
            raise CommandError(f"{e}, or pass --speed") from None
    length = float(rec.t[-1] - rec.t[0])
    if args.duration is None:  # the recording's length: after it there is no signal
        args.duration = length
    elif args.duration > length + 1.0 / args.rate:
        # Past its end the emulated chip would hold the last value: a frozen sensor to the
        # window checks. The replay ends with the file instead.
        say(f"--replay {args.replay}: end of file at {length:.3g} s, before --duration "
            f"{args.duration:g} s: the stream stops there")  # fmt: skip
        args.duration = length
    return rec


def _source_name(args) -> str:
    if args.replay:
        return f"--replay {args.replay}"
    return f"--i2c-bus {args.i2c_bus}" if args.i2c_bus is not None else "the emulated chip"


def _nominal(args) -> float:
    return 0.2 if args.speed is None else args.speed


def _meta(args, inputs, speed, cfg) -> dict:
    source = (f"simulate {args.simulate}" if args.simulate else
              f"replay {args.replay}" if args.replay else f"i2c-{args.i2c_bus}")  # fmt: skip
    meta = {"source": source, "model": str(args.model), "inputs": ",".join(i.name for i in inputs),
            "fsr_v": f"{cfg.fsr_v:g}", "data_rate_sps": cfg.data_rate_sps}  # fmt: skip
    if isinstance(speed, float | int):
        meta["speed_mps"] = speed
    if args.simulate:
        meta["terrain"] = args.simulate
    return meta


def _open_recorder(hw, args, inputs, meta):
    if args.record is None:
        return None
    if len(inputs) == 1:
        return hw.open_recorder(args.record, rate_hz=args.rate, meta=meta)
    return hw.Recorder(hw.unique_path(args.record), columns=[i.name for i in inputs],
                       rate_hz=args.rate, units="code", own_times=True, metadata=meta)  # fmt: skip


#: Longest --simulate stream (s) whose terrain is synthesised up front, in memory; longer or
#: endless ones are made in chunks while they play.
MAX_UP_FRONT_S = 600.0


def _check_numbers(args) -> None:
    """Refuse NaN, infinities and non-positive values (argparse's float takes 'nan', 'inf')."""
    if not (math.isfinite(args.stopped_below) and args.stopped_below >= 0):
        raise CommandError(f"--stopped-below {args.stopped_below!r} must be a number >= 0")
    for flag, value in (("--duration", args.duration), ("--rate", args.rate),
                        ("--hop", args.hop)):  # fmt: skip
        if value is not None and not (math.isfinite(value) and value > 0):
            hint = " (leave it out to run until Ctrl-C)" if flag == "--duration" else ""
            raise CommandError(f"{flag} {value!r} must be a positive number{hint}")
    if args.speed is not None:
        from .. import hw

        try:
            hw.check_speed_mps(args.speed, "--speed")
        except ValueError as e:
            raise CommandError(str(e)) from None
    if args.simulate is not None and args.speed == 0:
        raise CommandError("--speed 0 with --simulate: a terrain needs a moving robot")


def _right(out: dict, truth: str | None) -> str:
    """The share of windows labelled right, when the truth is known and a window was labelled."""
    if truth is None:
        return ""
    if out["fraction_correct"] is None:
        return ", no window labelled"
    return f", {out['fraction_correct']:.1%} windows right"
