"""``whiskerid demo``: the main job end to end on embedded defaults (no arguments needed)."""

from pathlib import Path

from ._common import FORCE_HELP, HelpFormatter, check_outputs, say, show_progress


def add_parser(sub) -> None:
    """Register ``demo`` on the CLI's subparsers."""
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
            "to --out, the stages' results to stderr, and a summary to stdout (--json: the "
            "whole summary as JSON)."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument("--out", type=Path, default=Path("whiskerid-demo"), help="output folder")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=run)


# Written first into --out: a later demo into the same folder recognises its own output by it
# and replaces it (the README's main command works every time); a folder without it is
# refused unless --force, so the demo never writes over anything else.
MARKER = ".whiskerid-demo"


def run(args) -> dict:
    """Run every stage of the demo; returns its JSON summary (and prints a short one on
    stdout without ``--json``)."""
    out = Path(args.out)
    own = out.is_dir() and (out / MARKER).is_file()
    check_outputs(
        {"--out": out},
        {},
        force=args.force or own,
        folders=("--out",),
        exists_hint=f"pass --force to write into it (a folder the demo wrote has {MARKER} in it)",
    )
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).write_text(
        "This folder was written by `whiskerid demo`; a later demo into it replaces its files.\n"
    )
    from ._demo_stages import run_demo, summary_lines

    quiet = not show_progress(args)
    summary = run_demo(args.out, plots=not args.no_plots, say=(lambda *a: None) if quiet else say)
    if not args.json:
        print("\n".join(summary_lines(summary, args.out)), flush=True)
    return summary
