"""Online terrain classification on the ADS1115 stream: ``whiskerid stream``.

Samples arrive from :class:`whiskerid.hw.Sampler` (a real ADS1115 over smbus2, or the
register-level :class:`whiskerid.hw.EmulatedADS1115` fed by the terrain simulator). Each one
goes into a ring buffer; every ``hop`` seconds the last ``window`` seconds are resampled onto
the model's uniform grid (timestamps are real, gaps happen) and classified, giving a label,
a confidence and the window-to-label latency. A :class:`whiskerid.hw.Recorder` can write the
stream to CSV with periodic fsync, so a crash leaves a readable file. Ctrl-C or SIGTERM stop
the stream cleanly: files are closed and a summary is printed.

In real time the model runs on a worker thread (:class:`BackgroundClassifier`): the sampling
loop only cuts the window (an interpolation of a few hundred samples) and goes back to its
schedule, so a slow model (a Pi is several times slower than a desktop) costs label latency,
not samples.

This module holds the windowing and the checks (:class:`OnlineClassifier`); the loop, its
worker thread and its summary are in :mod:`whiskerid.hw._stream_loop`, the simulated terrain
in :mod:`whiskerid.hw._terrain_source`.
"""

import collections
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io._ads1115_spec import CODE_MAX, CODE_MIN
from ..io._context import fuse_context
from ..io._health import UNKNOWN
from ..io._health_context import ModeContext
from ._live import MAX_SPEED_MPS


@dataclass(frozen=True)
class WindowLabel:
    """The classification of one window.

    Attributes:
        t_end_s: Time of the window's last sample (s since the stream started).
        label: Predicted terrain, from the window and the model's context before it.
        confidence: Its probability.
        latency_s: Time from the window's last sample arriving to its label (s).
        window_label: What the window alone says (equal to ``label`` for a model without
            context).
        reason: Why a window got no terrain (``label`` one of :data:`FAULT_LABELS`), else "".
        speed_mps: The robot's speed the window was classified with (None: unknown).
        speed_note: How that speed was known when it was not a fresh reading ("last known
            0.3 m/s, 4.2 s old", "none received yet"), else "".
    """

    t_end_s: float
    label: str
    confidence: float
    latency_s: float
    window_label: str = ""
    reason: str = ""
    speed_mps: float | None = None
    speed_note: str = ""

    @property
    def fault(self) -> bool:
        """True when the window got no terrain (a fault, no data, or the robot stopped)."""
        return self.label in FAULT_LABELS


#: Labels a window gets instead of a terrain. ``sensor-fault``: the signal cannot come from a
#: working sensor (flat, clipped, out of range, not finite); ``no-data``: the bus delivered too
#: few samples; ``model-fault``: the model's output is not a probability; ``stopped``: the
#: robot is not moving, so there is no terrain vibration to read.
SENSOR_FAULT, NO_DATA, MODEL_FAULT, STOPPED = "sensor-fault", "no-data", "model-fault", "stopped"
FAULT_LABELS = (SENSOR_FAULT, NO_DATA, MODEL_FAULT, STOPPED, "unknown")  # unknown: not the whisker

#: A live speed not updated for longer than this (s) is reported as the last known one.
SPEED_STALE_S = 2.0
#: Speed the model is compiled with before the robot's is known (m/s; any plausible one).
WARM_UP_SPEED_MPS = 0.2


@dataclass(frozen=True)
class PendingWindow:
    """A window cut from the ring buffer, waiting for the model.

    Attributes:
        t_end_s: Time of the window's last sample (s since the stream started).
        samples: The window on the model's uniform grid.
        arrived_s: Clock reading when its last sample arrived (for the latency).
        fault: ``(label, reason)`` when the window is not fit to classify, else None.
        speed_mps: The robot's speed when the window was cut (None: unknown).
        speed_note: How that speed was known, when not fresh (see :class:`WindowLabel`).
    """

    t_end_s: float
    samples: np.ndarray
    arrived_s: float
    fault: tuple[str, str] | None = None
    speed_mps: float | None = None
    speed_note: str = ""


class OnlineClassifier:
    """Ring buffer + windowing + checks + classifier, fed one sample at a time.

    Labels fuse each window with the windows that ended up to the model's ``lookback_s``
    before it (:func:`whiskerid.fuse_context`, by time, so a hop shorter than the window
    fuses more, overlapping, windows over the same span of signal).

    A window is never given a terrain it cannot show: one that the bus starved (fewer than
    ``min_fill`` of its samples) is labelled ``no-data``; one that is flat (a chip stuck at
    one code, a disconnected sensor), clipped at the ADC's full scale, outside the valid
    range or not finite is labelled ``sensor-fault``; a model output that is not a
    probability (NaN weights) gives ``model-fault``; a robot slower than ``stop_speed_mps``,
    or a signal quieter than ``quiet_std`` (a whisker at rest), gives ``stopped``. Each such
    label carries its reason and confidence 0, and breaks the context: later windows are not
    fused with the ones before it.

    Args:
        model: A trained :class:`whiskerid.ClassifierModel` (``window_proba``,
            ``window``, ``rate_hz``, ``labels``, ``lookback_s``).
        hop_s: Time between classified windows (s).
        speed_mps: Robot speed, for models that use it; a callable ``speed(t_s)`` for a
            speed that changes (live or from odometry); None when unknown.
        min_fill: Windows holding fewer than this fraction of their samples (lost to I2C
            errors or overruns) are labelled ``no-data``: interpolating across long gaps
            low-passes the window and misleads the features.
        limits: Lowest and highest value a working sensor can give (ADC codes by default);
            a window reaching them for ``clip_fraction`` of its samples is clipped.
        clip_fraction: Share of a window's samples at the limits that makes it clipped.
        stop_speed_mps: Below this speed the robot counts as stopped.
        quiet_std: A window whose standard deviation is below this (in the fed units) is a
            whisker at rest: ``stopped``. None: never.
        clock: Clock used for latencies (seconds, monotonic).
    """

    def __init__(
        self,
        model,
        *,
        hop_s: float = 0.5,
        speed_mps: float | Callable[[float], float | None] | None = None,
        min_fill: float = 0.9,
        limits: tuple[float, float] = (CODE_MIN, CODE_MAX),
        clip_fraction: float = 0.02,
        stop_speed_mps: float = 0.02,
        quiet_std: float | None = None,
        clock: Callable[[], float] = time.perf_counter,
    ):
        if hop_s <= 0:
            raise ValueError(f"hop_s = {hop_s!r} must be positive")
        self.model = model
        self.window_s = model.window / model.rate_hz
        self.hop_s = float(hop_s)
        self.speed = speed_mps
        self.min_fill = float(min_fill)
        self.limits = (float(limits[0]), float(limits[1]))
        self.clip_fraction = float(clip_fraction)
        self.stop_speed_mps = float(stop_speed_mps)
        self.quiet_std = quiet_std
        self.skipped_windows = 0
        self._clock = clock
        # Room for one window plus slack for jitter and a late hop.
        size = int(np.ceil((self.window_s + self.hop_s) * model.rate_hz * 1.5)) + 8
        self._t = np.full(size, -np.inf)
        self._x = np.zeros(size)
        self._n = 0
        self._next_s: float | None = None
        self._grid = np.arange(model.window) / model.rate_hz
        self._recent: collections.deque = collections.deque()  # (t_end_s, probabilities)
        self._modes = ModeContext()  # the mode check over the last windows together
        self._last_speed: tuple[float, float] | None = None  # (m/s, stream time)
        #: The window checks, in order (see :meth:`check_window`).
        self.window_checks: list[Callable] = [self._check, self._no_speed, self._stopped]

    def speed_at(self, t_s: float) -> float | None:
        """The robot's speed at stream time ``t_s`` (None when unknown)."""
        return self.speed_with_note(t_s)[0]

    def speed_with_note(self, t_s: float) -> tuple[float | None, str]:
        """The speed to label with at stream time ``t_s``, and how it is known.

        A fresh, plausible reading (finite, 0 to :data:`MAX_SPEED_MPS`) is used as it is.
        Otherwise (no reading yet, a NaN or a gap in the odometry, an implausible value, a
        live feed silent for over :data:`SPEED_STALE_S`) the last good reading is used and
        the note says so; before any, the speed is None ("none received yet"). A missing
        speed never stops the stream.
        """
        if self.speed is None:  # no speed given: nothing to note
            return None, ""
        v = self.speed(t_s) if callable(self.speed) else self.speed
        age = getattr(self.speed, "age_s", None)
        age_s = age() if callable(age) else 0.0
        good = v is not None and np.isfinite(v) and 0 <= v <= MAX_SPEED_MPS
        if good:
            if age_s is None or age_s <= SPEED_STALE_S:
                self._last_speed = (float(v), t_s)
                return float(v), ""
            return float(v), f"last known {v:g} m/s, {age_s:.1f} s old"  # a silent feed
        if self._last_speed is None:
            return None, "none received yet"
        last, when = self._last_speed
        return last, f"last known {last:g} m/s, {t_s - when:.1f} s old"

    def warm_up(self, saved_programs: str | Path | None = None) -> None:
        """Compile the model's path once, so that the first window's latency is honest.

        Args:
            saved_programs: A folder for the model's traced program
                (``ClassifierModel.use_saved_program``): a restart loads it instead of
                tracing again. Best the folder of JAX's persistent compilation cache, so
                that the compiled code is loaded too.
        """
        if saved_programs is not None and hasattr(self.model, "use_saved_program"):
            self.model.use_saved_program(saved_programs)
        # Any plausible speed compiles the same program; the robot's may not be known yet.
        self.model.window_proba(np.zeros(self.model.window), WARM_UP_SPEED_MPS)

    def push(self, t_s: float, value: float) -> WindowLabel | None:
        """Add a sample; return a label when a window is due, else None (model run inline)."""
        pending = self.cut(t_s, value)
        return None if pending is None else self.classify(pending)

    def cut(self, t_s: float, value: float, arrived_s: float | None = None) -> PendingWindow | None:
        """Add a sample; return the window to classify when one is due, else None.

        Cheap (a ring-buffer write, and every hop an interpolation onto the model's grid and
        a few checks): this is all the sampling loop does when the model runs on a worker
        thread.

        Args:
            t_s: The sample's time (s since the stream started).
            value: Its value.
            arrived_s: When it arrived, on this classifier's clock (default: now); latencies
                are counted from it.
        """
        arrived = self._clock() if arrived_s is None else arrived_s
        i = self._n % self._t.size
        self._t[i], self._x[i] = t_s, value
        self._n += 1
        if self._next_s is None:
            self._next_s = t_s + self.window_s
        return self._due(t_s, arrived)

    def gap(self, t_s: float, arrived_s: float | None = None) -> PendingWindow | None:
        """Note a slot without a sample at ``t_s``; a window due by then is cut (``no-data``
        when the bus starved it), so that a dead bus still gives a label every hop."""
        if self._next_s is None:
            self._next_s = t_s + self.window_s
        return self._due(t_s, self._clock() if arrived_s is None else arrived_s)

    def _due(self, t_s: float, arrived: float) -> PendingWindow | None:
        assert self._next_s is not None
        if t_s < self._next_s:
            return None
        self._next_s += self.hop_s * max(1, np.ceil((t_s - self._next_s) / self.hop_s + 1e-12))
        speed, note = self.speed_with_note(t_s)
        in_window = np.count_nonzero(self._t > t_s - self.window_s)
        if in_window < self.min_fill * self.model.window:
            self.skipped_windows += 1
            reason = (f"bus starved the window: {in_window} of {self.model.window} samples "
                      f"arrived")  # fmt: skip
            return PendingWindow(t_s, np.empty(0), arrived, (NO_DATA, reason), speed, note)
        x = self._window(t_s)
        return PendingWindow(t_s, x, arrived, self.check_window(x, speed), speed, note)

    def check_window(self, x: np.ndarray, speed: float | None) -> tuple[str, str] | None:
        """Why a window (on the model's grid) gets no terrain, or None.

        The checks of :attr:`window_checks` in order, the first that objects giving the
        label and reason; more can be appended (each ``check(x, speed)`` returns
        ``(label, reason)`` or None).
        """
        for check in self.window_checks:
            if (fault := check(x, speed)) is not None:
                return fault
        return None

    def _no_speed(self, x: np.ndarray, speed: float | None) -> tuple[str, str] | None:
        if speed is None and getattr(self.model, "needs_speed", False):
            return NO_DATA, "no robot speed received yet (this model needs one)"
        return None

    def _stopped(self, x: np.ndarray, speed: float | None) -> tuple[str, str] | None:
        if speed is not None and speed < self.stop_speed_mps:
            return STOPPED, f"the robot is stopped ({speed:g} m/s)"
        if self.quiet_std is not None and (sd := np.std(x)) < self.quiet_std:
            return STOPPED, f"quiet: the signal varies by {sd:.3g} RMS (whisker at rest?)"
        return None

    def _check(self, x: np.ndarray, speed: float | None = None) -> tuple[str, str] | None:
        """Why the window cannot come from a working sensor, or None."""
        lo, hi = self.limits
        if not np.all(np.isfinite(x)):
            return SENSOR_FAULT, "not-finite samples"
        if np.ptp(x) == 0:
            return SENSOR_FAULT, f"flat: every sample is {x[0]:g} (stuck chip, sensor off?)"
        if np.any(x < lo) or np.any(x > hi):
            return SENSOR_FAULT, f"out of range: samples beyond {lo:g}..{hi:g}"
        clipped = np.count_nonzero((x <= lo) | (x >= hi)) / x.size
        if clipped >= self.clip_fraction:
            return SENSOR_FAULT, f"clipped: {clipped:.0%} of samples at full scale"
        return None

    def classify(self, pending: PendingWindow) -> WindowLabel:
        """Run the model on a cut window (features + MLP) and fuse its context; a fault
        window gets its fault label without the model."""
        if pending.fault is not None:
            return self._fault(pending, *pending.fault)
        health = getattr(self.model, "window_health", None)  # no terrain for a non-whisker
        why = None if health is None else health(pending.samples)
        if why is None or why[0] == UNKNOWN:  # an unknown window still counts for the mode
            ref = getattr(self.model, "health_in_use", None)
            over = self._modes.check(pending.samples, pending.t_end_s, self.window_s, ref)
            why = why or (over and (UNKNOWN, over))
        if why:
            return self._fault(pending, *why)
        p = np.asarray(self.model.window_proba(pending.samples, pending.speed_mps))
        if not (np.all(np.isfinite(p)) and np.all(p >= 0) and abs(float(np.sum(p)) - 1) < 1e-3):
            return self._fault(pending, MODEL_FAULT, "the model's output is not a probability "
                               "(NaN or corrupt weights?)")  # fmt: skip
        lookback = getattr(self.model, "lookback_s", 0.0)
        recent = self._recent
        recent.append((pending.t_end_s, p))
        while recent and recent[0][0] < pending.t_end_s - lookback - 1e-9:
            recent.popleft()  # fuse_context would skip it too; the deque stays short
        t_end, probs = zip(*recent, strict=True)
        fused = fuse_context(np.stack(probs), np.zeros(len(t_end), int), np.asarray(t_end),
                             lookback_s=lookback)[-1]  # fmt: skip
        k, own = int(np.argmax(fused)), int(np.argmax(p))
        conf = float(fused[k])
        latency = self._clock() - pending.arrived_s
        labels = self.model.labels
        return WindowLabel(pending.t_end_s, labels[k], conf, latency, labels[own],
                           speed_mps=pending.speed_mps, speed_note=pending.speed_note)  # fmt: skip

    def _fault(self, pending: PendingWindow, label: str, reason: str) -> WindowLabel:
        self._recent.clear()  # what came before the fault says nothing about what follows
        if label != UNKNOWN:
            self._modes.reset()
        latency = self._clock() - pending.arrived_s
        return WindowLabel(pending.t_end_s, label, 0.0, latency, label, reason,
                           pending.speed_mps, pending.speed_note)  # fmt: skip

    def _window(self, t_end: float) -> np.ndarray:
        order = np.argsort(self._t)
        t, x = self._t[order], self._x[order]
        keep = np.isfinite(t)
        grid = t_end - self.window_s + 1.0 / self.model.rate_hz + self._grid
        return np.interp(grid, t[keep], x[keep])
