"""Is a window the whisker at all? Checks run before any terrain is given.

A classifier names one of its terrains for whatever it is fed: a dead sensor's electrical
noise, a chip toggling between two codes or a stuck reading all come out as some terrain,
often with a confidence near one, because the network was never shown anything else. Every
window is therefore checked first, offline (``classify``) and online (``stream``) alike, by
:func:`window_health`:

* **sensor faults** (label ``sensor-fault``), which no working sensor produces whatever the
  ground: samples that are not finite; a reading stuck at one value for a quarter of the
  window or more (a frozen chip, a pinned ADC at full scale); a window holding two distinct
  values or fewer (a chip toggling between two codes, a disconnected input);
* **out of distribution** (label ``unknown``): a window whose level, amplitude or spectral
  shape lies far from every window the model was trained on (:class:`HealthReference`,
  kept in the model file). A whisker dragged over ground rings at its modes, so its
  spectrum is shaped by them; electrical noise alone has a flat spectrum at a level set by
  the electronics, not the ground.

The spectral shape is described by a few numbers per channel (:func:`descriptors`): the
log amplitude (RMS), the spectral flatness (geometric over arithmetic mean of the
periodogram, 1 for a flat spectrum, about ``e^-γ ≈ 0.56`` for one window of white noise,
far lower for a resonance), and the share of power in each of ten equal bands up to Nyquist.
A window's score is its Mahalanobis distance, under the training windows' within-class
covariance, to the nearest class mean of these numbers; it is ``unknown`` above the
threshold chosen on the training windows (:data:`TRAIN_QUANTILE` of their scores, widened by
:data:`THRESHOLD_MARGIN`). The numbers are NumPy only: the check costs one FFT per window.
"""

import functools
import itertools
from dataclasses import dataclass

import numpy as np

SENSOR_FAULT = "sensor-fault"
UNKNOWN = "unknown"

#: A run of identical samples this long (share of the window) is a stuck reading.
STUCK_FRACTION = 0.25
#: Equal bands from DC to Nyquist whose power shares describe the spectrum: fine enough
#: to place the whisker's first mode and the sampling chain's roll-off near Nyquist.
N_BANDS = 10
#: Quantile of the training windows' scores the threshold starts from.
TRAIN_QUANTILE = 0.999
#: Factor on that quantile: the training windows set it, new recordings of the same
#: grounds spread a little wider (held-out recordings, not training ones, measure what it
#: rejects; see the classify guide).
THRESHOLD_MARGIN = 1.5
#: A window as flat in spectrum as all but this share of white-noise windows is noise-like.
NOISE_QUANTILE = 0.001
#: Noise-like training windows beyond this share: the model was trained on windows that
#: look like noise, so it cannot call noise unknown (the noise check is left off).
NOISE_TRAIN_LIMIT = 0.01
#: A level (median) beyond the training levels by this many times their range plus
#: typical RMS is far outside training.
LEVEL_MARGIN = 10.0


def _channels(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return x[None] if x.ndim == 1 else x


def sensor_fault(x) -> str | None:
    """Why a window (``(window,)`` or ``(channels, window)``) cannot come from a working
    sensor, whatever the ground; None when it could."""
    for k, c in enumerate(_channels(x)):
        where = "" if np.ndim(x) == 1 else f"channel {k}: "
        if not np.all(np.isfinite(c)):
            return f"{where}not-finite samples"
        values = np.unique(c)
        if values.size == 1:
            return f"{where}flat: every sample is {c[0]:g} (stuck chip, sensor off?)"
        if values.size == 2:
            return (f"{where}toggling between two values ({values[0]:g}, {values[1]:g}): "
                    "a chip or input fault, not a whisker")  # fmt: skip
        run = _longest_run(c)
        if run >= max(STUCK_FRACTION * c.size, 3):
            return (f"{where}stuck: {run} of {c.size} samples in a row read the same value "
                    "(frozen chip, or pinned at full scale?)")  # fmt: skip
    return None


def _longest_run(c: np.ndarray) -> int:
    """Length of the longest run of equal consecutive samples."""
    change = np.flatnonzero(np.diff(c) != 0)
    edges = np.concatenate([[-1], change, [c.size - 1]])
    return int(np.max(np.diff(edges)))


def descriptors(windows) -> np.ndarray:
    """The spectral-shape numbers of each window, shape ``(n, channels × (2 + N_BANDS))``:
    per channel log10 RMS, log10 spectral flatness and log10 power share of each of
    :data:`N_BANDS` equal bands up to Nyquist (the mean removed, a Hann taper applied)."""
    w = np.asarray(windows, dtype=float)
    if w.ndim == 2:
        w = w[:, None, :]
    d = w - w.mean(axis=-1, keepdims=True)
    rms = np.sqrt(np.mean(d**2, axis=-1))
    p = np.abs(np.fft.rfft(d * np.hanning(w.shape[-1]), axis=-1))[..., 1:] ** 2
    tiny = np.finfo(float).tiny
    p = p + tiny
    flat = np.exp(np.mean(np.log(p), axis=-1)) / np.mean(p, axis=-1)
    edges = _band_edges(p.shape[-1])
    total = p.sum(axis=-1)
    share = np.stack([p[..., a:b].sum(axis=-1) / total for a, b in edges], axis=-1)
    out = np.concatenate([np.log10(rms + tiny)[..., None], np.log10(flat)[..., None],
                          np.log10(share + 1e-12)], axis=-1)  # fmt: skip
    return out.reshape(len(w), -1)


def _band_edges(n_bins: int) -> list[tuple[int, int]]:
    """Bin ranges of :data:`N_BANDS` equal bands (DC excluded; at least one bin each)."""
    tops = np.linspace(0, n_bins, N_BANDS + 1).round().astype(int)
    return [(min(a, n_bins - 1), max(b, a + 1)) for a, b in itertools.pairwise(tops)]


@dataclass(frozen=True)
class HealthReference:
    """What the training windows looked like, for the ``unknown`` check.

    Attributes:
        centres: Each class's mean descriptors, shape ``(classes, d)``.
        precision: Inverse of the within-class covariance of the descriptors (shrunk
            towards its diagonal so that it inverts), shape ``(d, d)``.
        threshold: Score above which a window is ``unknown``.
        level: Lowest and highest training window median, per channel, shape
            ``(channels, 2)``.
        rms: Median training window RMS per channel, shape ``(channels,)``.
        train_rejection: Share of the training windows the threshold rejects.
        noise_flatness: log10 spectral flatness at or above which a window is
            noise-like (:func:`white_flatness`); None when the training windows were
            themselves noise-like too often (:data:`NOISE_TRAIN_LIMIT`).
    """

    centres: np.ndarray
    precision: np.ndarray
    threshold: float
    level: np.ndarray
    rms: np.ndarray
    train_rejection: float = 0.0
    noise_flatness: float | None = None

    @classmethod
    def fit(cls, windows, labels) -> "HealthReference":
        """The reference of training windows ``(n, [channels,] window)`` and their class
        indices ``(n,)``. Sensor-fault windows among them are left out."""
        w = np.asarray(windows, dtype=float)
        labels = np.asarray(labels)
        ok = np.array([sensor_fault(x) is None for x in w])
        w, labels = w[ok], labels[ok]
        d = descriptors(w)
        classes = np.unique(labels)
        centres = np.stack([d[labels == c].mean(axis=0) for c in classes])
        resid = d - centres[np.searchsorted(classes, labels)]
        cov = resid.T @ resid / max(len(d) - len(classes), 1)
        # Shrunk towards the diagonal (a fifth) plus a floor: a descriptor that barely
        # varies in training (one speed, one gain) must not make every new window unknown.
        diag = np.diag(np.diag(cov)) + 1e-4 * np.eye(len(cov))
        precision = np.linalg.inv(0.8 * cov + 0.2 * diag + 1e-4 * np.eye(len(cov)))
        chans = w if w.ndim == 3 else w[:, None, :]
        level = np.median(chans, axis=-1)
        ref = cls(centres, precision, 0.0, np.stack([level.min(0), level.max(0)], axis=1),
                  np.median(np.std(chans, axis=-1), axis=0))  # fmt: skip
        scores = ref.scores(w)
        threshold = THRESHOLD_MARGIN * float(np.quantile(scores, TRAIN_QUANTILE))
        noise = white_flatness(w.shape[-1])
        noisy = np.all(d[:, 1 :: 2 + N_BANDS] >= noise, axis=1)
        noise = noise if np.mean(noisy) <= NOISE_TRAIN_LIMIT else None
        rejected = float(np.mean((scores > threshold) | (noisy if noise is not None else False)))
        return cls(ref.centres, ref.precision, threshold, ref.level, ref.rms, rejected, noise)

    def scores(self, windows) -> np.ndarray:
        """Each window's distance to the nearest class (see the module docstring)."""
        d = descriptors(windows)
        diff = d[:, None, :] - self.centres[None]
        m = np.einsum("nci,ij,ncj->nc", diff, self.precision, diff)
        return np.sqrt(np.maximum(m.min(axis=1), 0.0))

    def out_of_range(self, x) -> str | None:
        """Why a window lies outside what the model was trained on, or None."""
        chans = _channels(x)
        for k, c in enumerate(chans):
            lo, hi = self.level[k]
            margin = LEVEL_MARGIN * ((hi - lo) + self.rms[k])
            med = float(np.median(c))
            if not lo - margin <= med <= hi + margin:
                return (f"level {med:.4g} far outside training's {lo:.4g}..{hi:.4g} "
                        "(another sensor, gain or unit?)")  # fmt: skip
        d = descriptors(chans[None] if chans.shape[0] > 1 else chans)[0]
        flat = d[1 :: 2 + N_BANDS]
        if self.noise_flatness is not None and np.all(flat >= self.noise_flatness):
            return (f"noise-like: spectral flatness {10 ** flat.min():.2f}, as flat as white "
                    f"noise's (>= {10**self.noise_flatness:.2f}; the training windows' "
                    "resonances stay below): a dead sensor's electrical noise, or no whisker "
                    "signal")  # fmt: skip
        score = float(self.scores(chans[None] if chans.shape[0] > 1 else chans)[0])
        if score > self.threshold:
            return (
                f"unlike the training data: spectral shape and amplitude score "
                f"{score:.3g} > {self.threshold:.3g} (noise-like or not the whisker?)"
            )
        return None

    def to_dict(self) -> dict:
        """JSON-ready form (for the model header)."""
        return {
            "descriptors": "per channel: log10 rms, log10 spectral flatness, log10 power "
                           f"share of {N_BANDS} equal bands up to Nyquist",
            "centres": self.centres.tolist(),
            "precision": self.precision.tolist(),
            "threshold": self.threshold,
            "level": self.level.tolist(),
            "rms": self.rms.tolist(),
            "train_rejection": self.train_rejection,
            "noise_flatness": self.noise_flatness,
        }  # fmt: skip

    @classmethod
    def from_dict(cls, d: dict) -> "HealthReference":
        """Read :meth:`to_dict`'s form; raises ValueError/KeyError/TypeError when corrupt."""
        noise = d.get("noise_flatness")
        ref = cls(np.asarray(d["centres"], float), np.asarray(d["precision"], float),
                  float(d["threshold"]), np.asarray(d["level"], float),
                  np.asarray(d["rms"], float), float(d.get("train_rejection", 0.0)),
                  None if noise is None else float(noise))  # fmt: skip
        n = ref.centres.shape[-1]
        if ref.centres.ndim != 2 or ref.precision.shape != (n, n) or ref.level.ndim != 2:
            raise ValueError("inconsistent health reference shapes")
        arrays = (ref.centres, ref.precision, ref.level, ref.rms)
        if not (all(np.isfinite(a).all() for a in arrays) and ref.threshold > 0):
            raise ValueError("non-finite health reference")
        return ref


@functools.lru_cache(maxsize=8)
def white_flatness(n: int) -> float:
    """log10 spectral flatness that all but :data:`NOISE_QUANTILE` of white-noise windows
    of ``n`` samples reach (Monte Carlo, fixed seed; about -0.38 for 200 samples, where a
    single periodogram's expected value is log10 e^-γ ≈ -0.25)."""
    x = np.random.default_rng(0).standard_normal((20_000, n))
    return float(np.quantile(descriptors(x)[:, 1], NOISE_QUANTILE))


def window_health(x, reference: HealthReference | None = None) -> tuple[str, str] | None:
    """``(label, reason)`` when a window must not be given a terrain, else None.

    Args:
        x: One window, ``(window,)`` or ``(channels, window)``, in the units the model
            was trained on.
        reference: The training data's :class:`HealthReference` (a model file's); None
            (models written before it) checks sensor faults only.

    Returns:
        ``("sensor-fault", why)`` for a signal no working sensor gives, ``("unknown",
        why)`` for one unlike the training data, None for a window fit to classify.
    """
    why = sensor_fault(x)
    if why is not None:
        return SENSOR_FAULT, why
    if reference is not None and (why := reference.out_of_range(x)) is not None:
        return UNKNOWN, why
    return None
