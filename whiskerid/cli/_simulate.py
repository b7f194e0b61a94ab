"""``whiskerid simulate``: a whisker recording (CSV) from a model and an excitation."""

from pathlib import Path

from .._choices import EXCITATIONS, MODELS, OBSERVABLES, UNITS
from ._common import FORCE_HELP, CommandError, HelpFormatter, check_outputs, record_or_paper, say


def add_parser(sub) -> None:
    """Register ``simulate`` on the CLI's subparsers."""
    p = sub.add_parser(
        "simulate",
        help="simulate a whisker recording (CSV) from a model and an excitation",
        description=(
            "Simulate what a whisker records. Models: 'paper' is Eq. 1 as printed (sine only), "
            "'steady' the exact modal model's harmonic steady state (sine only), 'exact' the "
            "exact modal model from rest (sine switched on at t=0, a pluck's free decay, or "
            "any base motion). Observables: deflection (relative to the base, m), "
            "acceleration (absolute, m/s^2), voltage (Hall output, V), adc (ADS1115 codes, "
            "with conversion averaging, oscillator error, clipping, quantisation). The CSV "
            "has columns t and the observable's name."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument("--whisker", type=Path, help="whisker record (TOML); the paper's by default")
    p.add_argument(
        "--model",
        choices=MODELS,
        default="exact",
        help="paper: Eq. 1 as printed; steady: harmonic steady state; exact: from rest",
    )
    p.add_argument(
        "--excitation",
        choices=EXCITATIONS,
        default="sine",
        help="sine: h_b sin(2 pi f_b t); decay: free decay after a pluck; "
        "base: a measured base motion (--base)",
    )
    p.add_argument("--fb", type=float, default=100.0, help="base excitation frequency (Hz)")
    p.add_argument("--hb", type=float, default=1e-4, help="base excitation amplitude (m)")
    p.add_argument(
        "--tip-deflection",
        type=float,
        default=1e-3,
        help="initial tip deflection of a pluck, for --excitation decay (m)",
    )
    p.add_argument(
        "--base",
        type=Path,
        help="base motion for --excitation base: a recording (CSV/NPZ/NPY) with "
        "time and base acceleration (m/s^2)",
    )
    p.add_argument(
        "--base-col",
        help="column of --base holding the acceleration (the first signal column by "
        "default); with --channels 2, two columns 'VERTICAL,LATERAL' give each plane its own",
    )
    p.add_argument(
        "--channels",
        type=int,
        choices=(1, 2),
        default=1,
        help="Hall sensors: 1 (one column, the observable's name) or 2 (the two orthogonal "
        "sensors, columns hall_a for the vertical plane and hall_b for the lateral one; "
        "--model exact, --observable voltage or adc; the lateral plane and sensor B from "
        "the record's [planes] table)",
    )
    p.add_argument(
        "--angle",
        type=float,
        default=45.0,
        help="with --channels 2: direction of the pluck, the sine or a one-column --base "
        "from the vertical plane (degrees; 0 vertical only, 90 lateral only)",
    )
    p.add_argument("--rate", type=float, default=200.0, help="sampling rate (Hz)")
    p.add_argument("--duration", type=float, default=10.0, help="length (s)")
    p.add_argument(
        "--observable",
        choices=OBSERVABLES,
        default="deflection",
        help="what the recording holds (see above)",
    )
    p.add_argument("--noise-db", type=float, help="add white noise at this SNR (dB)")
    p.add_argument(
        "--jitter",
        type=float,
        help="timestamp jitter (s); the record's ADC value for voltage/adc, else 0",
    )
    p.add_argument("--seed", type=int, default=0, help="seed for noise and jitter")
    p.add_argument("--out", type=Path, required=True, help="CSV file to write")
    p.add_argument("--plot", type=Path, help="also save signal and spectrum as this PNG")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=run)


def run(args) -> dict:
    """Simulate, write the CSV (and the plot); returns the JSON summary."""

    from ..model import simulate

    check_outputs({"--out": args.out, "--plot": args.plot},
                  {"--whisker": args.whisker, "--base": args.base}, force=args.force)  # fmt: skip
    record = record_or_paper(args.whisker)
    if args.channels == 2:
        return _run_planes(args, record)
    base = None
    if _base_given(args):
        base = _read_base_motion(args.base, args.base_col)
    sim = simulate(
        record,
        model=args.model,
        excitation=args.excitation,
        observable=args.observable,
        fb_hz=args.fb,
        hb_m=args.hb,
        tip_deflection_m=args.tip_deflection,
        base=base,
        rate_hz=args.rate,
        duration_s=args.duration,
        noise_db=args.noise_db,
        jitter_s=args.jitter,
        seed=args.seed,
    )
    return _written(args, sim, f"{record.name}: {args.model} model, {args.excitation} excitation")


def _run_planes(args, record) -> dict:
    """``--channels 2``: both Hall sensors (see :func:`whiskerid.terrain.simulate_planes`)."""

    from ..terrain import PLANE_OBSERVABLES, simulate_planes

    if args.model != "exact":
        raise CommandError(
            f"--channels 2 simulates the exact modal model: drop --model {args.model}"
        )
    if args.observable not in PLANE_OBSERVABLES:
        raise CommandError(
            f"--channels 2 records the two Hall sensors: give --observable "
            f"{' or '.join(PLANE_OBSERVABLES)}, not {args.observable}"
        )
    base = lateral = None
    if _base_given(args):
        cols = (args.base_col or "").split(",") if args.base_col else [None]
        if len(cols) > 2:
            raise CommandError(
                f"--base-col {args.base_col!r}: give one column or two (VERTICAL,LATERAL)"
            )
        base = _read_base_motion(args.base, cols[0])
        lateral = _read_base_motion(args.base, cols[1]) if len(cols) == 2 else None
    try:
        sim = simulate_planes(
            record,
            excitation=args.excitation,
            observable=args.observable,
            angle_deg=args.angle,
            tip_deflection_m=args.tip_deflection,
            fb_hz=args.fb,
            hb_m=args.hb,
            base=base,
            lateral_base=lateral,
            rate_hz=args.rate,
            duration_s=args.duration,
            noise_db=args.noise_db,
            jitter_s=args.jitter,
            seed=args.seed,
        )
    except ValueError as err:
        raise CommandError(str(err)) from None
    return _written(args, sim, f"{record.name}: two sensors, {args.excitation}", per_channel=True)


def _base_given(args) -> bool:
    """Whether the base motion is read from --base (refused when it is missing)."""
    if args.excitation == "base" and args.base is None:
        raise CommandError("--excitation base needs --base FILE (time and base acceleration)")
    return args.excitation == "base"


def _written(args, sim, title: str, *, per_channel: bool = False) -> dict:
    """Write the recording (and the plot of its first signal); the JSON summary, with a
    value per column when ``per_channel``."""
    import numpy as np

    from ..io import write_csv

    write_csv(args.out, sim)
    columns = f", columns {', '.join(sim.columns)}" if per_channel else ""
    say(f"wrote {args.out} ({sim.t.size} samples of {args.observable}{columns})")
    units = UNITS[args.observable]
    summary = {"out": str(args.out), "samples": int(sim.t.size),
               "observable": args.observable, "units": units}  # fmt: skip
    if per_channel:
        summary["channels"] = list(sim.columns)

    def each(f):
        return {c: f(x) for c, x in sim.columns.items()} if per_channel else f(sim.signal())

    summary["min"] = each(lambda x: float(np.min(x)))
    summary["max"] = each(lambda x: float(np.max(x)))
    summary["dominant_peaks_hz"] = each(lambda x: _peaks(sim.t, x))
    if args.plot:
        from ..plot import plot_signal_and_spectrum

        col = next(iter(sim.columns)) if per_channel else None
        x = sim.columns[col] if per_channel else sim.signal()
        plot_signal_and_spectrum(args.plot, sim.t, x, label=f"{col or args.observable} ({units})",
                                 title=title)  # fmt: skip
        summary["plot"] = str(args.plot)
        say(f"wrote {args.plot}" + (f" (sensor {col})" if per_channel else ""))
    return summary


def _read_base_motion(path: Path, column: str | None):
    from ..io import check_samples, read_recording, recording_rate
    from ..model import BaseMotion

    rec = read_recording(path)
    acc = rec.signal(column)
    check_samples(rec.t, acc, where=str(path))
    recording_rate(rec)  # rate_hz metadata, if any, must agree with the timestamps
    return BaseMotion(t=rec.t, acc=acc)


def _peaks(t, x, n: int = 3) -> list[float]:
    from ..fit import dominant_peaks

    return [round(p.frequency_hz, 3) for p in dominant_peaks(t, x, n=n)]
