"""``whiskerid analyze``: dominant frequency components per terrain and speed."""

import json
from pathlib import Path

from ._common import FORCE_HELP, HelpFormatter, check_outputs, say


def add_parser(sub) -> None:
    """Register ``analyze`` on the CLI's subparsers."""
    a = sub.add_parser(
        "analyze",
        help="dominant frequency components per terrain and speed of a dataset",
        description=(
            "The paper's analysis of DATASET (ROOT/<label>/<recording>.csv, with speed_mps "
            "metadata): per terrain and speed, the largest peaks of the recordings' mean "
            "spectrum (Welch, Hann segments) and the spread of each recording's dominant "
            "frequency; then the paper's claim checked: are the dominant components distinct "
            "per terrain (at one speed) and per speed (on one terrain), and is the dominant "
            "one sandwiched by two less dominant ones? Two groups count as distinct when their "
            "dominant frequencies differ by more than twice the combined spread."
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
    a.add_argument("--out", type=Path, metavar="JSON", help="write the table as this JSON file")
    a.add_argument("--plot", type=Path, metavar="PNG",
                   help="save a panel per terrain (frequency by speed) as this PNG")  # fmt: skip
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
    if not args.segment > 0 or args.components < 1:
        raise CommandError("--segment must be positive and --components at least 1")
    res = analyze_dataset(args.dataset, channel=args.channel, segment_s=args.segment,
                          rate_hz=args.rate, n_components=args.components,
                          time_col=args.time_col)  # fmt: skip
    for label, speeds in res["groups"].items():
        for speed, g in speeds.items():
            comps = ", ".join(f"{f:.2f}" for f, _ in g["components"])
            say(f"{label:>11} v={speed:>5}: dominant {g['dominant_hz']:7.2f} ± "
                f"{g['dominant_spread_hz']:.2f} Hz; components {comps} Hz")  # fmt: skip
    say(res["claim"]["verdict"])
    if args.out is not None:
        atomic_write(args.out, json.dumps(res, indent=1) + "\n")
        say(f"wrote {args.out}")
    if args.plot is not None:
        from ..plot import plot_dominant_frequencies

        plot_dominant_frequencies(args.plot, res)
        say(f"wrote {args.plot}")
    return res
