"""``whiskerid analyze``: the dominant line, the perturbation frequency and a test for
symmetric sidebands per terrain and speed: the paper's claim tested."""

import json
from pathlib import Path

from ._common import FORCE_HELP, HelpFormatter, check_outputs, say


def add_parser(sub) -> None:
    """Register ``analyze`` on the CLI's subparsers."""
    a = sub.add_parser(
        "analyze",
        help="test the paper's claim on a dataset: dominant line, perturbation, sidebands",
        description=(
            "The paper's claim tested on DATASET (ROOT/<label>/<recording>.csv, with "
            "speed_mps metadata): per terrain and speed, the dominant line of the recordings' "
            "mean spectrum (Welch, Hann segments) and its spread; the perturbation frequency "
            "f_b (from perturbation_hz metadata, --perturbation-hz, or --per-rev with the "
            "speed and --wheel-diameter) and whether the dominant line is at it; and a "
            "test for sidebands at f_b +- D (around the dominant line when f_b is unknown): "
            "a significant carrier line, then lines at both f_b - D and f_b + D (multitaper "
            "F-tests, frequency-continuous: random modulation and a resonance's skirts are "
            "no lines), D chosen on the recordings' first halves and the weaker side tested "
            "on their second halves (Fisher-combined p-value; the JSON gives the test's "
            "name, the carrier's p-value and the power at the recordings' length). Then the "
            "verdict per group and overall: distinct dominant frequencies per terrain and "
            "per speed (means more than twice the combined spread apart), dominant line at "
            "f_b, sidebands present; the claim holds when each is true of 90 % of them."
        ),
        formatter_class=HelpFormatter,
    )
    a.add_argument("dataset", type=Path,
                   help="dataset folder: one subfolder of recordings per label")  # fmt: skip
    a.add_argument("--channel", help="column to analyse (the first signal column by default)")
    a.add_argument("--time-col", default="t", help="name of the recordings' time column")
    a.add_argument("--segment", type=float, default=4.0, metavar="S",
                   help="Welch segment length (s): the frequency resolution is 1/S")  # fmt: skip
    a.add_argument("--rate", type=float,
                   help="resample to this rate (Hz); the first recording's by default")  # fmt: skip
    a.add_argument("--components", type=int, default=3,
                   help="peaks reported per terrain and speed, the dominant one first")  # fmt: skip
    a.add_argument("--perturbation-hz", type=float, metavar="F",
                   help="the perturbation frequency (Hz) of recordings without "
                   "perturbation_hz metadata")  # fmt: skip
    a.add_argument("--per-rev", type=float, metavar="N",
                   help="perturbations per wheel revolution: f_b = N v/(pi D) from each "
                   "group's speed (e.g. a gear ratio for the motor shaft's tone)")  # fmt: skip
    a.add_argument("--wheel-diameter", type=float, default=0.070, metavar="M",
                   help="wheel diameter D (m) for --per-rev")  # fmt: skip
    a.add_argument("--alpha", type=float, default=0.01,
                   help="significance level of the sideband test")  # fmt: skip
    a.add_argument("--out", type=Path, metavar="JSON", help="write the table as this JSON file")
    a.add_argument("--plot", type=Path, metavar="PNG",
                   help="save a panel per terrain (frequency by speed: dominant line, f_b, "
                   "sidebands) as this PNG")  # fmt: skip
    a.add_argument("--force", action="store_true", help=FORCE_HELP)
    a.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    a.set_defaults(func=run)


def run(args) -> dict:
    """Analyse the dataset; returns the table and the verdict."""
    from ..classify import analyze_dataset
    from ..io import atomic_write
    from ._common import CommandError

    check_outputs({"--out": args.out, "--plot": args.plot}, {"DATASET": args.dataset},
                  force=args.force)  # fmt: skip
    import math

    if not (math.isfinite(args.segment) and 0.05 <= args.segment <= 600) or args.components < 1:
        raise CommandError(
            f"--segment {args.segment:g} s, --components {args.components}: give a segment "
            "from 0.05 to 600 s and at least 1 component"
        )
    if args.rate is not None and not (math.isfinite(args.rate) and 1 <= args.rate <= 10_000):
        raise CommandError(f"--rate {args.rate:g}: give a rate from 1 to 10000 Hz")
    # Plausible ranges: a perturbation a whisker can record, a wheel a robot can have.
    for name, value, lo, hi in (("--perturbation-hz", args.perturbation_hz, 1e-3, 1e4),
                                ("--per-rev", args.per_rev, 1e-3, 1e4),
                                ("--wheel-diameter", args.wheel_diameter, 1e-3, 10.0)):  # fmt: skip
        if value is not None and not (math.isfinite(value) and lo <= value <= hi):
            raise CommandError(f"{name} {value:g}: give a number from {lo:g} to {hi:g}")
    if args.channel is not None:
        _check_channel(args.dataset, args.channel, args.time_col)
    if not 0 < args.alpha < 0.5:
        raise CommandError(f"--alpha {args.alpha:g}: give a significance level in (0, 0.5)")
    res = analyze_dataset(args.dataset, channel=args.channel, segment_s=args.segment,
                          rate_hz=args.rate, n_components=args.components,
                          time_col=args.time_col, perturbation_hz=args.perturbation_hz,
                          per_rev=args.per_rev, wheel_diameter_m=args.wheel_diameter,
                          alpha=args.alpha)  # fmt: skip
    for label, speeds in res["groups"].items():
        for speed, g in speeds.items():
            say(f"{label:>11} v={speed:>5}: {g['verdict']}")
    say(res["claim"]["verdict"])
    if args.out is not None:
        atomic_write(args.out, json.dumps(res, indent=1) + "\n")
        say(f"wrote {args.out}")
    if args.plot is not None:
        from ..plot import plot_sidebands

        plot_sidebands(args.plot, res)
        say(f"wrote {args.plot}")
    return res


def _check_channel(dataset: Path, channel: str, time_col: str) -> None:
    """``--channel`` names a signal column of the dataset's first CSV recording (NPY files
    have one column, whatever its name)."""
    from ..io import RecordingError, read_recording
    from ._common import CommandError

    first = next(iter(sorted(Path(dataset).glob("*/*.csv"))), None)
    if first is None:
        return
    try:
        rec = read_recording(first)
    except (RecordingError, OSError, ValueError):
        return  # the analysis names the file and what is wrong with it
    columns = [c for c in rec.columns if c != time_col]
    if channel not in columns:
        raise CommandError(
            f"--channel {channel!r}: {first} has no such column; its signal columns are "
            f"{', '.join(columns) or 'none'}"
        )
