"""The mode check over the last few windows together: :class:`ModeContext`.

One window of 1 s resolves the spectrum to 1 Hz with two degrees of freedom a bin, and there
noise coloured by a filter can look like the whisker's weakest response: a moving average of
white noise over 20 samples at 200 Hz has a sidelobe between its nulls at 40 and 50 Hz,
right on a 46 Hz mode, and a 1 s window of it stands out there as much as a slow run over
soft ground does in one window in two hundred. Over several windows the periodograms average
(the spread of the prominence shrinks as 1/√k) while the whisker's response stays where it
is: the training windows' weakest three seconds stand well above what such noise reaches on
average. So the mode prominence (:func:`whiskerid.io._health_modes.mode_prominence`) of the
mean periodogram of the last :data:`CONTEXT_WINDOWS` windows must reach the training
windows' weakest (:attr:`HealthReference.context_floor`: the weakest three windows in a row
of any training recording): weaker is a stretch unlike any the model was trained on. Windows
refused by the single-window checks as ``unknown`` count in the stretch (a dead input's own
refusals must not hide it); a sensor fault starts it afresh. The check starts once that many
windows follow one another; before, the single-window checks alone apply.
"""

import collections
import functools

import numpy as np

from ._health_modes import _periodogram, _prominence

#: How many consecutive windows the mode is judged over.
CONTEXT_WINDOWS = 3
#: The context threshold is this quantile of the training windows' context prominence
#: (0: the weakest three windows in a row of any training recording).
CONTEXT_TRAIN_QUANTILE = 0.0


def context_prominence(windows, rate_hz: float, modes_hz, groups=None,
                       k: int = CONTEXT_WINDOWS) -> np.ndarray:  # fmt: skip
    """Mode prominence of the mean periodogram of every ``k`` consecutive windows within
    a group (a recording), shape ``(m, channels)``.

    Args:
        windows: ``(n, window)`` or ``(n, channels, window)``, in time order per group.
        rate_hz: Sample rate (Hz).
        modes_hz: Mode frequencies (Hz).
        groups: Recording of each window, shape ``(n,)``; None: one recording.
        k: Windows per stretch.
    """
    w = np.asarray(windows, dtype=float)
    p = _periodogram(w)
    p = p[:, None, :] if p.ndim == 2 else p
    g = np.zeros(len(w), int) if groups is None else np.asarray(groups)
    starts = [i for i in range(len(w) - k + 1) if np.all(g[i : i + k] == g[i])]
    if not starts:
        return np.zeros((0, p.shape[1]))
    mean = np.stack([p[i : i + k].mean(0) for i in starts])
    return _prominence(mean, w.shape[-1], rate_hz, modes_hz)


class ModeContext:
    """The last windows' periodograms, for the mode check over several windows.

    Feed each window that passed the single-window checks to :meth:`check`, in time order;
    call :meth:`reset` at a fault or a gap (what came before says nothing about after).
    """

    def __init__(self) -> None:
        self._recent: collections.deque = collections.deque()  # (t_end_s, periodogram)

    def reset(self) -> None:
        """Forget the windows seen so far."""
        self._recent.clear()

    def check(self, x, t_end_s: float, window_s: float, reference) -> str | None:
        """Why the mode is missing over the last :data:`CONTEXT_WINDOWS` windows ending at
        ``t_end_s`` (s), this one ``x`` (``(window,)`` or ``(channels, window)``) included,
        or None (also while fewer windows have been seen, or without a threshold)."""
        floor = getattr(reference, "context_floor", None)
        if floor is None:
            return None
        chans = np.asarray(x, dtype=float)
        chans = chans[None] if chans.ndim == 1 else chans
        span = (CONTEXT_WINDOWS - 1) * window_s
        self._recent.append((t_end_s, _periodogram(chans)))
        while self._recent and self._recent[0][0] < t_end_s - span - 1e-6 * window_s:
            self._recent.popleft()
        if t_end_s - self._recent[0][0] < span - 1e-6 * window_s:
            return None  # not yet the whole stretch
        mean = np.mean([p for _, p in self._recent], axis=0)[None]
        prom = _prominence(mean, chans.shape[-1], reference.rate_hz, reference.modes_hz)[0]
        if np.all(prom < floor):
            modes = ", ".join(f"{f:.1f}" for f in reference.modes_hz)
            return (f"no whisker response over the last {CONTEXT_WINDOWS} windows: their "
                    f"mean spectrum stands {10 ** prom.max():.2g}x above the local floor "
                    f"near its mode ({modes} Hz), the weakest {CONTEXT_WINDOWS} training windows "
                    f"in a row {10**floor:.2g}x: coloured electrical noise, or no whisker "
                    "signal")  # fmt: skip
        return None


@functools.lru_cache(maxsize=16)
def white_context(n: int, rate_hz: float, modes_hz: tuple[float, ...]) -> float:
    """The context prominence that all but 0.1 % of stretches of white noise (windows of
    ``n`` samples) stay below (Monte Carlo, fixed seed)."""
    x = np.random.default_rng(2).standard_normal((3000 * CONTEXT_WINDOWS, n))
    groups = np.repeat(np.arange(3000), CONTEXT_WINDOWS)
    prom = context_prominence(x, rate_hz, modes_hz, groups)[:, 0]
    return float(np.quantile(prom, 0.999))
