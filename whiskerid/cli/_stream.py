"""``whiskerid stream``: classify terrain online from an ADS1115 (real or emulated)."""

import math
import sys
from pathlib import Path

from ._common import CommandError, HelpFormatter, check_outputs, model_folder, record_or_paper


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
            "'whiskerid[pi]') or a register-level emulated chip fed by the terrain simulator "
            "(--simulate TERRAIN). Ctrl-C or SIGTERM stop cleanly and print a summary."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument("--model", type=Path, required=True, help="trained model (whiskerid train)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--i2c-bus", type=int, help="I2C bus number of a real ADS1115 (1 on a Pi)")
    src.add_argument(
        "--simulate",
        metavar="TERRAIN",
        help="emulate the chip, fed by the terrain simulator on this terrain",
    )
    p.add_argument(
        "--address",
        type=lambda s: int(s, 0),
        default=0x48,
        help="I2C address (ADDR pin: GND 0x48, VDD 0x49, SDA 0x4A, SCL 0x4B)",
    )
    p.add_argument("--speed", type=float, default=0.2, help="robot speed (m/s)")
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
        help="with --simulate: run on a virtual clock, as fast as possible",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated terrain")
    p.add_argument("--quiet", action="store_true", help="no line per window on stderr")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=run)


def run(args) -> dict:
    """Stream until --duration, Ctrl-C or SIGTERM; returns the JSON summary."""
    from .. import hw
    from ..classify import RATE_TOLERANCE, ClassifierModel
    from ..hw import OnlineClassifier, open_recorder, run_stream, terrain_source

    _check_numbers(args)
    # --record never replaces a file (a taken name gets -1, -2, ...), but it must not
    # land inside what the stream reads.
    check_outputs({"--record": args.record},
                  {"--model": model_folder(args.model), "--whisker": args.whisker},
                  force=True)  # fmt: skip
    if args.fast and args.simulate is None:
        raise CommandError("--fast needs --simulate (a real chip runs in real time)")
    model = ClassifierModel.load(args.model)
    if args.simulate is not None and args.simulate not in model.labels:
        raise CommandError(f"--simulate {args.simulate!r} is not a terrain of this model; "
                            f"its labels are {', '.join(model.labels)}")  # fmt: skip
    if args.rate < model.rate_hz * (1 - RATE_TOLERANCE):
        # Resampling up cannot add what lies between the two Nyquist limits: every window
        # would be refused or misread, so refuse before sampling starts.
        raise CommandError(
            f"--rate {args.rate:g} Hz is below the {model.rate_hz:g} Hz this model was trained "
            f"at: stream at {model.rate_hz:g} Hz or more, or train a model at {args.rate:g} Hz "
            "(whiskerid train --rate)"
        )
    clock = hw.FakeClock() if args.fast else None
    timing = {} if clock is None else {"clock": clock.now_ns, "sleep": clock.sleep}
    if args.simulate is not None:
        record = record_or_paper(args.whisker)
        horizon = 600.0 if args.duration is None else args.duration + 2.0
        source = terrain_source(record, args.simulate, args.speed, horizon, seed=args.seed)
        chip = hw.EmulatedADS1115(source, address=args.address, seed=args.seed, **timing)
        bus = chip
    else:
        bus = hw.open_bus(args.i2c_bus)
    adc = hw.ADS1115(bus, args.address, **timing)
    sampler = hw.Sampler(adc, args.rate, **timing)
    meta = {"source": f"simulate {args.simulate}" if args.simulate else f"i2c-{args.i2c_bus}",
            "speed_mps": args.speed, "model": str(args.model)}  # fmt: skip
    if args.simulate:
        meta["terrain"] = args.simulate
    recorder = open_recorder(args.record, rate_hz=args.rate, meta=meta)
    online = OnlineClassifier(model, hop_s=args.hop, speed_mps=args.speed)
    online.warm_up()

    def show(w):
        if not args.quiet:
            alone = "" if w.window_label in ("", w.label) else f"  [window alone: {w.window_label}]"
            print(f"t = {w.t_end_s:8.2f} s  {w.label:<12s} p = {w.confidence:.2f}  "
                  f"({w.latency_s * 1e3:.2f} ms){alone}", file=sys.stderr)  # fmt: skip

    # A virtual clock never waits, so a worker thread would only fall behind: run inline.
    summary = run_stream(sampler.samples(duration_s=args.duration), online, recorder=recorder,
                         on_label=show, background=not args.fast)  # fmt: skip
    summary.gaps, summary.overruns = sampler.stats.gaps, sampler.stats.overruns
    out = summary.to_dict(truth=args.simulate)
    print(f"stream: {out['samples']} samples, {out['windows']} windows, majority "
          f"{out['majority_label']}, gaps {out['gaps']}, overruns {out['overruns']}, "
          f"windows skipped {out['skipped_windows']} / dropped {out['dropped_windows']}"
          + _right(out, args.simulate)
          + (f", recorded to {out['record']}" if out["record"] else ""),
          file=sys.stderr)  # fmt: skip
    return out


#: Longest --simulate stream (s): its terrain is synthesised up front, in memory.
MAX_SIMULATED_S = 3600.0


def _check_numbers(args) -> None:
    """Refuse NaN, infinities and non-positive values (argparse's float takes 'nan', 'inf')."""
    for flag, value in (("--duration", args.duration), ("--rate", args.rate),
                        ("--hop", args.hop), ("--speed", args.speed)):  # fmt: skip
        if value is not None and not (math.isfinite(value) and value > 0):
            hint = " (leave it out to run until Ctrl-C)" if flag == "--duration" else ""
            raise CommandError(f"{flag} {value!r} must be a positive number{hint}")
    if args.simulate is not None and args.speed >= 5:
        raise CommandError(f"--speed {args.speed:g} m/s is not plausible (0 < v < 5)")
    if args.simulate is not None and (args.duration or 0) > MAX_SIMULATED_S:
        raise CommandError(
            f"--duration {args.duration:g} s: a simulated stream lasts at most "
            f"{MAX_SIMULATED_S:g} s (its terrain is synthesised up front)"
        )


def _right(out: dict, truth: str | None) -> str:
    """The share of windows labelled right, when the truth is known and a window was labelled."""
    if truth is None:
        return ""
    if out["fraction_correct"] is None:
        return ", no window labelled"
    return f", {out['fraction_correct']:.1%} windows right"
