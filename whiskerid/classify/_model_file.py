"""The trained classifier (:class:`ClassifierModel`) and its model files.

:class:`ClassifierModel` is what a stream calls: :meth:`ClassifierModel.predict_window`
(one window → label and confidence) and :meth:`ClassifierModel.predict_windows` (a batch).
Both run module-level compiled functions whose cache key is the architecture (the feature
spec's structure, the layer sizes, the number of ensemble members and the batch's size
class): the model's numbers (weights, normalisation, rate) are traced arguments, so loading
a model file again, or another model of the same architecture, compiles nothing.

A model file is a folder with ``model.json`` (format, versions, feature spec, rate, window,
hop, labels, normalisation, network sizes, training summary) and ``weights.npz``: arrays
``m<member>_W<layer>`` and ``m<member>_b<layer>``, read with ``allow_pickle=False``; no pickle
anywhere. The weights stay in NPZ rather than equinox's ``tree_serialise_leaves``: that format
is an unnamed sequence of leaves whose meaning is the flattening order of the :class:`MLP`
class (a change to the class would silently misread older files), it can only be read back
into a skeleton built by equinox, and files written so far are NPZ and must keep loading. NPZ
names every array, so each layer's presence and shape is checked with a message naming it,
and any NumPy (a Pi without JAX, another language) can read a model.
"""

import functools
import hashlib
import json
import zipfile
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .._version import __version__
from ..io import Recording, RecordingError, atomic_folder, atomic_write, sha256_of
from ..io._context import check_context, fuse_context
from ..io._health import UNKNOWN, HealthReference, window_health
from ..io._health_context import ModeContext
from ..io._health_modes import gain_ratio
from ._dataset import (
    check_rate,
    check_speed,
    multi_windows,
    recording_signal,
    recording_signals,
    recording_speed,
    signal_column,
    windows_of,
)
from ._features import (
    N_WINDOW_FIT,
    FeatureSpec,
    batch_features,
    window_features,
    window_fit_features,
)
from ._mlp import (
    MLP,
    from_arrays,
    pad_rows,
    to_arrays,
)
from ._whisker import WhiskerResponse

MODEL_FORMAT = "whiskerid.classifier/2"  # /2: spectral-shape and envelope features
MODEL_JSON = "model.json"
MODEL_WEIGHTS = "weights.npz"


class ModelError(ValueError):
    """A classifier model file that is missing, corrupt or from an incompatible version."""


def _mean_proba(nets, z):
    """The ensemble's mean class probabilities of standardised features ``z`` (one row or
    a batch)."""
    if z.ndim == 1:
        return sum(jax.nn.softmax(n(z)) for n in nets) / len(nets)
    return sum(jax.nn.softmax(jax.vmap(n)(z), axis=-1) for n in nets) / len(nets)


@functools.partial(jax.jit, static_argnums=0)
def _batch_proba(structure, numbers, nets, mean, std, windows, speeds, extra):
    """Class probabilities of a batch of windows: compiled once per feature structure,
    network sizes and (padded) batch shape, for every model of that architecture.
    ``extra``: features computed on the host (window fits), ``(n, 0)`` when none."""
    feats = jnp.concatenate([batch_features(structure, numbers, windows, speeds), extra], axis=1)
    return _mean_proba(nets, (feats.astype(jnp.float32) - mean) / std)


@functools.partial(jax.jit, static_argnums=0)
def _window_proba(structure, numbers, nets, mean, std, window, speed, extra):
    """Class probabilities of one window (see :func:`_batch_proba`)."""
    feats = jnp.concatenate([window_features(structure, window, speed, numbers), extra])
    return _mean_proba(nets, (feats.astype(jnp.float32) - mean) / std)


class ClassifierModel:
    """A trained terrain classifier: feature spec, normalisation, network, labels.

    The online stream calls :meth:`predict_window` on each new window of ``window``
    samples at ``rate_hz`` (uniformly resampled), or :meth:`predict_windows` on a batch.
    ``net`` is one network or a sequence of them (an ensemble: their class probabilities
    are averaged).

    ``context_s`` is how much signal a label rests on: the window itself and the windows
    that started up to ``context_s − window_s`` before it, fused by :func:`fuse_context`
    (recordings, evaluation and the online stream alike). Equal to the window length,
    every window is labelled on its own, as in the paper.
    """

    def __init__(self, spec: FeatureSpec, labels, mean, std, net: "MLP | list[MLP]", *,
                 hop: int, channel: str | None = None, info: dict | None = None,
                 context_s: float | None = None,
                 whisker: WhiskerResponse | None = None,
                 health: HealthReference | None = None):  # fmt: skip
        self.spec = spec
        self.health = health
        self.labels = tuple(labels)
        self.mean = np.asarray(mean, dtype=np.float32)
        self.std = np.asarray(std, dtype=np.float32)
        self.nets = (net,) if isinstance(net, MLP) else tuple(net)
        self.net = self.nets[0]
        self.hop = int(hop)
        self.channel = channel
        self.info = dict(info or {})
        self.context_s = self.window_s if context_s is None else context_s
        self.whisker = whisker
        self.recorded_with = whisker
        self._other_health = None
        if spec.deconvolve and whisker is None:
            raise ValueError("a model with whisker-aware features needs its training whisker")
        # Device-resident arguments of the module-level compiled functions, which depend on
        # the architecture only: a warm call is one dispatch and one small transfer.
        self._structure = spec.structure()
        self._args = (spec.numbers(whisker), self.nets, jnp.asarray(self.mean),
                      jnp.asarray(self.std))  # fmt: skip
        self._exported = None  # window_proba from a saved program (see use_saved_program)

    def window_health(self, samples) -> tuple[str, str] | None:
        """``(label, reason)`` when a window must get no terrain (``sensor-fault``: no
        working sensor gives it; ``unknown``: unlike every training window), else None
        (:func:`whiskerid.classify.window_health`).

        The training data's reference applies while the model reads its own whisker's
        recordings; on another whisker (:meth:`use_whisker`), with its own offset, gain and
        modes, the noise check and the amplitude range scaled by its gain do
        (:meth:`HealthReference.for_whisker`).
        """
        return window_health(samples, self.health_in_use)

    @property
    def health_in_use(self) -> HealthReference | None:
        """The health reference for the whisker read now (:meth:`window_health`)."""
        if self.health is None or self.recorded_with is self.whisker:
            return self.health
        if self._other_health is None:
            gain = gain_ratio(self.recorded_with, self.whisker, self.rate_hz, self.window)
            self._other_health = self.health.for_whisker(gain)
        return self._other_health

    @property
    def needs_whisker(self) -> bool:
        """Whether the features divide out the recording whisker's transfer function."""
        return self.spec.deconvolve

    def use_whisker(self, whisker: WhiskerResponse) -> None:
        """Run on windows recorded with another calibrated whisker: they are recoloured to
        the training whisker (see :class:`WhiskerResponse`)."""
        if not self.needs_whisker:
            raise ValueError(
                "this model's features are the raw signal's: it cannot take another whisker "
                "into account (train with --whisker to make one that can)"
            )
        whisker = WhiskerResponse(whisker.record, whisker.amplifier, self.spec.channels)
        self.recorded_with = whisker
        self._other_health = None  # its health reference, made when first asked
        self._args = (self.spec.numbers(whisker, self.whisker), *self._args[1:])
        self._exported = None

    @property
    def channels(self) -> tuple[str, ...] | None:
        """The recorded columns the model reads, in order (None: the first column)."""
        if self.channel is None:
            return None
        return tuple(self.channel.split(","))

    @property
    def rate_hz(self) -> float:
        """Sample rate the model expects (Hz)."""
        return self.spec.rate_hz

    @property
    def window(self) -> int:
        """Samples per window."""
        return self.spec.window

    @property
    def window_s(self) -> float:
        """Window length (s)."""
        return self.spec.window / self.spec.rate_hz

    @property
    def context_s(self) -> float:
        """Signal a label rests on (s), at least one window (see the class docstring)."""
        return self._context_s

    @context_s.setter
    def context_s(self, value: float) -> None:
        self._context_s = check_context(value, self.window_s)

    @property
    def lookback_s(self) -> float:
        """How far back a label looks for windows to fuse (s): ``context_s − window_s``."""
        return max(self.context_s - self.window_s, 0.0)

    def fuse(self, proba, recording, start_s) -> np.ndarray:
        """:func:`fuse_context` with this model's look-back."""
        return fuse_context(proba, recording, start_s, lookback_s=self.lookback_s)

    @property
    def needs_speed(self) -> bool:
        """Whether windows must come with the robot speed."""
        return self.spec.kind == "fitted" and self.spec.use_speed

    def _speeds(self, n: int, speeds) -> np.ndarray:
        if speeds is None:
            if self.needs_speed:
                raise ValueError("this model needs the robot speed (m/s) of each window")
            return np.full(n, np.nan)
        speeds = np.broadcast_to(np.asarray(speeds, dtype=float), (n,))
        if self.needs_speed:
            check_speed(speeds)
        return speeds

    def predict_proba(self, windows, speeds=None) -> np.ndarray:
        """Class probabilities, shape ``(n, classes)``, for windows ``(n, window)``."""
        windows = np.asarray(windows, dtype=float)
        if windows.shape[1:] != self.spec.window_shape:
            shape = ", ".join(map(str, ("n", *self.spec.window_shape)))
            raise ValueError(f"windows must have shape ({shape}), got {windows.shape}")
        speeds = self._speeds(len(windows), speeds)
        n = len(windows)
        if n == 0:
            return np.zeros((0, len(self.labels)), np.float32)
        # Padded (repeating the last window) to a size class: one compilation serves
        # recordings and datasets of many lengths.
        rows = np.minimum(np.arange(pad_rows(n)), n - 1)
        extra = window_fit_features(self.spec, windows[rows])
        p = _batch_proba(self._structure, *self._args, windows[rows], speeds[rows], extra)
        return _finite(np.asarray(p)[:n])

    def predict_windows(self, windows, speeds=None) -> tuple[np.ndarray, np.ndarray]:
        """Class index and confidence (its probability) per window."""
        p = self.predict_proba(windows, speeds)
        idx = np.argmax(p, axis=1)
        return idx, p[np.arange(len(idx)), idx]

    def predict_window(self, samples, speed: float | None = None) -> tuple[str, float]:
        """Label and confidence of one window of ``window`` samples at ``rate_hz``, on its
        own (no context; the online stream fuses :meth:`window_proba` itself).

        This is the stable entry point for online use: compiled on the first call for the
        model's architecture, one small dispatch per call afterwards.
        """
        p = self.window_proba(samples, speed)
        k = int(np.argmax(p))
        return self.labels[k], float(p[k])

    def window_proba(self, samples, speed: float | None = None) -> np.ndarray:
        """Class probabilities of one window, shape ``(classes,)`` (see :meth:`predict_window`)."""
        x = np.asarray(samples, dtype=np.float64)
        if x.shape != self.spec.window_shape:
            raise ValueError(
                f"a window has {self.window} samples (shape {self.spec.window_shape}), "
                f"got shape {x.shape}"
            )
        if speed is None and self.needs_speed:
            raise ValueError("this model needs the robot speed (m/s) of each window")
        if self.needs_speed:
            check_speed(speed)
        v = np.float64(np.nan if speed is None else speed)
        extra = window_fit_features(self.spec, x[None])[0] if self.spec.window_fit else _NONE
        if self._exported is not None:
            return _finite(np.asarray(self._exported(x, v, extra)))
        return _finite(np.asarray(_window_proba(self._structure, *self._args, x, v, extra)))

    def use_saved_program(self, folder: str | Path) -> bool:
        """Run :meth:`window_proba` from a program saved in ``folder``, saving it first if
        it is not there; a restarted process then skips tracing the features and networks.

        The program (:mod:`jax.export`, StableHLO with this model's numbers as constants)
        is keyed by those numbers, the feature structure and the JAX version, so another
        model, whisker or JAX never picks it up. Together with JAX's persistent compilation
        cache in the same folder, a restart loads instead of tracing and compiling.

        Returns:
            True when the program was loaded from ``folder``, False when it was saved now
            (or could not be: an unwritable folder only costs the saving).
        """
        folder = Path(folder)
        path = folder / f"window-proba-{self._program_key()}.jaxexport"
        try:
            exported = jax.export.deserialize(bytearray(path.read_bytes()))
            loaded = True
        # Absent, torn or from an incompatible writer: the file is only a cache of ours,
        # so whatever reading it raises, the program is traced once more and saved again.
        except Exception:
            x = jax.ShapeDtypeStruct(self.spec.window_shape, jnp.float64)
            v = jax.ShapeDtypeStruct((), jnp.float64)
            extra = jax.ShapeDtypeStruct(
                (self.spec.channels * N_WINDOW_FIT,) if self.spec.window_fit else (0,),
                jnp.float64,
            )
            fn = functools.partial(_window_proba, self._structure, *self._args)
            exported = jax.export.export(jax.jit(fn))(x, v, extra)
            loaded = False
            try:
                folder.mkdir(parents=True, exist_ok=True)
                atomic_write(path, bytes(exported.serialize()))
            except (OSError, ImportError):  # read-only folder, or no flatbuffers to write
                pass
        self._exported = jax.jit(exported.call)
        return loaded

    def _program_key(self) -> str:
        """Hash of everything the compiled window function depends on."""
        h = hashlib.sha256()
        for part in (jax.__version__, jax.lib.__version__, repr(self._structure),
                     str(jax.tree.structure(self._args)), self.spec.window_shape,
                     self.spec.window_fit):  # fmt: skip
            h.update(repr(part).encode())
        for leaf in jax.tree.leaves(self._args):
            a = np.asarray(leaf)
            h.update(f"{a.dtype}{a.shape}".encode())
            h.update(a.tobytes())
        return h.hexdigest()[:32]

    def classify_recording(self, rec: Recording, *, speed: float | None = None) -> dict:
        """Labels of every window of a recording, and one for the whole (mean probability).

        Each window's ``label`` and ``confidence`` fuse its context (``context_s``);
        ``window_label`` and ``window_confidence`` are the window's own. ``channel`` is the
        column classified: the model's, or a recording's only signal column whatever its
        name (an NPY recording's is ``signal``).
        """
        if self.spec.channels != 1:
            return self._classify_channels(rec, speed=speed)
        if self.channel is not None and self.channel not in rec.columns and len(rec.columns) > 1:
            raise RecordingError(
                f"{rec.source or 'recording'}: no column {self.channel!r}, the one the model "
                f"was trained on (columns: {list(rec.columns)}): rename the column, or "
                "train a model on one of these"
            )
        used = signal_column(rec, self.channel, only_column_ok=True)
        x = recording_signal(rec, used)
        check_rate(rec, self.rate_hz)
        w, starts = windows_of(rec.t, x, rate_hz=self.rate_hz, window=self.window, hop=self.hop)
        if len(w) == 0:
            raise RecordingError(
                f"{rec.source}: shorter than one window ({self.window / self.rate_hz:g} s)"
            )
        return self._label_windows(rec, w, starts, used, speed)

    def _classify_channels(self, rec: Recording, *, speed: float | None) -> dict:
        """:meth:`classify_recording` for a model of several channels."""
        names = self.channels
        if names is None or len(names) != self.spec.channels:
            raise ValueError(f"the model reads {self.spec.channels} channels but names {names}")
        xs = recording_signals(rec, names)
        check_rate(rec, self.rate_hz)
        w, starts = multi_windows(rec.t, xs, rate_hz=self.rate_hz, window=self.window,
                                  hop=self.hop)  # fmt: skip
        if len(w) == 0:
            raise RecordingError(
                f"{rec.source}: shorter than one window ({self.window / self.rate_hz:g} s)"
            )
        return self._label_windows(rec, w, starts, self.channel, speed)

    def _label_windows(self, rec, w, starts, used, speed) -> dict:
        if speed is None and self.needs_speed:
            speed = recording_speed(rec)
            if not np.isfinite(speed):
                raise RecordingError(
                    f"{rec.source}: the model needs the robot speed; add '# speed_mps: V' "
                    "to the recording or pass --speed"
                )
        # A window that is not the whisker gets no terrain, and no label fuses across it.
        faults, context = [], ModeContext()
        for x, s in zip(w, starts, strict=True):
            fault = self.window_health(x)
            if fault is not None and fault[0] != UNKNOWN:
                context.reset()  # a sensor fault: what follows is another signal
            else:  # an unknown window still counts for the mode over several
                why = context.check(x, s + self.window_s, self.window_s, self.health_in_use)
                fault = fault or (None if why is None else (UNKNOWN, why))
            faults.append(fault)
        good = np.array([f is None for f in faults])
        p = self.predict_proba(w[good], None if speed is None else np.full(good.sum(), speed))
        fused = self.fuse(p, np.cumsum(~good)[good], starts[good])
        own, idx = np.argmax(p, axis=1), np.argmax(fused, axis=1)
        windows, j = [], 0
        for i, fault in enumerate(faults):
            start = round(float(starts[i]), 6)
            if fault is not None:
                windows.append({"start_s": start, "label": fault[0], "confidence": 0.0,
                                "window_label": fault[0], "window_confidence": 0.0,
                                "reason": fault[1]})  # fmt: skip
                continue
            k = idx[j]
            windows.append({"start_s": start, "label": self.labels[k],
                            "confidence": round(float(fused[j, k]), 4),
                            "window_label": self.labels[own[j]],
                            "window_confidence": round(float(p[j, own[j]]), 4)})  # fmt: skip
            j += 1
        return {**_overall(self.labels, p, faults), "channel": used, "context_s": self.context_s,
                "fault_windows": int((~good).sum()), "windows": windows}  # fmt: skip

    # ----------------------------------------------------------------------- files
    def header(self) -> dict:
        """The JSON header of a model file."""
        return {
            "format": MODEL_FORMAT,
            "whiskerid_version": __version__,
            "features": self.spec.to_dict(),
            "rate_hz": self.rate_hz,
            "window": self.window,
            "window_s": self.window / self.rate_hz,
            "hop": self.hop,
            "context_s": self.context_s,
            "context": "a label fuses the windows that started up to context_s - window_s "
                       "before it (mean log-probability, renormalised)",
            "channel": self.channel,
            "labels": list(self.labels),
            **({"whisker": self.whisker.to_dict()} if self.whisker is not None else {}),
            "normalisation": {"mean": self.mean.tolist(), "std": self.std.tolist()},
            "network": {"sizes": self.net.sizes, "hidden_activation": "relu",
                        "output": "softmax", "members": len(self.nets),
                        "combine": "mean of the members' probabilities"},
            "training": self.info,
            **({"health": self.health.to_dict()} if self.health is not None else {}),
        }  # fmt: skip

    def save(self, path: str | Path) -> Path:
        """Write ``path/model.json`` and ``path/weights.npz``."""
        path = Path(path)
        if path.exists() and not path.is_dir():
            raise ValueError(f"{path} is a file; a model is a folder: give a folder name")
        arrays = {f"m{j}_{k}": a for j, n in enumerate(self.nets) for k, a in to_arrays(n).items()}
        with atomic_folder(path) as tmp:  # the two files appear together or not at all
            np.savez(tmp / MODEL_WEIGHTS, **arrays)
            (tmp / MODEL_JSON).write_text(json.dumps(self.header(), indent=2) + "\n")
        return path

    @classmethod
    def load(cls, path: str | Path) -> "ClassifierModel":
        """Read a model folder; refuses corrupt or incompatible files with a clear message."""
        path = Path(path)
        head_file = path / MODEL_JSON if path.is_dir() else path
        if not head_file.is_file():
            raise ModelError(
                f"{path}: no classifier model here (expected a folder with {MODEL_JSON})"
            )
        try:
            head = json.loads(head_file.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as err:
            raise ModelError(f"{head_file}: corrupt model header (not JSON: {err})") from None
        if not isinstance(head, dict) or head.get("format") != MODEL_FORMAT:
            got = head.get("format") if isinstance(head, dict) else None
            raise ModelError(
                f"{head_file}: incompatible model format {got!r}; this whiskerid "
                f"({__version__}) reads {MODEL_FORMAT!r}: retrain with 'whiskerid train'"
            )
        try:
            spec = FeatureSpec.from_dict(head["features"])
            labels = [str(s) for s in head["labels"]]
            mean = np.asarray(head["normalisation"]["mean"], dtype=float)
            std = np.asarray(head["normalisation"]["std"], dtype=float)
            sizes = [int(s) for s in head["network"]["sizes"]]
            hop = int(head["hop"])
            if hop < 1:
                raise ValueError(f"hop {hop} < 1")
            if len(set(labels)) != len(labels):
                raise ValueError(f"repeated labels {labels}")
            context_s = float(head.get("context_s", spec.window / spec.rate_hz))
            if not np.isfinite(context_s):
                raise ValueError(f"context_s {context_s}")
            members = int(head["network"].get("members", 1))
            if members < 1:
                raise ValueError(f"members {members} < 1")
        except (KeyError, TypeError, ValueError) as err:
            raise ModelError(f"{head_file}: corrupt model header ({err!r})") from None
        n = spec.n_features
        if sizes[0] != n or sizes[-1] != len(labels) or mean.shape != (n,) or std.shape != (n,):
            raise ModelError(
                f"{head_file}: inconsistent model (features {n}, network {sizes}, "
                f"{len(labels)} labels, normalisation {mean.shape})"
            )
        if not (np.isfinite(mean).all() and np.isfinite(std).all() and (std > 0).all()):
            raise ModelError(f"{head_file}: corrupt normalisation (non-finite or zero std)")
        weights = head_file.parent / MODEL_WEIGHTS
        try:
            with np.load(weights, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
            nets = []
            for j in range(members):
                prefix = f"m{j}_"
                mine = {k[len(prefix) :]: a for k, a in arrays.items() if k.startswith(prefix)}
                nets.append(from_arrays(mine, sizes))
            _check_weights(weights, arrays)
        except FileNotFoundError:
            raise ModelError(f"{weights}: missing model weights") from None
        except (ValueError, OSError, EOFError, zipfile.BadZipFile) as err:
            raise ModelError(f"{weights}: corrupt model weights ({err})") from None
        whisker = None
        if "whisker" in head:
            try:
                whisker = WhiskerResponse.from_dict(head["whisker"], spec.channels)
            except (KeyError, TypeError, ValueError) as err:
                raise ModelError(f"{head_file}: corrupt whisker in the header ({err})") from None
        health = None
        if "health" in head:
            try:
                health = HealthReference.from_dict(head["health"])
            except (KeyError, TypeError, ValueError) as err:
                raise ModelError(f"{head_file}: corrupt health reference ({err})") from None
        try:
            return cls(spec, labels, mean, std, nets, hop=hop, channel=head.get("channel"),
                       info=head.get("training", {}), context_s=context_s,
                       whisker=whisker, health=health)  # fmt: skip
        except ValueError as err:
            raise ModelError(f"{head_file}: corrupt model header ({err})") from None


def recording_hashes(paths) -> list[str]:
    """SHA-256 of each recording file that exists (what a model remembers of its training
    data: the content, whatever the file is called later)."""
    return [sha256_of(p) for p in map(Path, paths) if p.is_file()]


def trained_on(model: ClassifierModel, paths) -> list[str]:
    """The ones among ``paths`` whose content trained ``model`` (by SHA-256)."""
    known = set(model.info.get("recordings_sha256", []))
    if not known:
        return []
    return [str(p) for p in map(Path, paths) if p.is_file() and sha256_of(p) in known]


#: Largest weight a trained network holds (weight decay keeps them of order one); beyond
#: it the float32 logits overflow and every probability comes out NaN.
MAX_WEIGHT = 1e6


def _check_weights(path: Path, arrays: dict) -> None:
    for name, a in arrays.items():
        a = np.asarray(a, dtype=float)
        if not np.isfinite(a).all():
            raise ModelError(f"{path}: weights {name} are not finite: the file is corrupt; "
                             "retrain with 'whiskerid train'")  # fmt: skip
        if a.size and np.max(np.abs(a)) > MAX_WEIGHT:
            raise ModelError(
                f"{path}: weights {name} reach {np.max(np.abs(a)):.3g} (a trained network's "
                f"stay below {MAX_WEIGHT:g}): the file is corrupt; retrain with 'whiskerid train'"
            )


def _overall(labels, p: np.ndarray, faults: list) -> dict:
    """The whole recording's label: the mean probability of the windows fit to classify;
    when none is, the commonest fault, with its first reason."""
    if len(p):
        mean = p.mean(axis=0)
        return {"label": labels[int(np.argmax(mean))], "confidence": float(mean.max())}
    kinds = [f[0] for f in faults]
    label = max(set(kinds), key=kinds.count)
    return {"label": label, "confidence": 0.0,
            "reason": next(f[1] for f in faults if f[0] == label)}  # fmt: skip


#: No host-computed features: one device-resident empty row, reused by every call.
_NONE = jnp.zeros((0,))


def _finite(p: np.ndarray) -> np.ndarray:
    """Class probabilities, refused when any is not finite (no label can be read from them)."""
    if not np.isfinite(p).all():
        raise ModelError(
            "the model's class probabilities are not finite (overflowing weights or "
            "normalisation, or non-finite samples): no label can be given; retrain the model "
            "or check the recording"
        )
    return p
