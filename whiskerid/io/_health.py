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
  the electronics, not the ground. Nor does noise show a **response near the whisker's
  mode** (its calibrated f1, or the training windows' resonance): the mode check of
  :mod:`whiskerid.io._health_modes`.

Noise-likeness is measured by the spectral flatness (geometric over arithmetic mean of the
periodogram of the Hann-tapered window, mean removed): 1 for a flat spectrum, about
``e^-γ ≈ 0.56`` on average for one window of white noise, far lower for a resonance. A
window at least as flat as all but :data:`NOISE_QUANTILE` of white-noise windows of its
length is noise-like, a check left off for a model whose own training windows are
noise-like too often. The level (median) and the amplitude (RMS) are compared with the
training windows' ranges, widely (:data:`LEVEL_MARGIN`, :data:`RMS_MARGIN`): a new
recording may be quieter or rougher than any trained on, and the sampling chain of a
deployment (another ADC rate, its filter) reshapes the spectrum's details, so they are not
compared. The checks are NumPy only: one FFT per window. A window that passes them may
still be a ground the model never saw; the network's confidence is then the only guide.
"""

import functools
from dataclasses import dataclass, replace

import numpy as np

from ._health_context import CONTEXT_TRAIN_QUANTILE, context_prominence, white_context
from ._health_modes import mode_prominence, training_modes, white_detection, white_prominence

SENSOR_FAULT = "sensor-fault"
UNKNOWN = "unknown"

#: A run of identical samples this long (share of the window) is a stuck reading.
STUCK_FRACTION = 0.25
#: A window as flat in spectrum as all but this share of white-noise windows is noise-like.
NOISE_QUANTILE = 0.001
#: Noise-like training windows beyond this share: the model was trained on windows that
#: look like noise, so it cannot call noise unknown (the noise check is left off).
NOISE_TRAIN_LIMIT = 0.01
#: The mode threshold is at most the prominence this share of training windows stay below.
MODE_TRAIN_QUANTILE = 0.005
#: The mode check is kept only while its threshold catches this share of white noise.
MIN_NOISE_CAUGHT = 0.9
#: An amplitude (RMS) more than this factor beyond every training window's is far outside
#: training: wide, since a new recording may be quieter or rougher than any trained on.
RMS_MARGIN = 10.0
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
    """log10 RMS and log10 spectral flatness of each window, shape ``(n, channels × 2)``
    (per channel, in that order; the mean removed, a Hann taper applied)."""
    w = np.asarray(windows, dtype=float)
    if w.ndim == 2:
        w = w[:, None, :]
    d = w - w.mean(axis=-1, keepdims=True)
    tiny = np.finfo(float).tiny
    rms = np.sqrt(np.mean(d**2, axis=-1))
    p = np.abs(np.fft.rfft(d * np.hanning(w.shape[-1]), axis=-1))[..., 1:] ** 2 + tiny
    flat = np.exp(np.mean(np.log(p), axis=-1)) / np.mean(p, axis=-1)
    return np.stack([np.log10(rms + tiny), np.log10(flat)], axis=-1).reshape(len(w), -1)


@dataclass(frozen=True)
class HealthReference:
    """What the training windows looked like, for the ``unknown`` check.

    Attributes:
        level: Lowest and highest training window median, per channel, shape
            ``(channels, 2)``.
        log_rms: Lowest and highest log10 RMS of a training window, per channel, shape
            ``(channels, 2)``.
        noise_flatness: log10 spectral flatness at or above which a window is
            noise-like (:func:`white_flatness`); None when the training windows were
            themselves noise-like too often (:data:`NOISE_TRAIN_LIMIT`).
        train_rejection: Share of the training windows these checks reject.
        rate_hz: Sample rate of the windows (Hz), for the mode check; None: no mode check.
        modes_hz: Where the whisker's response stands out (Hz, below Nyquist): the
            calibrated whisker's mode, or the training windows' resonance
            (:mod:`whiskerid.io._health_modes`).
        mode_floor: Mode prominence (log10) a window must reach in some channel: white
            noise's 99.9 % quantile (:func:`white_prominence`), or the training windows'
            :data:`MODE_TRAIN_QUANTILE` quantile where lower; None when the check is off
            (no rate, or a threshold that catches less than :data:`MIN_NOISE_CAUGHT` of
            white noise).
        mode_noise_caught: Share of white-noise windows below ``mode_floor``.
        context_floor: Mode prominence (log10) the mean periodogram of the last few
            windows must reach: the training windows' weakest stretches
            (:mod:`whiskerid.io._health_context`); None: no such check.
        rms_gain: On another whisker, the factor its response puts on the amplitude range
            (the range then applies without ``ranges``); None: no such scaling.
        ranges: Whether the level and amplitude ranges apply (not on another whisker,
            whose offset and gain differ: :meth:`for_whisker`).
    """

    level: np.ndarray
    log_rms: np.ndarray
    noise_flatness: float | None = None
    train_rejection: float = 0.0
    rate_hz: float | None = None
    modes_hz: tuple[float, ...] = ()
    mode_floor: float | None = None
    ranges: bool = True
    mode_noise_caught: float | None = None
    rms_gain: float | None = None
    context_floor: float | None = None

    @classmethod
    def fit(cls, windows, labels=None, *, rate_hz: float | None = None,
            modes_hz=None, groups=None) -> "HealthReference":  # fmt: skip
        """The reference of training windows ``(n, [channels,] window)``; sensor-fault
        windows among them are left out. ``labels`` is accepted for symmetry and unused.
        With ``rate_hz``, the mode check is set up at ``modes_hz`` (the calibrated
        whisker's; by default the training windows' own resonance, :func:`training_modes`),
        and over consecutive windows of one recording (``groups``, each window's; None:
        one recording) the context threshold."""
        w = np.asarray(windows, dtype=float)
        keep = np.array([sensor_fault(x) is None for x in w])
        groups = np.zeros(len(w), int) if groups is None else np.asarray(groups)[keep]
        w = w[keep]
        chans = w if w.ndim == 3 else w[:, None, :]
        d = descriptors(w).reshape(len(w), chans.shape[1], 2)
        level = np.median(chans, axis=-1)
        noise = white_flatness(w.shape[-1])
        noisy = np.all(d[..., 1] >= noise, axis=1)
        ref = cls(np.stack([level.min(0), level.max(0)], axis=1),
                  np.stack([d[..., 0].min(0), d[..., 0].max(0)], axis=1),
                  noise if np.mean(noisy) <= NOISE_TRAIN_LIMIT else None)  # fmt: skip
        if rate_hz is not None:
            modes = tuple(float(f) for f in (modes_hz or training_modes(w, rate_hz)))
            prom = np.max(mode_prominence(w, rate_hz, modes), axis=1)
            # White noise's 99.9 % quantile, lowered where the training windows' own
            # weakest reach below it (slow runs over soft ground excite the mode little):
            # kept while it still catches most white noise.
            floor = min(white_prominence(w.shape[-1], float(rate_hz), modes),
                        float(np.quantile(prom, MODE_TRAIN_QUANTILE, method="lower")))  # fmt: skip
            caught = white_detection(w.shape[-1], float(rate_hz), modes, floor)
            ref = replace(ref, rate_hz=float(rate_hz), modes_hz=modes,
                          mode_floor=floor if caught >= MIN_NOISE_CAUGHT else None,
                          mode_noise_caught=caught)  # fmt: skip
            ctx = np.max(context_prominence(w, rate_hz, modes, groups), axis=1)
            if ctx.size and ref.mode_floor is not None:
                # The weakest stretches of training, kept where white noise stays below.
                cfloor = float(np.quantile(ctx, CONTEXT_TRAIN_QUANTILE, method="lower"))
                if cfloor > white_context(w.shape[-1], float(rate_hz), modes):
                    ref = replace(ref, context_floor=cfloor)
        rejected = np.mean([ref.out_of_range(x) is not None for x in w])
        return replace(ref, train_rejection=float(rejected))

    def out_of_range(self, x) -> str | None:
        """Why a window lies outside what the model was trained on, or None."""
        chans = _channels(x)
        d = descriptors(chans[None])[0].reshape(len(chans), 2)
        flat = d[:, 1]
        if self.noise_flatness is not None and np.all(flat >= self.noise_flatness):
            return (f"noise-like: spectral flatness {10 ** flat.min():.2f}, as flat as white "
                    f"noise's (>= {10**self.noise_flatness:.2f}; the training windows' "
                    "resonances stay below): a dead sensor's electrical noise, or no whisker "
                    "signal")  # fmt: skip
        if self.mode_floor is not None:
            prom = mode_prominence(chans[None], self.rate_hz, self.modes_hz)[0]
            if np.all(prom < self.mode_floor):
                modes = ", ".join(f"{f:.1f}" for f in self.modes_hz)
                return (f"no whisker response: nothing stands out near its mode ({modes} Hz; "
                        f"{10 ** prom.max():.2g}x the local floor, white noise reaches "
                        f"{10**self.mode_floor:.2g}x): a dead sensor, or no whisker "
                        "signal")  # fmt: skip
        if not self.ranges and self.rms_gain is None:
            return None
        for k, c in enumerate(chans):
            where = "" if len(chans) == 1 else f"channel {k}: "
            lo, hi = self.level[k]
            rms_lo, rms_hi = 10.0 ** self.log_rms[k] * (self.rms_gain or 1.0)
            margin = LEVEL_MARGIN * ((hi - lo) + rms_hi)
            med = float(np.median(c))
            if self.ranges and not lo - margin <= med <= hi + margin:
                return (f"{where}level {med:.4g} far outside training's {lo:.4g}..{hi:.4g} "
                        "(another sensor, gain or unit?)")  # fmt: skip
            rms = 10.0 ** d[k, 0]
            if (self.ranges or self.rms_gain) and not (rms_lo / RMS_MARGIN <= rms
                                                       <= rms_hi * RMS_MARGIN):  # fmt: skip
                return (f"{where}amplitude {rms:.3g} RMS, more than {RMS_MARGIN:g}x outside "
                        f"training's {rms_lo:.3g}..{rms_hi:.3g} (another sensor, gain or "
                        "unit?)")  # fmt: skip
        return None

    def to_dict(self) -> dict:
        """JSON-ready form (for the model header)."""
        return {
            "level": self.level.tolist(),
            "log_rms": self.log_rms.tolist(),
            "noise_flatness": self.noise_flatness,
            "train_rejection": self.train_rejection,
            "rate_hz": self.rate_hz,
            "modes_hz": list(self.modes_hz),
            "mode_floor": self.mode_floor,
            "mode_noise_caught": self.mode_noise_caught,
            "context_floor": self.context_floor,
        }

    def for_whisker(self, gain: float | None = None) -> "HealthReference":
        """This reference for windows of another calibrated whisker: the noise check, which
        holds for any whisker, and with ``gain`` (that whisker's response over the training
        whisker's, :func:`gain_ratio`) the amplitude range scaled by it.

        The level range is the training whisker's (another has its own offset), and so is
        the mode threshold: a stiffer whisker responds less (deflection per base
        acceleration ∝ 1/f1²), and at f1 × 1.3 the simulated set's slow runs over soft
        ground put 4 % of clean windows below it at that whisker's mode
        (``benchmarks/window_health.py``)."""
        return replace(self, mode_floor=None, context_floor=None, ranges=False, rms_gain=gain)

    @classmethod
    def from_dict(cls, d: dict) -> "HealthReference":
        """Read :meth:`to_dict`'s form; raises ValueError/KeyError/TypeError when corrupt."""
        noise, rate, floor = d.get("noise_flatness"), d.get("rate_hz"), d.get("mode_floor")
        ref = cls(np.asarray(d["level"], float), np.asarray(d["log_rms"], float),
                  None if noise is None else float(noise),
                  float(d.get("train_rejection", 0.0)),
                  None if rate is None else float(rate),
                  tuple(float(f) for f in d.get("modes_hz", ())),
                  None if floor is None else float(floor))  # fmt: skip
        if (caught := d.get("mode_noise_caught")) is not None:
            ref = replace(ref, mode_noise_caught=float(caught))
        if (cfloor := d.get("context_floor")) is not None:
            if ref.mode_floor is None:
                raise ValueError("a context threshold without a mode threshold")
            ref = replace(ref, context_floor=float(cfloor))
        if ref.mode_floor is not None and not (ref.rate_hz and ref.modes_hz):
            raise ValueError("a mode threshold without its rate or modes")
        if not all(0 < f < (ref.rate_hz or np.inf) / 2 for f in ref.modes_hz):
            raise ValueError(f"modes {ref.modes_hz} outside 0..Nyquist")
        if ref.level.ndim != 2 or ref.level.shape != ref.log_rms.shape or ref.level.shape[1] != 2:
            raise ValueError("inconsistent health reference shapes")
        if not (np.isfinite(ref.level).all() and np.isfinite(ref.log_rms).all()):
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
