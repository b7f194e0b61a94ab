"""``whiskerid dataset synth``, ``train``, ``evaluate`` and ``classify`` (NOTES §7)."""

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from .._choices import FEATURE_KINDS
from ..io._recording import check_out_path

_FMT = argparse.ArgumentDefaultsHelpFormatter


#: Recordings labelled wrong that ``evaluate`` names on stderr (all of them are in --json).
_SHOW_WRONG = 10

_CONTEXT_HELP = (
    "signal each label rests on (s): the window and the windows before it, fused (mean "
    "log-probability; the label lags a change of terrain by up to S minus one window)"
)


def _say(*parts) -> None:
    print(*parts, file=sys.stderr)


def add_classify_commands(sub, command_error) -> None:
    """Register ``dataset``, ``train``, ``evaluate`` and ``classify``."""
    global CommandError
    CommandError = command_error

    p = sub.add_parser("dataset", help="make labelled datasets (synthetic terrains)",
                       formatter_class=_FMT)  # fmt: skip
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
        formatter_class=_FMT,
    )
    from ..terrain._terrain import SPEEDS_MPS, TERRAINS

    s.add_argument("--out", type=Path, required=True, help="dataset folder to write")
    s.add_argument("--whisker", type=Path, help="whisker record (TOML); the paper's by default")
    s.add_argument("--terrains", nargs="+", default=list(TERRAINS), metavar="T",
                   help=f"terrains among {', '.join(TERRAINS)}")  # fmt: skip
    s.add_argument("--speeds", nargs="+", type=float, default=list(SPEEDS_MPS), metavar="V",
                   help="nominal robot speeds (m/s)")  # fmt: skip
    s.add_argument("--runs", type=int, default=4, help="recordings per terrain and speed")
    s.add_argument("--duration", type=float, default=30.0, help="length of each recording (s)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    s.set_defaults(func=_cmd_synth)

    t = sub.add_parser(
        "train",
        help="train a terrain classifier on a dataset folder",
        description=(
            "Train an MLP terrain classifier on DATASET (ROOT/<label>/<recording>.csv). "
            "Recordings are resampled to the rate in their metadata or timestamps and cut "
            "into windows. --features paper: standardise + |FFT| and the paper's 7-layer "
            "network; fitted: spectral peaks with sub-bin interpolation, band energies and "
            "spectral shape, a closed-form resonance estimate, time-domain and envelope "
            "statistics, and, when every recording has speed_mps, speed-normalised forms "
            "and absolute levels in octave bands, "
            "with one small network. Early stopping on held-out recordings chooses the "
            "number of epochs; the network is then refitted on all windows."
        ),
        formatter_class=_FMT,
    )
    t.add_argument("dataset", type=Path)
    t.add_argument("--out", type=Path, required=True, help="model folder to write")
    t.add_argument("--features", choices=FEATURE_KINDS, default="fitted")
    t.add_argument(
        "--channel",
        help="column to classify (by default the first signal column, which must then be the "
        "same in every recording; kept in the model)",
    )
    t.add_argument("--window", type=float, default=1.0, help="window length (s)")
    t.add_argument("--hop", type=float, help="window step (s); the window length by default")
    t.add_argument(
        "--rate",
        type=float,
        help="resample to this rate (Hz), at most the slowest recording's; by default the "
        "recordings' own, which must then agree within 5 %%",
    )
    t.add_argument("--no-speed", action="store_true", help="do not use speed_mps metadata")
    t.add_argument("--hidden", type=int, nargs="+", help="hidden layer sizes")
    t.add_argument(
        "--max-epochs",
        type=int,
        help="epoch limit, rounded up to whole chunks of 20 (fitted) or 10 (paper) epochs "
        "between stopping checks (1500 for fitted, 300 for paper by default)",
    )
    t.add_argument("--ensemble", type=int, help="networks averaged (1 by default)")
    t.add_argument(
        "--balance", action=argparse.BooleanOptionalAction, default=None,
        help="weight classes by inverse frequency, so each counts alike whatever the time "
        "recorded on it (default for fitted; the paper preset does not)",
    )  # fmt: skip
    t.add_argument("--weight-decay", type=float, metavar="W",
                   help="decoupled weight decay (1.0 for fitted by default)")  # fmt: skip
    t.add_argument("--input-noise", type=float, metavar="S",
                   help="Gaussian noise on the standardised inputs while training "
                   "(0.3 for fitted by default)")  # fmt: skip
    t.add_argument(
        "--context", type=float, metavar="S",
        help=_CONTEXT_HELP + "; 3 windows for fitted, 1 for paper by default",
    )  # fmt: skip
    t.add_argument(
        "--cv", type=int, metavar="K",
        help="first cross-validate by recording with K folds (every recording tested once by "
        "a network that never saw it; K = number of recordings: leave one out) and report "
        "it and keep it in the model file: the accuracy to expect on new recordings",
    )  # fmt: skip
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    t.set_defaults(func=_cmd_train)

    e = sub.add_parser(
        "evaluate",
        help="score a classifier on a labelled dataset",
        description="Accuracy, per-class accuracy and confusion matrix of MODEL on DATASET, "
        "with labels per window and for whole recordings (the recordings labelled wrong "
        "are named).",
        formatter_class=_FMT,
    )
    e.add_argument("model", type=Path)
    e.add_argument("dataset", type=Path)
    e.add_argument("--plot", type=Path, help="save the confusion matrix as this PNG")
    e.add_argument("--context", type=float, metavar="S",
                   help=_CONTEXT_HELP + "; the model's by default")  # fmt: skip
    e.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    e.set_defaults(func=_cmd_evaluate)

    c = sub.add_parser(
        "classify",
        help="label the terrain of a recording, per window and overall",
        description="Classify every window of REC and the whole recording (mean probability).",
        formatter_class=_FMT,
    )
    c.add_argument("model", type=Path)
    c.add_argument("recording", type=Path)
    c.add_argument("--speed", type=float, help="robot speed (m/s); from the metadata by default")
    c.add_argument("--plot", type=Path, metavar="PNG",
                   help="save the signal and its labels over time as this PNG")  # fmt: skip
    c.add_argument("--context", type=float, metavar="S",
                   help=_CONTEXT_HELP + "; the model's by default")  # fmt: skip
    c.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    c.set_defaults(func=_cmd_classify)


def _cmd_synth(args) -> dict:
    from ..model._record import load_record, paper_record
    from ..terrain._terrain import synthesize_dataset

    if args.runs < 1 or args.duration <= 0:
        raise CommandError("--runs must be >= 1 and --duration > 0")
    record = paper_record() if args.whisker is None else load_record(args.whisker)
    paths = synthesize_dataset(args.out, record=record, terrains=tuple(args.terrains),
                               speeds=tuple(args.speeds), runs=args.runs,
                               duration_s=args.duration, seed=args.seed)  # fmt: skip
    _say(f"wrote {len(paths)} recordings to {args.out}")
    return {"out": str(args.out), "recordings": len(paths), "terrains": args.terrains,
            "speeds_mps": args.speeds, "runs": args.runs, "duration_s": args.duration}  # fmt: skip


def _cmd_train(args) -> dict:
    from ..classify import cross_validate, default_config, load_dataset, train_classifier

    if args.window <= 0:
        raise CommandError("--window must be positive")
    if args.cv is not None and args.cv < 2:
        raise CommandError(f"--cv must be at least 2 folds, not {args.cv}")
    # Settings first: bad ones are refused before the data is read.
    config = replace(default_config(args.features), seed=args.seed)
    if args.max_epochs is not None:
        if args.max_epochs < 1:
            raise CommandError("--max-epochs must be at least 1")
        config = replace(config, max_epochs=args.max_epochs)
    if args.hidden:
        if min(args.hidden) < 1:
            raise CommandError(f"--hidden sizes must be at least 1, not {args.hidden}")
        config = replace(config, hidden=tuple(args.hidden))
    if args.ensemble is not None:
        if args.ensemble < 1:
            raise CommandError("--ensemble must be at least 1")
        config = replace(config, ensemble=args.ensemble)
    if args.balance is not None:
        config = replace(config, balance=args.balance)
    for name in ("weight_decay", "input_noise"):
        value = getattr(args, name)
        if value is not None:
            if not 0 <= value < float("inf"):
                raise CommandError(
                    f"--{name.replace('_', '-')} must be a finite number at least 0, not {value:g}"
                )
            config = replace(config, **{name: value})
    ws = load_dataset(args.dataset, channel=args.channel, window_s=args.window,
                      hop_s=args.hop, rate_hz=args.rate)  # fmt: skip
    hop = None if args.hop is None else round(args.hop * ws.rate_hz)
    use_speed = False if args.no_speed else None
    cv = None
    if args.cv is not None:
        cv = cross_validate(ws, features=args.features, folds=args.cv, seed=args.seed,
                            config=config, context_s=args.context, use_speed=use_speed,
                            progress=sys.stderr.isatty())  # fmt: skip
        cv = {k: cv[k] for k in ("folds", "accuracy", "accuracy_per_window", "per_class",
                                 "accuracy_by_fold", "context_s", "accuracy_per_recording",
                                 "n_recordings")}  # fmt: skip
        _say(f"{args.cv}-fold cross-validation by recording: {cv['accuracy']:.3f} "
             f"({cv['accuracy_per_window']:.3f} per window; whole recordings "
             f"{cv['accuracy_per_recording']:.3f} of {cv['n_recordings']})")  # fmt: skip
    model = train_classifier(ws, features=args.features, config=config,
                             use_speed=use_speed, channel=args.channel, hop=hop,
                             context_s=args.context)  # fmt: skip
    if cv is not None:
        model.info["cross_validation"] = cv
    model.save(args.out)
    info = model.info
    _say(f"trained on {len(ws)} windows of {ws.windows.shape[-1]} samples at {ws.rate_hz:g} Hz, "
         f"{len(ws.label_names)} classes; validation accuracy {info['val_accuracy']:.3f}; "
         f"wrote {args.out}")  # fmt: skip
    return {"out": str(args.out), "features": args.features, "labels": list(model.labels),
            "rate_hz": ws.rate_hz, "window": model.window, "windows": len(ws),
            "use_speed": model.needs_speed, "context_s": model.context_s, **info}  # fmt: skip


def _load_model(path, context_s=None):
    from ..classify import ClassifierModel

    model = ClassifierModel.load(path)
    if context_s is not None:
        model.context_s = context_s  # checked by the model
    return model


def _cmd_evaluate(args) -> dict:
    from ..classify import evaluate_classifier as evaluate
    from ..classify import format_confusion, load_dataset
    from ..plot._classify import plot_confusion

    if args.plot is not None:  # before any work
        check_out_path(args.plot, "--plot", inputs={"MODEL": args.model, "DATASET": args.dataset})
    model = _load_model(args.model, args.context)
    ws = load_dataset(args.dataset, channel=model.channel, window_s=model.window / model.rate_hz,
                      rate_hz=model.rate_hz, labels=model.labels)  # fmt: skip
    if model.needs_speed and not ws.has_speed:
        raise CommandError(f"{args.model} needs speed_mps on every recording of {args.dataset}")
    res = evaluate(model, ws)
    _say(format_confusion(res["confusion"], res["labels"]))
    _say(f"accuracy {res['accuracy']:.4f} on {res['n_windows']} windows, labels resting on "
         f"{model.context_s:g} s (each window on its own: "
         f"{res['accuracy_per_window']:.4f}; whole recordings: "
         f"{res['accuracy_per_recording']:.4f} of {res['n_recordings']})")  # fmt: skip
    wrong = res["wrong_recordings"]
    for w in wrong[:_SHOW_WRONG]:
        _say(f"  labelled wrong whole: {w['recording']} as {w['predicted']} "
             f"(mean probability {w['confidence']:.3f})")  # fmt: skip
    if len(wrong) > _SHOW_WRONG:
        _say(f"  ... and {len(wrong) - _SHOW_WRONG} more (all in --json: wrong_recordings)")
    if args.plot:
        plot_confusion(args.plot, res["confusion"], res["labels"])
        res["plot"] = str(args.plot)
        _say(f"wrote {args.plot}")
    return res


def _cmd_classify(args) -> dict:
    from ..io._recording import read_recording

    if args.plot is not None:  # before any work
        check_out_path(args.plot, "--plot", inputs={"MODEL": args.model, "REC": args.recording})
    model = _load_model(args.model, args.context)
    rec = read_recording(args.recording)
    res = model.classify_recording(rec, speed=args.speed)
    if model.channel is not None and res["channel"] != model.channel:
        _say(f"note: the model was trained on column {model.channel!r}; this recording's "
             f"only signal column is {res['channel']!r}, classified instead")  # fmt: skip
    _say(f"{args.recording}: {res['label']} (confidence {res['confidence']:.3f}, "
         f"{len(res['windows'])} windows)")  # fmt: skip
    out = {"recording": str(args.recording), **res}
    if args.plot is not None:
        from ..plot._plot import plot_recording_labels

        x = rec.columns[res["channel"]]  # checked by classify_recording
        title = f"{args.recording.name}: {res['label']} (mean probability {res['confidence']:.2f})"
        plot_recording_labels(args.plot, rec.t, x, res, model.labels, window_s=model.window_s,
                              title=title)  # fmt: skip
        out["plot"] = str(args.plot)
        _say(f"wrote {args.plot}")
    return out


CommandError = ValueError  # replaced by the CLI's own class on registration
