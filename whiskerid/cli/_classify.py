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
    c.add_argument("--whisker", type=Path, metavar="TOML", help=WHISKER_HELP)
    c.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    c.set_defaults(func=run)


WHISKER_HELP = (
    "calibrated record (TOML, from 'whiskerid calibrate') of the whisker that made the "
    "recordings, when it is not the one the model was trained with: a model trained with "
    "--whisker divides each whisker's own response out of its windows, so it runs on "
    "another calibrated whisker"
)


def apply_whisker(model, whisker: Path | None, metas: list[dict], model_path: Path) -> None:
    """Point a whisker-aware model at the whisker that made the recordings, or refuse.

    With ``whisker`` (a record), the model recolours windows from it to its training
    whisker. Without, recordings whose metadata names another whisker than the model's are
    refused: the features would be read through the wrong resonance.
    """
    from ..classify import WhiskerResponse, recorded_amplifier
    from ..model import load_record

    if whisker is not None:
        if not model.needs_whisker:
            raise CommandError(
                f"{model_path} was trained without a whisker record (its features are the "
                "raw signal's), so --whisker cannot adapt it: retrain with "
                "'whiskerid train --whisker TOML' to make a model that carries over"
            )
        amplifier = recorded_amplifier(metas, model.whisker.amplifier)
        model.use_whisker(WhiskerResponse(load_record(whisker), amplifier))
        return
    if not model.needs_whisker:
        return
    own = model.whisker.record.name
    other = sorted({str(m["whisker"]) for m in metas if m.get("whisker", own) != own})
    if other:
        raise CommandError(
            f"the recordings were made with whisker {', '.join(map(repr, other))} but "
            f"{model_path} was trained with {own!r}: pass --whisker with that whisker's "
            "calibrated record (whiskerid calibrate writes one)"
        )


def run(args) -> dict:
    """Label the recording (and plot its labels); returns the JSON summary."""
    from ..io import read_recording

    _check_order(args.model, args.recording)
    check_outputs({"--plot": args.plot},
                  {"MODEL": model_folder(args.model), "REC": args.recording},
                  force=args.force)  # fmt: skip
    model = load_model(args.model, args.context)
    rec = read_recording(args.recording)
    apply_whisker(model, args.whisker, [rec.meta], args.model)
    warn_training_recordings(model, [args.recording])
    res = model.classify_recording(rec, speed=args.speed)
    if model.channel is not None and res["channel"] != model.channel:
        say(f"note: the model was trained on column {model.channel!r}; this recording's "
            f"only signal column is {res['channel']!r}, classified instead")  # fmt: skip
    say(f"{args.recording}: {res['label']} (confidence {res['confidence']:.3f}, "
        f"{len(res['windows'])} windows)")  # fmt: skip
    if res["fault_windows"]:
        first = next(w for w in res["windows"] if "reason" in w)
        say(f"warning: {res['fault_windows']} window(s) got no terrain, e.g. at "
            f"{first['start_s']:g} s: {first['label']} ({first['reason']})")  # fmt: skip
    out = {"recording": str(args.recording), **res}
    if args.plot is not None:
        from ..plot import plot_recording_labels

        x = rec.columns[res["channel"].split(",")[0]]  # checked by classify_recording
        title = f"{args.recording.name}: {res['label']} (mean probability {res['confidence']:.2f})"
        faults = sorted({w["label"] for w in res["windows"]} - set(model.labels))
        plot_recording_labels(args.plot, rec.t, x, res, [*model.labels, *faults],
                              window_s=model.window_s, title=title)  # fmt: skip
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


def warn_training_recordings(model, paths) -> list[str]:
    """Say (stderr) which of ``paths`` trained the model (by content hash): their scores
    say how well it remembers, not how well it does on new recordings."""
    from ..classify import trained_on

    seen = trained_on(model, paths)
    if seen:
        say(f"warning: {len(seen)} of these {len(list(paths))} recording(s) trained this "
            f"model (e.g. {seen[0]}): their scores flatter it; evaluate on recordings it "
            "never saw")  # fmt: skip
    return seen
