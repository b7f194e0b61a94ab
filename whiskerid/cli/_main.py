"""The ``whiskerid`` command line (NOTES §7).

Every command has ``--help``; ``--json`` prints one JSON object on stdout while human text
goes to stderr; the exit status is 0 on success and 2 with a one-line reason on bad input.
"""

import argparse
import json
import math
import sys
import time
import zipfile
from pathlib import Path

import numpy as np

from .._version import __version__
from ..io._recording import RecordingError, check_out_path, read_recording, write_csv
from ..model._record import RecordError, load_record, paper_record
from ..model._simulate import EXCITATIONS, MODELS, SIM_OBSERVABLES, UNITS, BaseMotion, simulate

# Reported on one line with exit status 2. The readers turn corrupt archives into
# RecordingErrors with the path; BadZipFile, EOFError and MemoryError are a safety net.
_EXPECTED = (
    ValueError,
    RecordError,
    RecordingError,
    OSError,
    RuntimeError,
    zipfile.BadZipFile,
    EOFError,
    MemoryError,
)


class CommandError(Exception):
    """Bad input detected by a command (reported on one line, exit status 2)."""


def _enable_x64() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)


def _say(*parts) -> None:
    print(*parts, file=sys.stderr)


# --------------------------------------------------------------------------- simulate
def _add_simulate(sub) -> None:
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
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
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
        help="column of --base holding the acceleration (the first signal column by default)",
    )
    p.add_argument("--rate", type=float, default=200.0, help="sampling rate (Hz)")
    p.add_argument("--duration", type=float, default=10.0, help="length (s)")
    p.add_argument(
        "--observable",
        choices=SIM_OBSERVABLES,
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
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=_cmd_simulate)


def _record_or_paper(path: Path | None):
    return paper_record() if path is None else load_record(path)


def _cmd_simulate(args) -> dict:
    inputs = {"--whisker": args.whisker, "--base": args.base}
    check_out_path(args.out, "--out", inputs=inputs)
    if args.plot is not None:
        check_out_path(args.plot, "--plot", inputs={**inputs, "--out": args.out})
    record = _record_or_paper(args.whisker)
    base = None
    if args.excitation == "base":
        if args.base is None:
            raise CommandError("--excitation base needs --base FILE (time and base acceleration)")
        rec = read_recording(args.base)
        from ..classify import recording_rate
        from ..io._recording import check_samples

        acc = rec.signal(args.base_col)
        check_samples(rec.t, acc, where=str(args.base))
        recording_rate(rec)  # rate_hz metadata, if any, must agree with the timestamps
        base = BaseMotion(t=rec.t, acc=acc)
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
    write_csv(args.out, sim)
    _say(f"wrote {args.out} ({sim.t.size} samples of {args.observable})")
    x = sim.signal()
    summary = {
        "out": str(args.out),
        "samples": int(sim.t.size),
        "observable": args.observable,
        "units": UNITS[args.observable],
        "min": float(np.min(x)),
        "max": float(np.max(x)),
        "dominant_peaks_hz": _peaks(sim.t, x),
    }
    if args.plot:
        from ..plot._plot import plot_signal_and_spectrum

        plot_signal_and_spectrum(
            args.plot,
            sim.t,
            x,
            label=f"{args.observable} ({UNITS[args.observable]})",
            title=f"{record.name}: {args.model} model, {args.excitation} excitation",
        )
        summary["plot"] = str(args.plot)
        _say(f"wrote {args.plot}")
    return summary


def _peaks(t, x, n: int = 3) -> list[float]:
    from ..fit._signal import dominant_peaks

    return [round(p.frequency_hz, 3) for p in dominant_peaks(t, x, n=n)]


# --------------------------------------------------------------------------- demo
def _add_demo(sub) -> None:
    p = sub.add_parser(
        "demo",
        help="run the main job end to end on embedded defaults (no arguments needed)",
        description=(
            "Run whiskerid on the paper's whisker with embedded defaults: print its "
            "equivalent-beam values and natural frequencies, reproduce the paper's modal "
            "analysis (Eq. 1 and the exact modal model at h_b = 0.1/0.3 mm, f_b = 100/300 Hz) "
            "with dominant spectral peaks, and simulate what the Pi would record (ADS1115 at "
            "200 Hz) for a sine excitation and a pluck; calibrate that pluck, sample its "
            "damping posterior with emcee, train and test a terrain classifier, and run the "
            "Pi's online loop on an emulated ADS1115. Writes CSVs, TOML records and PNG plots "
            "to --out."
        ),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--out", type=Path, default=Path("whiskerid-demo"), help="output folder")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=_cmd_demo)


def _cmd_demo(args) -> dict:
    from ._demo import run_demo

    return run_demo(args.out, plots=not args.no_plots, say=_say)


# --------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``whiskerid`` command."""
    parser = argparse.ArgumentParser(
        prog="whiskerid",
        description=(
            "Differentiable system identification for compliant whisker sensors: beam "
            "models in JAX (the paper's Eq. 1 and the exact modal model), Hall sensor and "
            "ADS1115 models, simulation, calibration, damping posteriors, terrain "
            "classification and online streaming on a Raspberry Pi. Start with "
            "'whiskerid demo'."
        ),
    )
    parser.add_argument("--version", action="version", version=f"whiskerid {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_demo(sub)
    _add_simulate(sub)
    from ._calibrate import add_calibrate

    add_calibrate(sub, CommandError)
    from ._posterior import add_posterior

    add_posterior(sub, CommandError)
    from ._classify import add_classify_commands

    add_classify_commands(sub, CommandError)
    from ._stream import add_stream

    add_stream(sub, CommandError)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``whiskerid`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    _enable_x64()
    start = time.perf_counter()
    try:
        result = args.func(args)
    except (CommandError, *_EXPECTED) as err:
        print(f"whiskerid {args.command}: error: {_one_line(err)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"whiskerid {args.command}: interrupted", file=sys.stderr)
        return 130
    if getattr(args, "json", False):
        result = {
            "command": args.command,
            **result,
            "elapsed_s": round(time.perf_counter() - start, 3),
        }
        print(json.dumps(json_safe(result), indent=2, allow_nan=False))
    return 0


def json_safe(value):
    """``value`` with every non-finite float (NaN, ±inf, NumPy's too) replaced by None.

    Standard JSON has no NaN or Infinity; ``null`` is what other tools can read.
    """
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split()) or type(err).__name__


if __name__ == "__main__":
    sys.exit(main())
