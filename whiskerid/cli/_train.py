"""``whiskerid train``: a terrain classifier from a dataset folder."""

import argparse
from pathlib import Path

from .._choices import FEATURE_KINDS
from ._common import (
    CONTEXT_HELP,
    FORCE_HELP,
    QUIET_HELP,
    CommandError,
    HelpFormatter,
    check_outputs,
    say,
    show_progress,
)


def add_parser(sub) -> None:
    """Register ``train`` on the CLI's subparsers."""
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
        formatter_class=HelpFormatter,
    )
    t.add_argument("dataset", type=Path,
                   help="dataset folder: one subfolder of recordings per label")  # fmt: skip
    t.add_argument("--out", type=Path, required=True, help="model folder to write")
    t.add_argument("--features", choices=FEATURE_KINDS, default="fitted",
                   help="fitted: fitted spectral and time-domain features, one small network; "
                   "paper: the paper's |FFT| input and 7-layer network")  # fmt: skip
    t.add_argument(
        "--channel",
        help="column to classify (by default the first signal column, which must then be the "
        "same in every recording; kept in the model); several columns joined by commas "
        "(hall_a,hall_b: the two Hall sensors) or 'all' make windows of several channels",
    )
    t.add_argument(
        "--whisker", type=Path, metavar="TOML",
        help="calibrated record of the whisker that made the recordings (whiskerid "
        "calibrate): the features then divide out its own response (base-motion band "
        "levels in dB, the windows recoloured to it), and the model keeps it, so that "
        "classify/evaluate --whisker can run it on another calibrated whisker",
    )  # fmt: skip
    t.add_argument(
        "--span-whiskers", type=int, metavar="N",
        help="with --whisker: also train on every window as N whiskers around the calibrated "
        "one (f1 x0.6-1.6, zeta x0.5-2) would have recorded it, so that the model serves "
        "them alike (8 by default; 0: the recordings alone; each costs about as much "
        "feature time as the recordings themselves)",
    )  # fmt: skip
    t.add_argument(
        "--modal-fit", action="store_true",
        help="with --features fitted: add a damped oscillation fitted to each window in the "
        "time domain (all windows at once): its frequency, zeta, amplitude and whether the "
        "fit converged, per channel",
    )  # fmt: skip
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
        help=CONTEXT_HELP + "; 3 windows for fitted, 1 for paper by default",
    )  # fmt: skip
    t.add_argument(
        "--cv", type=int, metavar="K",
        help="first cross-validate by recording with K folds (every recording tested once by "
        "a network that never saw it; K = number of recordings: leave one out) and report "
        "it and keep it in the model file: the accuracy to expect on new recordings",
    )  # fmt: skip
    t.add_argument("--seed", type=int, default=0,
                   help="seed of the initial weights, the validation recordings, the batches "
                   "and the --cv folds")  # fmt: skip
    t.add_argument("--force", action="store_true", help=FORCE_HELP)
    t.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    t.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    t.set_defaults(func=run)


def run(args) -> dict:
    """Train (and cross-validate), write the model folder; returns the JSON summary."""
    from ..classify import cross_validate, load_dataset, train_classifier

    check_outputs({"--out": args.out},
                  {"DATASET": args.dataset, "--whisker": getattr(args, "whisker", None)},
                  force=args.force, folders=("--out",))  # fmt: skip
    if args.window <= 0:
        raise CommandError("--window must be positive")
    if args.modal_fit and args.features != "fitted":
        raise CommandError("--modal-fit goes with --features fitted")
    if args.cv is not None and args.cv < 2:
        raise CommandError(f"--cv must be at least 2 folds, not {args.cv}")
    if args.span_whiskers is not None and args.span_whiskers < 0:
        raise CommandError(f"--span-whiskers must be 0 or more, not {args.span_whiskers}")
    if args.span_whiskers and args.whisker is None:
        raise CommandError("--span-whiskers goes with --whisker (the calibrated whisker that "
                           "made the recordings)")  # fmt: skip
    # Settings first: bad ones are refused before the data is read.
    config = _config(args)
    ws = load_dataset(args.dataset, channel=args.channel, window_s=args.window,
                      hop_s=args.hop, rate_hz=args.rate)  # fmt: skip
    hop = None if args.hop is None else round(args.hop * ws.rate_hz)
    use_speed = False if args.no_speed else None
    whisker = _whisker(args.whisker, ws)
    cv = None
    if args.cv is not None:
        cv = cross_validate(ws, features=args.features, folds=args.cv, seed=args.seed,
                            config=config, context_s=args.context, use_speed=use_speed,
                            progress=show_progress(args), whisker=whisker,
                            window_fit=args.modal_fit,
                            span_whiskers=args.span_whiskers)  # fmt: skip
        cv = {k: cv[k] for k in ("folds", "accuracy", "accuracy_per_window", "per_class",
                                 "accuracy_by_fold", "context_s", "accuracy_per_recording",
                                 "n_recordings")}  # fmt: skip
        say(f"{args.cv}-fold cross-validation by recording: {cv['accuracy']:.3f} "
            f"({cv['accuracy_per_window']:.3f} per window; whole recordings "
            f"{cv['accuracy_per_recording']:.3f} of {cv['n_recordings']})")  # fmt: skip
    model = train_classifier(ws, features=args.features, config=config,
                             use_speed=use_speed, channel=None, hop=hop,
                             context_s=args.context, whisker=whisker,
                             window_fit=args.modal_fit,
                             span_whiskers=args.span_whiskers)  # fmt: skip
    if cv is not None:
        model.info["cross_validation"] = cv
    model.save(args.out)
    info = model.info
    say(f"trained on {len(ws)} windows of {ws.windows.shape[-1]} samples at {ws.rate_hz:g} Hz, "
        f"{len(ws.label_names)} classes; validation accuracy {info['val_accuracy']:.3f}; "
        f"wrote {args.out}")  # fmt: skip
    return {"out": str(args.out), "features": args.features, "labels": list(model.labels),
            "rate_hz": ws.rate_hz, "window": model.window, "windows": len(ws),
            "use_speed": model.needs_speed, "context_s": model.context_s,
            "channel": model.channel,
            "whisker": None if whisker is None else whisker.record.name, **info}  # fmt: skip


def _whisker(path: Path | None, ws):
    """The calibrated whisker of ``--whisker`` with the recordings' amplifier, or None."""
    if path is None:
        return None
    from ..classify import WhiskerResponse, recorded_amplifier
    from ..model import load_record

    return WhiskerResponse(load_record(path), recorded_amplifier(ws.metas or []))


def _config(args):
    """The training settings: the feature kind's preset with the options given."""
    from dataclasses import replace

    from ..classify import default_config

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
    return config
