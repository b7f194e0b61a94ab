"""Training a classifier: feature settings for a window set, standardisation, the MLP with
early stopping on held-out *recordings* (then refitted on all windows), and the model."""

from dataclasses import replace

import numpy as np

from ..io._context import check_context, default_context_s
from ..io._health import HealthReference
from ..io._health_modes import whisker_mode
from ._dataset import WindowSet
from ._features import FeatureSpec, compute_features, rerecorded
from ._mlp import TrainConfig, default_config, train_mlp
from ._model_file import ClassifierModel, recording_hashes
from ._split import grouped_split
from ._whisker import ALIAS_SLOPE, SPAN_WHISKERS, WhiskerResponse


def default_spec(
    ws: WindowSet, features: str = "fitted", *, use_speed: bool | None = None,
    whisker: bool = False, window_fit: bool = False,
) -> FeatureSpec:  # fmt: skip
    """Feature settings for a window set: its rate and window; speed features and absolute
    octave levels when the speed is known; whisker-aware features with ``whisker`` (a
    calibrated whisker is given); cross-channel features for two channels (two Hall
    sensors).

    The spatial-frequency range is the one every training speed covers: bins from
    ``2 Δf`` at the slowest speed to Nyquist at the fastest.
    """
    window = ws.windows.shape[-1]
    channels = ws.windows.shape[1] if ws.windows.ndim == 3 else 1
    if features == "paper":
        return FeatureSpec(kind="paper", rate_hz=ws.rate_hz, window=window, channels=channels,
                           deconvolve=whisker, floor_match=whisker, extend_edges=whisker,
                           alias_slope=ALIAS_SLOPE if whisker else 0.0)  # fmt: skip
    use = ws.has_speed if use_speed is None else use_speed
    if use and not ws.has_speed:
        raise ValueError("speed features need speed_mps on every recording")
    # Absolute octave levels only with the speed: without it a level says as much about
    # how fast a run went as about the ground (BorealTC, runs held out: 1-4 points worse
    # with them; the synthetic set, where the speed is known: 1 point better).
    spec = FeatureSpec(kind="fitted", rate_hz=ws.rate_hz, window=window, octave_bands=use,
                       use_speed=use, channels=channels, deconvolve=whisker, floor_match=whisker,
                       extend_edges=whisker, alias_slope=ALIAS_SLOPE if whisker else 0.0,
                       cross_channel=channels == 2, window_fit=window_fit)  # fmt: skip
    if use:
        df, nyq = ws.rate_hz / window, ws.rate_hz / 2
        lo, hi = 2 * df / float(ws.speeds.min()), nyq / float(ws.speeds.max())
        if not lo < hi / 2:
            lo = hi / 10
        spec = replace(spec, spatial_lo=float(lo), spatial_hi=float(hi))
    return spec


def features_of(ws: WindowSet, spec: FeatureSpec, whisker: WhiskerResponse | None = None
                ) -> np.ndarray:  # fmt: skip
    """Features of every window, shape ``(n, spec.n_features)`` (``whisker``: the one that
    recorded them, for whisker-aware features).

    Raises:
        ValueError: Some windows give features that are not finite or beyond float32 (a
            cell such as 1e308 in a recording): the recordings are named, since a network
            trained on them could not be used.
    """
    speeds = ws.speeds if (spec.kind == "fitted" and spec.use_speed) else None
    numbers = spec.numbers(whisker) if spec.deconvolve else None
    feats = np.asarray(compute_features(spec, ws.windows, speeds, numbers))
    bad = ~np.all(np.isfinite(feats) & (np.abs(feats) < _FEATURE_LIMIT), axis=1)
    if bad.any():
        names = [ws.sources[r] for r in np.unique(ws.recording[bad])]
        raise ValueError(
            f"{len(names)} recording(s) give features that are not finite numbers (e.g. "
            f"{names[0]}, window at {ws.starts()[np.flatnonzero(bad)[0]]:g} s): a sample there "
            "is absurdly large (such as 1e308); mend or remove the recording(s)"
        )
    return feats


def span_features(ws: WindowSet, spec: FeatureSpec, whisker: WhiskerResponse, count: int,
                  seed: int = 0) -> np.ndarray:  # fmt: skip
    """Features of every window of ``ws`` (recorded with ``whisker``) as each of ``count``
    whiskers of the span around it would have recorded the same base motion
    (:meth:`WhiskerResponse.span`, :meth:`WhiskerResponse.rerecord`: through that whisker's
    response, with the sensors' white floor made up where it responds more weakly), read
    as a model with ``whisker`` reads that whisker's recordings: recoloured back, floor
    matched. Shape ``(count × n, spec.n_features)``, whisker by whisker.

    Recolouring gives back the training whisker's signal but not its floor: a weaker
    whisker's floor, recoloured, stands above the matched floor wherever that whisker is
    weaker than the span's average, and a model trained on one whisker alone reads that
    as ground. Trained on these too, it learns what the recolouring leaves.
    """
    own = replace(whisker, alias_slope=spec.alias_slope)
    freqs = np.fft.rfftfreq(2 * spec.window, 1.0 / spec.rate_hz)
    speeds = ws.speeds if (spec.kind == "fitted" and spec.use_speed) else None
    parts = [np.zeros((0, spec.n_features))]
    for k, other in enumerate(own.span(count, seed)):
        response, floor = own.rerecord(other, freqs, spec.rate_hz)
        noise_seed = seed * 1009 + k  # every whisker its own noise
        windows = rerecorded(ws.windows, response, floor, extend=spec.extend_edges,
                             seed=noise_seed)  # fmt: skip
        numbers = spec.numbers(other, own)
        parts.append(np.asarray(compute_features(spec, windows, speeds, numbers)))
    return np.concatenate(parts)


def with_span_features(feats, ws, spec, whisker, count, seed):
    """The features of ``ws`` followed by its :func:`span_features`, the window set
    repeated to match, and each row's window."""
    index = np.tile(np.arange(len(ws)), count + 1)
    if count == 0:
        return feats, ws, index
    span = span_features(ws, spec, whisker, count, seed)
    return np.concatenate([feats, span]), ws.subset(index), index


def span_count(span_whiskers: int | None, whisker: WhiskerResponse | None) -> int:
    """How many span whiskers training adds: :data:`SPAN_WHISKERS` for a whisker-aware
    model by default, none without a whisker."""
    if span_whiskers is None:
        return SPAN_WHISKERS if whisker is not None else 0
    if span_whiskers < 0:
        raise ValueError(f"span_whiskers must be 0 or more, not {span_whiskers}")
    if span_whiskers and whisker is None:
        raise ValueError("span whiskers need the calibrated whisker that made the recordings")
    return int(span_whiskers)


#: Features beyond this cannot be standardised in float32, the networks' precision.
_FEATURE_LIMIT = 1e30


def fit_on_features(
    feats: np.ndarray, ws: WindowSet, spec: FeatureSpec, config: TrainConfig,
    *, val_fraction: float = 0.2, context_s: float | None = None,
    whisker: WhiskerResponse | None = None,
) -> ClassifierModel:  # fmt: skip
    """Train on precomputed features of ``ws`` (validation: held-out recordings).

    Early stopping on held-out recordings chooses the number of epochs; with
    ``config.refit`` (default) the network is then trained again on all of ``ws`` for that
    many epochs. With ``config.ensemble = K > 1``, K networks are trained, each with its
    own seed and its own validation recordings, and their probabilities are averaged.
    ``context_s`` goes into the model (see :class:`ClassifierModel`); None: each window on
    its own (:func:`train_classifier` applies :func:`default_context_s`).
    """
    if context_s is not None:  # refused before training, not after
        check_context(context_s, spec.window / spec.rate_hz)
    mean = feats.mean(axis=0)
    std = np.maximum(feats.std(axis=0), 1e-6 * (np.abs(mean) + 1.0))
    z = (feats - mean) / std
    nets, runs, refit_epochs = [], [], 0
    for j in range(max(config.ensemble, 1)):
        cfg = replace(config, seed=config.seed + 1000 * j)
        val = grouped_split(ws, val_fraction, cfg.seed + 1)
        n_cls = len(ws.label_names)
        res = train_mlp(z[~val], ws.labels[~val], z[val], ws.labels[val], n_cls, cfg)
        runs.append(res)
        if cfg.refit:  # same padded shape: no new compilation
            res = train_mlp(z, ws.labels, z[:0], ws.labels[:0], n_cls, cfg, epochs=res.best_epoch)
            refit_epochs += res.epochs
        nets.append(res.model)
    info = {"epochs": sum(r.epochs for r in runs), "best_epoch": runs[0].best_epoch,
            "refit_on_all": config.refit, "refit_epochs": refit_epochs,
            "val_loss": round(float(np.mean([r.best_val_loss for r in runs])), 5),
            "val_accuracy": round(float(np.mean([r.val_accuracy for r in runs])), 4),
            "members": len(nets), "train_windows": len(ws) if config.refit else int((~val).sum()),
            "val_windows": int(val.sum()),
            "seed": config.seed, "hidden": list(config.hidden),
            "weight_decay": config.weight_decay, "input_noise": config.input_noise}  # fmt: skip
    return ClassifierModel(spec, ws.label_names, mean, std, nets, hop=ws.windows.shape[-1],
                           info=info, context_s=context_s, whisker=whisker)  # fmt: skip


def check_classes(ws: WindowSet) -> None:
    """Refuse training data with fewer than two classes or a class without windows (its
    recordings all shorter than one window): a model would learn nothing of it, yet name
    it as a class."""
    counts = np.bincount(ws.labels, minlength=len(ws.label_names))
    if len(ws.label_names) < 2:
        raise ValueError(
            f"a classifier needs at least two terrains; the data have only {list(ws.label_names)}"
        )
    empty = [lab for lab, c in zip(ws.label_names, counts, strict=True) if c == 0]
    if empty:
        window_s = ws.windows.shape[-1] / ws.rate_hz
        raise ValueError(
            f"no windows of {empty}: their recordings are shorter than one window "
            f"({window_s:g} s); record longer or pass a shorter window"
        )


def train_classifier(
    ws: WindowSet,
    *,
    features: str = "fitted",
    config: TrainConfig | None = None,
    use_speed: bool | None = None,
    channel: str | None = None,
    hop: int | None = None,
    context_s: float | None = None,
    whisker: WhiskerResponse | None = None,
    window_fit: bool = False,
    span_whiskers: int | None = None,
) -> ClassifierModel:
    """Train a classifier on labelled windows.

    Args:
        ws: Training windows (all of them; a validation part of whole recordings is held
            out inside for early stopping).
        features: ``fitted`` (ours) or ``paper`` (standardise + |FFT|, the paper's network).
        config: Network and training settings; the paper's preset sizes for ``paper``.
        use_speed: Speed-normalised features; by default when every recording has a speed.
        channel: Recorded column the model classifies (kept in the model file); the
            window set's own by default.
        hop: Window step for whole recordings (samples); the window length by default.
        context_s: Signal each label rests on (s), fused over consecutive windows
            (:func:`fuse_context`); :func:`default_context_s` by default.
        whisker: The calibrated whisker that recorded ``ws``: the features then divide out
            its transfer function, and the model keeps it, so that it can run on another
            calibrated whisker (:meth:`ClassifierModel.use_whisker`).
        window_fit: Add per-window damped-oscillation fits (``fitted``; see
            :class:`FeatureSpec`).
        span_whiskers: With ``whisker``: train also on every window as this many whiskers
            of the span the model serves would have recorded it (:func:`span_features`);
            :data:`SPAN_WHISKERS` by default, 0 for the training whisker's windows alone.
    """
    count = span_count(span_whiskers, whisker)
    if config is None:
        config = default_config(features)
    check_classes(ws)
    if whisker is not None:
        channels = ws.windows.shape[1] if ws.windows.ndim == 3 else 1
        whisker = WhiskerResponse(whisker.record, whisker.amplifier, channels)
    spec = default_spec(ws, features, use_speed=use_speed, whisker=whisker is not None,
                        window_fit=window_fit)  # fmt: skip
    if context_s is None:
        context_s = default_context_s(features, spec.window / spec.rate_hz)
    plain = features_of(ws, spec, whisker)
    feats, train_ws, _ = with_span_features(plain, ws, spec, whisker, count, config.seed)
    model = fit_on_features(feats, train_ws, spec, config, context_s=context_s,
                            whisker=whisker)  # fmt: skip
    model.info["span_whiskers"] = count
    # What the training windows look like, so that a window unlike them all (a dead
    # sensor's noise, another instrument) is 'unknown' rather than some terrain.
    modes = None if whisker is None else (whisker_mode(whisker, ws.rate_hz, spec.window),)
    model.health = HealthReference.fit(ws.windows, ws.labels, rate_hz=ws.rate_hz, modes_hz=modes,
                                      groups=ws.recording)  # fmt: skip
    model.info["recordings_sha256"] = recording_hashes(ws.sources)
    model.channel = ws.channel if channel is None else channel
    if hop is not None:
        model.hop = int(hop)
    return model
