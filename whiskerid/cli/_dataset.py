"""``whiskerid dataset synth``: labelled recordings of simulated terrains."""

import math
from pathlib import Path

from .._choices import SPEEDS_MPS, TERRAINS
from ._common import (
    FORCE_HELP,
    QUIET_HELP,
    WATCH,
    CommandError,
    HelpFormatter,
    check_outputs,
    record_or_paper,
    say,
    show_progress,
)


def add_parser(sub) -> None:
    """Register ``dataset`` (with its action ``synth``) on the CLI's subparsers."""
    p = sub.add_parser("dataset", help="make labelled datasets (synthetic terrains)",
                       formatter_class=HelpFormatter)  # fmt: skip
    dsub = p.add_subparsers(dest="dataset_command", required=True, metavar="ACTION")
    s = dsub.add_parser(
        "synth",
        help="synthesise whisker recordings of the paper's 7 terrains at several speeds",
        description=(
            "Simulate a wheeled robot (70 mm wheels) on random terrain profiles (ISO 8608 "
            "roughness, joints, pile, ripples, bumps; ground compliance), the whisker's exact "
            "modal response to the body motion, the Hall sensor and the ADS1115 at 200 Hz. "
            "Writes OUT/<terrain>/<terrain>_v<speed>_r<run>.csv with metadata (terrain, "
            "speed_mps, rate_hz, whisker). Deterministic for a seed."
        ),
        formatter_class=HelpFormatter,
    )
    s.add_argument("--out", type=Path, required=True, help="dataset folder to write")
    s.add_argument("--whisker", type=Path, help="whisker record (TOML); the paper's by default")
    s.add_argument("--terrains", nargs="+", default=list(TERRAINS), metavar="T",
                   help=f"terrains among {', '.join(TERRAINS)}")  # fmt: skip
    s.add_argument("--speeds", nargs="+", type=float, default=list(SPEEDS_MPS), metavar="V",
                   help="nominal robot speeds (m/s)")  # fmt: skip
    s.add_argument("--runs", type=int, default=4, help="recordings per terrain and speed")
    s.add_argument("--duration", type=float, default=30.0, help="length of each recording (s)")
    s.add_argument(
        "--seed",
        type=int,
        default=0,
        help="dataset seed: with terrain, speed and run number, it fixes each recording",
    )
    s.add_argument("--force", action="store_true",
                   help=FORCE_HELP + "; only recordings this simulator wrote are replaced, a "
                   "folder holding other recordings is refused")  # fmt: skip
    s.add_argument("--channels", type=int, choices=(1, 2), default=1,
                   help="Hall sensors: 1 (column adc, the vertical bending plane) or 2 "
                   "(hall_a vertical, hall_b lateral: the paper's two orthogonal sensors; "
                   "the record's [planes] table sets the lateral plane, gains, offsets and "
                   "cross-talk)")  # fmt: skip
    s.add_argument("--contact", action="store_true",
                   help="put the whisker's tip on the ground: unilateral Hunt-Crossley contact "
                   "and smoothed Coulomb friction per terrain, integrated with diffrax (one "
                   "Hall sensor; about half a second of computing per simulated second and "
                   "run on a CPU); each recording's metadata gains contact, perturbation_hz, "
                   "contact_fraction and stick_fraction")  # fmt: skip
    s.add_argument("--preload", type=float, default=1.0, metavar="MM",
                   help="with --contact: how far the undeformed tip would sink into the mean "
                   "ground (mm): sets the static contact force")  # fmt: skip
    s.add_argument("--resume", action="store_true",
                   help="finish a synth that was stopped (Ctrl-C, SIGTERM): keep the "
                   "recordings it finished into --out with the same settings and simulate "
                   "the rest")  # fmt: skip
    s.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    s.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    s.set_defaults(func=run)


def run(args) -> dict:
    """Synthesise the recordings; returns the JSON summary."""
    from ..terrain import synthesize_dataset

    # A folder holding recordings is refused by the simulator itself (with --force, it
    # replaces only its own recordings), so here: no output inside an input, a writable place.
    check_outputs({"--out": args.out}, {"--whisker": args.whisker}, force=True,
                  folders=("--out",))  # fmt: skip
    if not 1 <= args.runs <= 10_000:
        raise CommandError(f"--runs {args.runs}: give a whole number from 1 to 10000")
    # An hour per recording at most: 1e9 s would need terabytes before the first is written.
    if not (math.isfinite(args.duration) and 0 < args.duration <= 3600):
        raise CommandError(f"--duration {args.duration:g} s: give a length from 2 to 3600 s")
    if args.contact and args.channels != 1:
        raise CommandError("--contact simulates one Hall sensor: drop --channels 2")
    if not 0 < args.preload < 20:
        raise CommandError(f"--preload {args.preload:g} mm: give a depth between 0 and 20 mm")
    record = record_or_paper(args.whisker)

    def kept() -> str | None:  # said in the one line of an interrupt
        n = len(list(args.out.glob("*/*.csv"))) if args.out.is_dir() else 0
        return (f"kept (complete): {n} finished recording(s) in {args.out}; the same command "
                "with --resume simulates the rest") if n else None  # fmt: skip

    WATCH.notes.append(kept)
    paths = synthesize_dataset(args.out, record=record, terrains=tuple(args.terrains),
                               speeds=tuple(args.speeds), runs=args.runs,
                               duration_s=args.duration, seed=args.seed,
                               replace_synthetic=args.force,
                               channels=args.channels, contact=args.contact,
                               preload_m=args.preload * 1e-3,
                               progress=show_progress(args), resume=args.resume)  # fmt: skip
    say(f"wrote {len(paths)} recordings to {args.out}")
    return {"out": str(args.out), "recordings": len(paths), "terrains": args.terrains,
            "speeds_mps": args.speeds, "runs": args.runs, "duration_s": args.duration,
            "channels": args.channels, "contact": args.contact,
            "preload_mm": args.preload if args.contact else None}  # fmt: skip
