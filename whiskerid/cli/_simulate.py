"""``whiskerid simulate``: a whisker recording (CSV) from a model and an excitation."""

import math
import sys
from pathlib import Path

from .._choices import EXCITATIONS, MODELS, OBSERVABLES, UNITS
from ._common import FORCE_HELP, CommandError, HelpFormatter, check_outputs, record_or_paper, say

# The largest base acceleration --base may hold (m/s^2, about 1000 g).
MAX_BASE_ACC_M_S2 = 1e4


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
        "--cubic",
        type=float,
        metavar="GAMMA",
        help="a nonlinear whisker: mode 1's cubic (Duffing) stiffness gamma (1/m^2, at the "
        "tip), so that f(a) = f0 (1 + 3 gamma a^2 / 8); with --excitation decay (e.g. 2e4: "
        "f1 about 0.75 %% higher at a 1 mm tip amplitude than at rest)",
    )
    p.add_argument(
        "--velocity-squared",
        type=float,
        metavar="C",
        help="a nonlinear whisker: mode 1's velocity-squared loss c (1/m), so that the "
        "damping ratio grows with the amplitude; with --excitation decay",
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
    record = _with_backbone(args, record_or_paper(args.whisker))
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


def _with_backbone(args, record):
    """The record with the nonlinear terms of ``--cubic`` / ``--velocity-squared`` (a
    ``[fit.nonlinear]`` table, as a nonlinear calibration writes, which the pluck plays)."""
    terms = {"--cubic": args.cubic, "--velocity-squared": args.velocity_squared}
    given = {flag: v for flag, v in terms.items() if v is not None}
    if not given:
        return record
    for flag, v in given.items():
        if not math.isfinite(v) or v < 0 or v > 1e9:
            raise CommandError(f"{flag} {v:g}: give a finite coefficient from 0 to 1e9")
    if args.excitation != "decay" or args.channels != 1 or args.model != "exact":
        raise CommandError(
            f"{' and '.join(given)} make a nonlinear pluck: give --excitation decay (one "
            "sensor, --model exact)"
        )
    fit = dict(record.extra.get("fit") or {})
    nl = dict(fit.get("nonlinear") or {})
    nl["gamma_per_m2"] = float(args.cubic or 0.0)
    nl["coulomb_m_s2"] = float(nl.get("coulomb_m_s2", 0.0))
    nl["quadratic_per_m"] = float(args.velocity_squared or 0.0)
    fit["nonlinear"] = nl
    return record.replace(extra={**record.extra, "fit": fit})


def _clipping(args, sim) -> dict | None:
    """Samples of an ``adc`` recording on the converter's rails: a warning on stderr (and
    in the JSON) when more than 1 % are, with how much smaller the excitation should be."""
    import numpy as np

    from ..io import CODE_MAX, CODE_MIN

    if args.observable != "adc":
        return None
    worst = None
    for name, x in sim.columns.items():
        x = np.asarray(x)
        for rail, n in ((CODE_MAX, np.sum(x >= CODE_MAX)), (CODE_MIN, np.sum(x <= CODE_MIN))):
            frac = float(n) / max(x.size, 1)
            if frac > 0.01 and (worst is None or frac > worst["fraction"]):
                # A sine of amplitude A about mid spends arccos(R/A)/pi of its time beyond a
                # rail R away: A = R / cos(pi frac) (a guide for other signals too).
                c = math.cos(math.pi * min(frac, 0.49))
                worst = {"column": name, "fraction": frac, "rail": int(rail), "scale": 0.9 * c}
    if worst is None:
        return None
    what = "--hb" if args.excitation == "sine" else (
        "--tip-deflection" if args.excitation == "decay" else "the base motion")  # fmt: skip
    worst["message"] = (
        f"warning: {100 * worst['fraction']:.3g} % of the samples of {worst['column']} sit on "
        f"the ADS1115's rail ({worst['rail']}): the signal is clipped; scale {what} by about "
        f"{worst['scale']:.2g} or less (it is in metres: 2e-4 is 0.2 mm)"
    )
    return worst


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
    clipped = _clipping(args, sim)
    if clipped:
        print(clipped["message"], file=sys.stderr, flush=True)
    columns = f", columns {', '.join(sim.columns)}" if per_channel else ""
    say(f"wrote {args.out} ({sim.t.size} samples of {args.observable}{columns})")
    units = UNITS[args.observable]
    summary = {"out": str(args.out), "samples": int(sim.t.size),
               "observable": args.observable, "units": units}  # fmt: skip
    if per_channel:
        summary["channels"] = list(sim.columns)
    if clipped:
        summary["clipped"] = clipped

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
    import numpy as np

    from ..io import check_samples, read_recording, recording_rate
    from ..model import BaseMotion

    rec = read_recording(path)
    acc = rec.signal(column)
    check_samples(rec.t, acc, where=str(path))
    # A finite but absurd sample (a corrupt 1e300) would integrate into a base displacement of
    # 1e293 m and be written as if measured; ~1000 g covers any shaker, vehicle or impact.
    big = np.flatnonzero(np.abs(acc) > MAX_BASE_ACC_M_S2)
    if big.size:
        name = column or "the first signal column"
        raise CommandError(
            f"--base {path}: column {name}, sample {big[0]} (t = {float(rec.t[big[0]])!r} s) "
            f"is {float(acc[big[0]])!r} m/s^2; a plausible base acceleration is within "
            f"±{MAX_BASE_ACC_M_S2:g} m/s^2 (about 1000 g)"
        )
    recording_rate(rec)  # rate_hz metadata, if any, must agree with the timestamps
    return BaseMotion(t=rec.t, acc=acc)


def _peaks(t, x, n: int = 3) -> list[float]:
    from ..fit import dominant_peaks

    return [round(p.frequency_hz, 3) for p in dominant_peaks(t, x, n=n)]
