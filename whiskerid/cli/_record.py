"""``whiskerid record``: sample ADS1115 inputs to a recording CSV, no model needed."""

import math
import signal
import sys
from pathlib import Path

from ._common import CommandError, HelpFormatter

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
    p.add_argument("--seed", type=int, default=0, help="seed of the emulated signal and noise")
    p.add_argument(
        "--fast", action="store_true", help="with --emulate: a virtual clock, as fast as possible"
    )
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=run)


def run(args) -> dict:
    """Record until --duration, Ctrl-C or SIGTERM; returns the JSON summary."""
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
        return _record(hw, bus, inputs, config, mode, args, timing)
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
        dr = args.data_rate
    elif mode == "continuous":
        dr = 860
    else:
        dr = hw.data_rate_for(slot_s)
    cfg = hw.Config(mux=inputs[0].mux, fsr_v=args.fsr, data_rate_sps=dr,
                    single_shot=mode == "single-shot")  # fmt: skip
    return cfg, mode


def _emulated_bus(hw, inputs, args, timing):
    """Emulated chip(s) answering on the inputs' addresses, each input fed by its source."""
    return hw.emulated_bus(inputs, _sources(inputs, args), seed=args.seed, noise_v=1e-4,
                           **timing)  # fmt: skip


def _sources(inputs, args) -> list:
    """One signal ``source(t_s) -> volts`` per input."""
    from .. import hw

    what = args.emulate
    if Path(what).suffix.lower() in (".csv", ".npz", ".npy"):
        try:
            return hw.replay_sources(what, [i.name for i in inputs], fsr_v=args.fsr)
        except ValueError as e:
            raise CommandError(str(e)) from None
    if what == "pluck":
        return [_pluck(args)] * len(inputs)
    return [_terrain(args, what, j) for j in range(len(inputs))]


def _pluck(args):
    """The Hall voltage of the whisker held bent by hand and released at PLUCK_DELAY_S.

    A pluck has rung down within seconds: longer recordings hold the rest value after it.
    """
    from .. import hw
    from ..model import simulate_pluck
    from ._common import record_or_paper

    length = min(args.duration or PLUCK_SPAN_S, PLUCK_SPAN_S) + 1.0
    sim, _ = simulate_pluck(record_or_paper(args.whisker), kind="held", observable="voltage",
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


def _record(hw, bus, inputs, config, mode, args, timing) -> dict:
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
    rounds = hw.Rounds(n)
    value = (lambda c: to_volts(c)) if args.units == "V" else (lambda c: c)
    previous = signal.getsignal(signal.SIGTERM)
    stopped_by = "duration"

    def _terminate(signum, frame):
        raise KeyboardInterrupt

    rec = hw.Recorder(args.out, columns=names, rate_hz=args.rate, units=args.units,
                      own_times=n > 1, metadata=meta, **({"clock": timing["clock"]} if timing
                                                        else {}))  # fmt: skip
    signal.signal(signal.SIGTERM, _terminate)
    try:
        for s in sampler.samples(duration_s=args.duration, gaps=True):
            if isinstance(s, hw.Gap):
                rec.maybe_sync()  # keep what came before durable while the bus is down
            elif n == 1:
                rec.write(s.t_s, value(s.code))
            elif (row := rounds.push(s)) is not None:
                rec.write_round(row[0], [value(c) for c in row[1]])
    except KeyboardInterrupt:
        stopped_by = "signal"
    finally:
        signal.signal(signal.SIGTERM, previous)
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
        "stopped_by": stopped_by,
    }
    print(f"record: {rec.rows} rows of {', '.join(names)} at {args.rate:g} Hz "
          f"({config.data_rate_sps} SPS {mode}, about {span:.1f} s), gaps {st.gaps}, overruns "
          f"{st.overruns}" + (f", incomplete rounds {rounds.incomplete}" if n > 1 else "")
          + f"; wrote {args.out}", file=sys.stderr)  # fmt: skip
    return out
