"""``whiskerid evaluate``: score a terrain classifier on a labelled dataset."""

from pathlib import Path

from ._classify import WHISKER_HELP, apply_whisker, warn_training_recordings
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

#: Recordings labelled wrong that ``evaluate`` names on stderr (all of them are in --json).
_SHOW_WRONG = 10


def add_parser(sub) -> None:
    """Register ``evaluate`` on the CLI's subparsers."""
    e = sub.add_parser(
        "evaluate",
        help="score a classifier on a labelled dataset",
        description="Accuracy, precision, recall and F1 per class (with macro and weighted "
        "averages) and the confusion matrix of MODEL on DATASET, with labels per window and "
        "for whole recordings (the recordings labelled wrong are named). Recordings that "
        "trained the model are pointed out.",
        formatter_class=HelpFormatter,
    )
    e.add_argument("model", type=Path, help="model folder (whiskerid train)")
    e.add_argument("dataset", type=Path,
                   help="dataset folder: one subfolder of recordings per label")  # fmt: skip
    e.add_argument("--plot", type=Path, help="save the confusion matrix as this PNG")
    e.add_argument("--context", type=float, metavar="S",
                   help=CONTEXT_HELP + "; the model's by default")  # fmt: skip
    e.add_argument("--force", action="store_true", help=FORCE_HELP)
    e.add_argument("--whisker", type=Path, metavar="TOML", help=WHISKER_HELP)
    e.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    e.set_defaults(func=run)


def run(args) -> dict:
    """Score the model and print its confusion matrix; returns the JSON summary."""
    from ..classify import evaluate_classifier as evaluate
    from ..classify import format_confusion, format_report, load_dataset
    from ..plot import plot_confusion

    check_outputs({"--plot": args.plot},
                  {"MODEL": model_folder(args.model), "DATASET": args.dataset},
                  force=args.force)  # fmt: skip
    model = load_model(args.model, args.context)
    ws = load_dataset(args.dataset, channel=model.channel, window_s=model.window / model.rate_hz,
                      rate_hz=model.rate_hz, labels=model.labels)  # fmt: skip
    if model.needs_speed and not ws.has_speed:
        raise CommandError(f"{args.model} needs speed_mps on every recording of {args.dataset}")
    apply_whisker(model, args.whisker, ws.metas or [], args.model)
    seen = warn_training_recordings(model, ws.sources)
    res = evaluate(model, ws)
    res["training_recordings_evaluated"] = len(seen)
    say(format_confusion(res["confusion"], res["labels"]))
    say(format_report(res["report"]))
    say(f"accuracy {res['accuracy']:.4f} on {res['n_windows']} windows, labels resting on "
        f"{model.context_s:g} s (each window on its own: "
        f"{res['accuracy_per_window']:.4f}; whole recordings: "
        f"{res['accuracy_per_recording']:.4f} of {res['n_recordings']})")  # fmt: skip
    wrong = res["wrong_recordings"]
    for w in wrong[:_SHOW_WRONG]:
        say(f"  labelled wrong whole: {w['recording']} as {w['predicted']} "
            f"(mean probability {w['confidence']:.3f})")  # fmt: skip
    if len(wrong) > _SHOW_WRONG:
        say(f"  ... and {len(wrong) - _SHOW_WRONG} more (all in --json: wrong_recordings)")
    if args.plot:
        plot_confusion(args.plot, res["confusion"], res["labels"])
        res["plot"] = str(args.plot)
        say(f"wrote {args.plot}")
    return res
