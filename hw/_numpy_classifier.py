"""A trained classifier run in NumPy: the stream's labels without JAX.

Importing JAX, equinox and the classifier package costs about a CPU second, and loading the
model's compiled program up to another on a busy machine: most of the stream's start. A
model whose features NumPy computes (:func:`whiskerid.hw._numpy_features.unsupported`: the
default ``fitted`` features, with or without speed, and the ``paper`` ones, one channel) is
run here instead: the same window checks (:func:`whiskerid.classify.window_health`, NumPy
already), the features in float64, then, as the compiled path does, the standardisation and
the ensemble's ReLU networks in float32 and the mean of their softmax probabilities. The
weights are read from the model file's ``weights.npz`` (``allow_pickle=False``) and its
``model.json``. Any model this cannot run, or a file it cannot read, goes to
:class:`whiskerid.ClassifierModel`, which also gives a corrupt file its error message.
"""

import itertools
import json
from pathlib import Path

import numpy as np

from ..io._context import check_context
from ..io._health import HealthReference, window_health
from ._live import MAX_SPEED_MPS
from ._numpy_features import SPEC_DEFAULTS, unsupported, window_features

#: The model file format this reads (:data:`whiskerid.classify._model_file.MODEL_FORMAT`).
MODEL_FORMAT = "whiskerid.classifier/2"


class NumpyClassifier:
    """What :class:`whiskerid.hw.OnlineClassifier` asks of a model, in NumPy.

    Attributes: ``labels``, ``rate_hz``, ``window``, ``window_s``, ``context_s``,
    ``lookback_s``, ``needs_speed``, ``channel``, ``spec`` (the header's feature settings,
    defaults filled in) and ``engine`` ("numpy").
    """

    engine = "numpy"

    def __init__(self, head: dict, arrays: dict[str, np.ndarray]):
        self.spec = {**SPEC_DEFAULTS, **head["features"]}
        self.labels = tuple(str(s) for s in head["labels"])
        self.mean = np.asarray(head["normalisation"]["mean"], dtype=np.float32)
        self.std = np.asarray(head["normalisation"]["std"], dtype=np.float32)
        self.channel = head.get("channel")
        self.rate_hz = float(self.spec["rate_hz"])
        self.window = int(self.spec["window"])
        self.window_s = self.window / self.rate_hz
        self.context_s = check_context(float(head.get("context_s", self.window_s)),
                                       self.window_s)  # fmt: skip
        self.lookback_s = max(self.context_s - self.window_s, 0.0)
        self.needs_speed = self.spec["kind"] == "fitted" and bool(self.spec["use_speed"])
        self.health = (HealthReference.from_dict(head["health"]) if "health" in head
                       else None)  # fmt: skip
        sizes = [int(s) for s in head["network"]["sizes"]]
        members = int(head["network"].get("members", 1))
        self.nets = [[(np.asarray(arrays[f"m{j}_W{i}"], np.float32),
                       np.asarray(arrays[f"m{j}_b{i}"], np.float32))
                      for i in range(len(sizes) - 1)] for j in range(members)]  # fmt: skip
        for j, net in enumerate(self.nets):
            for i, ((w, b), (a, c)) in enumerate(zip(net, itertools.pairwise(sizes), strict=True)):
                values = np.abs(np.concatenate([w.ravel(), b.ravel()]))
                # Non-finite or beyond a trained network's (MAX_WEIGHT in the model file
                # module): the compiled path refuses the file with its message.
                if w.shape != (c, a) or b.shape != (c,) or not np.all(values <= 1e6):
                    raise ValueError(f"m{j}_W{i}/b{i}: shape {w.shape} or values")
        n = window_features(self.spec, np.zeros(self.window), 1.0).shape[0]
        if not (sizes[0] == n == self.mean.size == self.std.size and sizes[-1] == len(self.labels)):
            raise ValueError(f"{n} features, network {sizes}, {len(self.labels)} labels")
        if not (np.isfinite(self.std).all() and (self.std > 0).all()):
            raise ValueError("non-finite or zero normalisation")

    def window_health(self, samples) -> tuple[str, str] | None:
        """``(label, reason)`` when the window gets no terrain (as the JAX model's)."""
        return window_health(samples, self.health)

    @property
    def health_in_use(self):
        """The health reference the windows are checked against (the model file's)."""
        return self.health

    def window_proba(self, samples, speed: float | None = None) -> np.ndarray:
        """Class probabilities of one window, shape ``(classes,)`` (float32)."""
        x = np.asarray(samples, dtype=np.float64)
        if x.shape != (self.window,):
            raise ValueError(f"a window has {self.window} samples, got shape {x.shape}")
        if self.needs_speed and not (speed is not None and 0 < speed <= MAX_SPEED_MPS):
            raise ValueError(f"this model needs a robot speed in (0, {MAX_SPEED_MPS:g}] m/s, "
                             f"got {speed!r}")  # fmt: skip
        v = np.nan if speed is None else float(speed)
        feats = window_features(self.spec, x, v).astype(np.float32)
        z = (feats - self.mean) / self.std
        with np.errstate(over="ignore", invalid="ignore"):
            return sum(_softmax(_forward(net, z)) for net in self.nets) / np.float32(len(self.nets))


def _forward(net, z: np.ndarray) -> np.ndarray:
    """Logits of one ReLU network (equinox's ``Linear``: ``W @ x + b``)."""
    for w, b in net[:-1]:
        z = np.maximum(w @ z + b, np.float32(0))
    w, b = net[-1]
    return w @ z + b


def _softmax(y: np.ndarray) -> np.ndarray:
    e = np.exp(y - np.max(y))
    return e / np.sum(e)


def load_numpy_classifier(path: str | Path) -> tuple[NumpyClassifier | None, str]:
    """The model at ``path`` as a :class:`NumpyClassifier`, or None and why it needs JAX
    (features NumPy does not compute, or a file this does not read: the JAX path then
    loads it, and refuses a corrupt one with its own message)."""
    path = Path(path)
    head_file = path / "model.json" if path.is_dir() else path
    try:
        head = json.loads(head_file.read_text())
        if head.get("format") != MODEL_FORMAT:
            return None, f"model format {head.get('format')!r}"
        if (why := unsupported(head["features"])) is not None:
            return None, why
        with np.load(head_file.parent / "weights.npz", allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        return NumpyClassifier(head, arrays), ""
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
        return None, f"model file not read here ({type(e).__name__}: {e})"
