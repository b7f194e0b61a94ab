"""``whiskerid record``: sample ADS1115 inputs to a recording CSV, no model needed."""

import contextlib
import json
import math
import sys
from pathlib import Path

from .._choices import TERRAINS
from ._common import WATCH, CommandError, HelpFormatter, Interrupted, interrupts, json_safe

#: When an emulated pluck is released (s): held bent by hand before, so its release is found
#: as in a real recording.
PLUCK_DELAY_S = 0.5
#: Longest emulated pluck simulated (s); the whisker is at rest after it.
PLUCK_SPAN_S = 10.0


def add_parser(sub) -> None:
    """Register ``record`` on the CLI's subparsers."""
    p = sub.add_parser(
        "record",
        help="record ADS1115 inputs to CSV (a calibration pluck, or data to train on)",
        description=(
            "Sample one or several ADS1115 inputs on a drift-free schedule and write them to "
            "a recording CSV that calibrate, train and classify read. Several inputs are "
            "read round-robin, one fresh single-shot conversion each: every input is "
            "sampled at --rate, input j later than the first by j/(n x rate); the file "
            "has one row per round, 't' the first input's time and 't_<input>' the others' "
            "own times. One input may be sampled up to the chip's fastest rate, 860 Hz "
            "(above what single-shot conversions allow the chip converts continuously). "
            "The file is fsynced every second: a crash or power cut loses at most the last "
            "second. Needs numpy and, for a real chip, smbus2 only."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument("out", type=Path, metavar="OUT.csv", help="file to write (never overwritten)")
    p.add_argument(
        "--inputs",
        default="A0",
        help="inputs, comma-separated: A0..A3 single-ended, A0-A1, A0-A3, A1-A3, A2-A3 "
        "differential; ADDRESS:INPUT (0x49:A0) for a second chip",
    )
    p.add_argument("--rate", type=float, default=200.0, help="samples per second of each input")
    p.add_argument(
        "--duration", type=float, help="seconds to record (default: until Ctrl-C or SIGTERM)"
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--i2c-bus", type=int, help="I2C bus number of a real ADS1115 (1 on a Pi)")
    src.add_argument(
        "--emulate",
        "--simulate",
        metavar="SOURCE",
        help="record an emulated chip instead: 'pluck' (the whisker released from a "
        "deflection), a terrain name (the terrain simulator), or a recording file to replay "
        "(each input from its own column, else the first)",
    )
    p.add_argument(
        "--address",
        type=lambda s: int(s, 0),
        default="0x48",  # converted by type; --help shows it as written, not as 72
        help="I2C address of the chip (ADDR pin: GND 0x48, VDD 0x49, SDA 0x4A, SCL 0x4B)",
    )
    p.add_argument("--fsr", type=float, default=4.096, help="PGA full-scale range (V)")
    p.add_argument(
        "--data-rate",
        type=int,
        help="ADS1115 data rate (SPS); default the slowest that fits each sample's slot",
    )
    p.add_argument(
        "--units", choices=("code", "V"), default="code", help="write ADC codes or volts"
    )
    p.add_argument("--whisker", type=Path, help="whisker record for --emulate (the paper's)")
    p.add_argument(
        "--speed",
        type=float,
        help="robot speed (m/s), written as speed_mps metadata for train and classify; "
        "drives --emulate TERRAIN (0.2 there by default)",
    )
    p.add_argument(
        "--added-mass",
        metavar="MASS",
        help="a known mass clipped to the whisker's tip for this recording (e.g. 0.52g±0.01g), "
        "written as added_mass_kg and added_mass_std_kg metadata: calibrate fits plucks with "
        "and without it jointly for EI and C (pluck, clip the mass, pluck again)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the emulated signal and noise")
    p.add_argument(
        "--fast", action="store_true", help="with --emulate: a virtual clock, as fast as possible"
    )
    p.add_argument(
        "--priority",
        choices=("auto", "realtime", "nice", "none"),
        default="auto",
        help="priority of the sampling, so that it keeps its schedule on a busy machine: "
        "auto tries real time (SCHED_FIFO, where permitted), then a raised nice value; the "
        "one granted is in the summary (ignored with --fast)",
    )
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=run)


def run(args) -> dict:
    """Record until --duration, Ctrl-C or SIGTERM; returns the JSON summary.

    A signal only raises a flag that the sampling loop reads at every slot: the file is
    closed whole, the summary printed, and the command exits 130 (SIGINT) or 143 (SIGTERM).
    """
    policy = interrupts()
    with policy.deferred():
        out = _run(args, policy)
    if policy.signum is not None:
        if args.json:
            print(json.dumps(json_safe({"command": "record", **out}), indent=2, allow_nan=False))
        WATCH.notes.append(lambda: f"kept (complete): {out['out']} ({out['rows']} rows)")
        raise Interrupted(policy.signum)
    return out


def _run(args, policy) -> dict:
    from .. import hw

    _check(args)
    try:
        inputs = hw.parse_inputs(args.inputs, default_address=args.address)
        config, mode = _config(hw, inputs, args)
    except ValueError as e:
        raise CommandError(str(e)) from None
    if args.out.exists():
        raise CommandError(f"{args.out} exists; give another file name (nothing is overwritten)")
    clock = hw.FakeClock() if args.fast else None
    timing = {} if clock is None else {"clock": clock.now_ns, "sleep": clock.sleep}
    bus = _emulated_bus(hw, inputs, args, timing) if args.emulate else hw.open_bus(args.i2c_bus)
    try:
        return _record(hw, bus, inputs, config, mode, args, timing, policy)
    finally:
        bus.close()


def _check(args) -> None:
    for flag, value in (("--rate", args.rate), ("--duration", args.duration)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise CommandError(f"{flag} {value!r} must be a positive number")
    if args.speed is not None and not (math.isfinite(args.speed) and 0 <= args.speed < 5):
        raise CommandError(f"--speed {args.speed!r} must be a plausible speed (0 <= v < 5 m/s)")
    if args.fast and not args.emulate:
        raise CommandError("--fast needs --emulate (a real chip runs in real time)")
    if args.fast and args.duration is None:
        raise CommandError("--fast needs --duration (a virtual clock would never stop)")
    if args.added_mass is not None:
        from ..io import parse_mass

        try:
            args.added_mass_kg = parse_mass(args.added_mass)
        except ValueError as e:
            raise CommandError(f"--added-mass: {e}") from None


def _config(hw, inputs, args):
    """The chip's configuration, and whether it converts single-shot or continuously."""
    n = len(inputs)
    slot_s = 1.0 / (n * args.rate)
    fastest = hw.max_scan_rate_hz(n)
    mode = "single-shot"
    if args.rate > fastest:
        if n > 1 or args.rate > 860:
            raise ValueError(
                f"--rate {args.rate:g} Hz: {n} input(s) read one fresh conversion each allow "
                f"at most {fastest:.0f} Hz per input"
                + ("; a single input may go up to 860 Hz" if n > 1 else "")
            )
        mode = "continuous"
    if args.data_rate is not None:
        dr = _check_data_rate(args.data_rate, slot_s, mode, args.rate, n)
    elif mode == "continuous":
        dr = 860
    else:
        dr = hw.data_rate_for(slot_s)
    cfg = hw.Config(mux=inputs[0].mux, fsr_v=args.fsr, data_rate_sps=dr,
                    single_shot=mode == "single-shot")  # fmt: skip
    return cfg, mode


def _check_data_rate(dr: int, slot_s: float, mode: str, rate: float, n: int) -> int:
    """``dr`` if every slot gets a fresh conversion at it, else refused: a slower data rate
    would repeat old conversions under new timestamps, and the file would claim a rate its
    samples do not have."""
    from .. import hw
    from ..io._ads1115_spec import DATA_RATES_SPS

    if dr not in DATA_RATES_SPS:
        return dr  # refused by the chip's configuration, in its own words
    fits = dr >= n * rate if mode == "continuous" else 1.0 / dr <= slot_s
    if not fits:
        fastest = hw.data_rate_for(slot_s) if mode == "single-shot" else 860
        raise ValueError(
            f"--data-rate {dr} SPS converts in {1e3 / dr:.3g} ms, longer than the "
            f"{slot_s * 1e3:.3g} ms slot of --rate {rate:g} Hz ({n} input(s)): each sample "
            f"would not be a fresh conversion; use --data-rate {fastest} or more, or leave it "
            "out"
        )
    return dr


def _emulated_bus(hw, inputs, args, timing):
    """Emulated chip(s) answering on the inputs' addresses, each input fed by its source."""
    return hw.emulated_bus(inputs, _sources(inputs, args), seed=args.seed, noise_v=1e-4,
                           **timing)  # fmt: skip


def _sources(inputs, args) -> list:
    """One signal ``source(t_s) -> volts`` per input."""
    from .. import hw

    what = args.emulate
    if Path(what).suffix.lower() in (".csv", ".npz", ".npy"):
        rec = _read_source(what, args.rate)
        try:
            return hw.replay_sources(rec, [i.name for i in inputs], fsr_v=args.fsr)
        except ValueError as e:
            raise CommandError(str(e)) from None
    if what == "pluck":
        return [_pluck(args)] * len(inputs)
    if what not in TERRAINS:
        raise CommandError(f"--emulate {what!r}: not a recording file (.csv, .npz, .npy), "
                           f"'pluck' or a terrain ({', '.join(TERRAINS)})")  # fmt: skip
    return [_terrain(args, what, j) for j in range(len(inputs))]


def _read_source(path: str, rate: float):
    """The recording to play, refused when its times are not seconds (a rate far below the
    one it is recorded at)."""
    from ..io import RATE_METADATA_TOLERANCE, RecordingError, read_recording, recording_rate

    try:
        rec = read_recording(path)
        own = recording_rate(rec)
    except RecordingError as e:
        raise CommandError(str(e)) from None
    if own < rate * (1 - RATE_METADATA_TOLERANCE):
        hint = " (is the time column in seconds?)" if own < rate / 50 else ""
        raise CommandError(
            f"--emulate {path}: sampled at {own:.4g} Hz{hint}, below the --rate {rate:g} Hz "
            f"it would be recorded at: write its times in seconds, or record at --rate "
            f"{own:.4g}"
        )
    return rec


def _pluck(args):
    """The Hall voltage of the whisker held bent by hand and released at PLUCK_DELAY_S
    (with the ``--added-mass`` at its tip, if given).

    A pluck has rung down within seconds: longer recordings hold the rest value after it.
    """
    from .. import hw
    from ..model import simulate_pluck
    from ._common import record_or_paper

    length = min(args.duration or PLUCK_SPAN_S, PLUCK_SPAN_S) + 1.0
    whisker = record_or_paper(args.whisker)
    if args.added_mass is not None:  # the emulated whisker carries the clipped mass too
        whisker = whisker.replace(tip_mass_kg=whisker.tip_mass_kg + args.added_mass_kg[0])
    sim, _ = simulate_pluck(whisker, kind="held", observable="voltage",
                            rate_hz=20_000.0, duration_s=length, release_s=PLUCK_DELAY_S,
                            noise_db=None, seed=args.seed)  # fmt: skip
    return hw.source_from_recording(sim.t, sim.signal())


def _terrain(args, terrain: str, j: int):
    from ..hw import terrain_source
    from ._common import record_or_paper

    if args.duration is None:
        raise CommandError("--emulate TERRAIN needs --duration (its terrain is made up front)")
    speed = 0.2 if args.speed is None else args.speed
    return terrain_source(record_or_paper(args.whisker), terrain, speed, args.duration + 2,
                          seed=args.seed + j)  # fmt: skip


def _record(hw, bus, inputs, config, mode, args, timing, policy) -> dict:
    names = [i.name for i in inputs]
    n = len(inputs)
    adc = hw.converter(bus, inputs, config=config, **timing)
    to_volts = adc.to_volts
    sampler = hw.Sampler(adc, args.rate, **timing)
    source = f"emulate {args.emulate}" if args.emulate else f"i2c-{args.i2c_bus}"
    meta = {"source": source, "inputs": ",".join(names), "fsr_v": f"{config.fsr_v:g}",
            "data_rate_sps": config.data_rate_sps, "mode": mode}  # fmt: skip
    if n > 1:
        meta["interleave_s"] = f"{1.0 / (n * args.rate):.9g}"
    if args.emulate == "pluck":
        meta["excitation"] = "decay"
    elif args.emulate and not Path(args.emulate).suffix:
        meta["terrain"] = args.emulate
        meta["speed_mps"] = 0.2 if args.speed is None else args.speed
    if args.speed is not None:
        meta["speed_mps"] = args.speed
    if args.added_mass is not None:
        from ..io import ADDED_MASS_KEY, ADDED_MASS_STD_KEY

        kg, std = args.added_mass_kg
        meta[ADDED_MASS_KEY], meta[ADDED_MASS_STD_KEY] = f"{kg:.9g}", f"{std:.9g}"
    rounds = hw.Rounds(n)
    value = (lambda c: to_volts(c)) if args.units == "V" else (lambda c: c)
    stopped_by = "duration"
    # Raised while sampling, after any simulation (only this thread, not JAX's), and put
    # back after it.
    raised = contextlib.nullcontext("virtual clock") if args.fast else hw.raised_priority(
        args.priority)  # fmt: skip
    rec = hw.Recorder(args.out, columns=names, rate_hz=args.rate, units=args.units,
                      own_times=n > 1, metadata=meta, **({"clock": timing["clock"]} if timing
                                                        else {}))  # fmt: skip
    priority = None
    try:
        with raised as priority:
            for s in sampler.samples(duration_s=args.duration, gaps=True):
                if policy.stop_requested():
                    stopped_by = "signal"
                    break
                if isinstance(s, hw.Gap):
                    rec.maybe_sync()  # keep what came before durable while the bus is down
                elif n == 1:
                    rec.write(s.t_s, value(s.code))
                elif (row := rounds.push(s)) is not None:
                    rec.write_round(row[0], [value(c) for c in row[1]])
    except KeyboardInterrupt:  # a second signal
        stopped_by = "signal"
    finally:
        rec.close()
    st = sampler.stats
    span = (st.samples / n) / args.rate if st.samples else 0.0
    out = {
        "out": str(args.out),
        "inputs": names,
        "rows": rec.rows,
        "samples": st.samples,
        "rate_hz": args.rate,
        "data_rate_sps": config.data_rate_sps,
        "mode": mode,
        "gaps": st.gaps,
        "overruns": st.overruns,
        "incomplete_rounds": rounds.incomplete,
        "last_error": st.last_error,
        "priority": priority,
        "stopped_by": stopped_by,
    }
    print(f"record: {rec.rows} rows of {', '.join(names)} at {args.rate:g} Hz "
          f"({config.data_rate_sps} SPS {mode}, about {span:.1f} s), gaps {st.gaps}, overruns "
          f"{st.overruns}" + (f", incomplete rounds {rounds.incomplete}" if n > 1 else "")
          + f"; wrote {args.out}", file=sys.stderr)  # fmt: skip
    return out
