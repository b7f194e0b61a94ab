"""``whiskerid classify``: label the terrain of a recording, per window and overall."""

from pathlib import Path

from ._common import (
    CONTEXT_HELP,
    FORCE_HELP,
    CommandError,
    HelpFormatter,
    check_outputs,
    load_model,
    model_folder,
    say,
)


def add_parser(sub) -> None:
    """Register ``classify`` on the CLI's subparsers."""
    c = sub.add_parser(
        "classify",
        help="label the terrain of a recording, per window and overall",
        description="Classify every window of REC and the whole recording (mean probability).",
        formatter_class=HelpFormatter,
    )
    c.add_argument("model", type=Path, help="model folder (whiskerid train)")
    c.add_argument("recording", type=Path, help="recording to label (CSV/NPZ/NPY)")
    c.add_argument("--speed", type=float, help="robot speed (m/s); from the metadata by default")
    c.add_argument("--plot", type=Path, metavar="PNG",
                   help="save the signal and its labels over time as this PNG")  # fmt: skip
    c.add_argument("--context", type=float, metavar="S",
                   help=CONTEXT_HELP + "; the model's by default")  # fmt: skip
    c.add_argument("--force", action="store_true", help=FORCE_HELP)
    c.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    c.set_defaults(func=run)


def run(args) -> dict:
    """Label the recording (and plot its labels); returns the JSON summary."""
    from ..io import read_recording

    _check_order(args.model, args.recording)
    check_outputs({"--plot": args.plot},
                  {"MODEL": model_folder(args.model), "REC": args.recording},
                  force=args.force)  # fmt: skip
    model = load_model(args.model, args.context)
    rec = read_recording(args.recording)
    res = model.classify_recording(rec, speed=args.speed)
    if model.channel is not None and res["channel"] != model.channel:
        say(f"note: the model was trained on column {model.channel!r}; this recording's "
            f"only signal column is {res['channel']!r}, classified instead")  # fmt: skip
    say(f"{args.recording}: {res['label']} (confidence {res['confidence']:.3f}, "
        f"{len(res['windows'])} windows)")  # fmt: skip
    out = {"recording": str(args.recording), **res}
    if args.plot is not None:
        from ..plot import plot_recording_labels

        x = rec.columns[res["channel"]]  # checked by classify_recording
        title = f"{args.recording.name}: {res['label']} (mean probability {res['confidence']:.2f})"
        plot_recording_labels(args.plot, rec.t, x, res, model.labels, window_s=model.window_s,
                              title=title)  # fmt: skip
        out["plot"] = str(args.plot)
        say(f"wrote {args.plot}")
    return out


def _check_order(model: Path, recording: Path) -> None:
    """Refuse a recording given as MODEL (the arguments swapped, most often), in words."""
    if model.is_file() and (recording.is_dir() or model.suffix.lower() == ".csv"):
        raise CommandError(
            f"MODEL {model} is a file that looks like a recording, and a model is the folder "
            f"'whiskerid train' wrote (REC is {recording}): the order is "
            "'whiskerid classify MODEL REC'"
        )
