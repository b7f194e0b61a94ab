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
"""

import collections
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


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
    """

    t_end_s: float
    label: str
    confidence: float
    latency_s: float
    window_label: str = ""


@dataclass(frozen=True)
class PendingWindow:
    """A window cut from the ring buffer, waiting for the model.

    Attributes:
        t_end_s: Time of the window's last sample (s since the stream started).
        samples: The window on the model's uniform grid.
        arrived_s: Clock reading when its last sample arrived (for the latency).
    """

    t_end_s: float
    samples: np.ndarray
    arrived_s: float


class OnlineClassifier:
    """Ring buffer + windowing + classifier, fed one sample at a time.

    Labels fuse each window with the windows that ended up to the model's ``lookback_s``
    before it (:func:`whiskerid.fuse_context`, by time, so a hop shorter than the window
    fuses more, overlapping, windows over the same span of signal).

    Args:
        model: A trained :class:`whiskerid.ClassifierModel` (``window_proba``,
            ``window``, ``rate_hz``, ``labels``, ``lookback_s``).
        hop_s: Time between classified windows (s).
        speed_mps: Robot speed, for models that use it.
        min_fill: Windows holding fewer than this fraction of their samples (lost to I2C
            errors or overruns) are not classified but counted in ``skipped_windows``:
            interpolating across long gaps low-passes the window and misleads the features.
        clock: Clock used for latencies (seconds, monotonic).
    """

    def __init__(
        self,
        model,
        *,
        hop_s: float = 0.5,
        speed_mps: float | None = None,
        min_fill: float = 0.9,
        clock: Callable[[], float] = time.perf_counter,
    ):
        if hop_s <= 0:
            raise ValueError(f"hop_s = {hop_s!r} must be positive")
        self.model = model
        self.window_s = model.window / model.rate_hz
        self.hop_s = float(hop_s)
        self.speed = speed_mps
        self.min_fill = float(min_fill)
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

    def warm_up(self) -> None:
        """Compile the model's path once, so that the first window's latency is honest."""
        self.model.window_proba(np.zeros(self.model.window), self.speed)

    def push(self, t_s: float, value: float) -> WindowLabel | None:
        """Add a sample; return a label when a window is due, else None (model run inline)."""
        pending = self.cut(t_s, value)
        return None if pending is None else self.classify(pending)

    def cut(self, t_s: float, value: float) -> PendingWindow | None:
        """Add a sample; return the window to classify when one is due, else None.

        Cheap (a ring-buffer write, and every hop an interpolation onto the model's grid):
        this is all the sampling loop does when the model runs on a worker thread.
        """
        arrived = self._clock()
        i = self._n % self._t.size
        self._t[i], self._x[i] = t_s, value
        self._n += 1
        if self._next_s is None:
            self._next_s = t_s + self.window_s
        if t_s < self._next_s:
            return None
        self._next_s += self.hop_s * max(1, np.ceil((t_s - self._next_s) / self.hop_s + 1e-12))
        in_window = np.count_nonzero(self._t > t_s - self.window_s)
        if in_window < self.min_fill * self.model.window:
            self.skipped_windows += 1
            return None
        return PendingWindow(t_s, self._window(t_s), arrived)

    def classify(self, pending: PendingWindow) -> WindowLabel:
        """Run the model on a cut window (features + MLP) and fuse its context."""
        from ..classify import fuse_context

        p = self.model.window_proba(pending.samples, self.speed)
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
        return WindowLabel(pending.t_end_s, labels[k], conf, latency, labels[own])

    def _window(self, t_end: float) -> np.ndarray:
        order = np.argsort(self._t)
        t, x = self._t[order], self._x[order]
        keep = np.isfinite(t)
        grid = t_end - self.window_s + 1.0 / self.model.rate_hz + self._grid
        return np.interp(grid, t[keep], x[keep])


class BackgroundClassifier:
    """Run :meth:`OnlineClassifier.classify` on a worker thread, fed through a short queue.

    The sampling thread hands over cut windows with :meth:`submit` and never waits: when the
    model falls so far behind that ``max_pending`` windows are queued, the new window is
    dropped and counted (``dropped``), never the samples. While the worker runs, the
    interpreter's switch interval is shortened (``switch_interval_s``) so that the sampling
    thread gets the GIL back within a fraction of a sample period when its sleep ends; the
    previous interval is restored by :meth:`close`.

    Args:
        online: The classifier that owns the ring buffer and the model.
        on_label: Called on the worker thread with each :class:`WindowLabel`.
        max_pending: Windows that may wait for the model.
        switch_interval_s: GIL switch interval while running (Python's default is 5 ms,
            as long as a sample period at 200 Hz).
    """

    def __init__(
        self,
        online: OnlineClassifier,
        on_label: Callable[[WindowLabel], None],
        *,
        max_pending: int = 4,
        switch_interval_s: float = 5e-4,
    ):
        self.online = online
        self.on_label = on_label
        self.dropped = 0
        self._queue: queue.Queue = queue.Queue(maxsize=max_pending)
        self._error: BaseException | None = None
        self._switch = switch_interval_s
        self._previous_switch: float | None = None
        self._thread = threading.Thread(target=self._run, name="whiskerid-classify", daemon=True)

    def start(self) -> "BackgroundClassifier":
        """Start the worker thread."""
        self._previous_switch = sys.getswitchinterval()
        sys.setswitchinterval(self._switch)
        self._thread.start()
        return self

    def submit(self, pending: PendingWindow) -> bool:
        """Queue a window without waiting; False (and counted) if the queue is full."""
        if self._error is not None:
            raise RuntimeError("the classifier thread failed") from self._error
        try:
            self._queue.put_nowait(pending)
        except queue.Full:
            self.dropped += 1
            return False
        return True

    def _run(self) -> None:
        while (pending := self._queue.get()) is not None:
            try:
                self.on_label(self.online.classify(pending))
            except BaseException as e:  # reported by submit() and close(), not lost
                self._error = e
                return

    def close(self, timeout_s: float = 10.0) -> None:
        """Classify what is queued, stop the worker (waiting at most ``timeout_s``).

        Raises:
            RuntimeError: If the worker failed (the original error is the cause) or did not
                finish within ``timeout_s``.
        """
        try:
            if self._thread.is_alive():
                self._queue.put(None, timeout=timeout_s)
                self._thread.join(timeout_s)
        finally:
            if self._previous_switch is not None:
                sys.setswitchinterval(self._previous_switch)
        if self._error is not None:
            raise RuntimeError("the classifier thread failed") from self._error
        if self._thread.is_alive():
            raise RuntimeError(f"the classifier thread did not finish within {timeout_s} s")


@dataclass
class StreamSummary:
    """What a stream did (printed at the end, and as ``--json``)."""

    duration_s: float = 0.0
    samples: int = 0
    windows: list[WindowLabel] = field(default_factory=list)
    gaps: int = 0
    overruns: int = 0
    skipped_windows: int = 0
    dropped_windows: int = 0
    record: str | None = None
    stopped_by: str = "duration"

    def to_dict(self, truth: str | None = None) -> dict:
        """JSON-able summary; with ``truth`` the fraction of windows labelled right."""
        labels = [w.label for w in self.windows]
        lat = np.array([w.latency_s for w in self.windows]) * 1e3
        counts = {lab: labels.count(lab) for lab in sorted(set(labels))}
        out = {
            "duration_s": round(self.duration_s, 3),
            "samples": self.samples,
            "achieved_rate_hz": round(self.samples / self.duration_s, 3) if self.duration_s else 0,
            "gaps": self.gaps,
            "overruns": self.overruns,
            "windows": len(labels),
            "skipped_windows": self.skipped_windows,
            "dropped_windows": self.dropped_windows,
            "label_counts": counts,
            "majority_label": max(counts, key=counts.get) if counts else None,
            "latency_ms": {"p50": _pct(lat, 50), "p99": _pct(lat, 99)},
            "record": self.record,
            "stopped_by": self.stopped_by,
        }
        if truth is not None:
            out["truth"] = truth
            out["fraction_correct"] = (
                round(labels.count(truth) / len(labels), 4) if labels else None
            )
            own = [w.window_label for w in self.windows]
            out["fraction_correct_per_window"] = (
                round(own.count(truth) / len(own), 4) if own else None
            )
        return out


def _pct(x: np.ndarray, q: float) -> float | None:
    return round(float(np.percentile(x, q)), 4) if x.size else None


def run_stream(
    samples: Iterable,
    online: OnlineClassifier,
    *,
    recorder=None,
    on_label: Callable[[WindowLabel], None] | None = None,
    background: bool = True,
) -> StreamSummary:
    """Feed samples (``hw.Sample``: ``t_s``, ``code``, ``volts``) to the classifier.

    The model's channel decides what is fed: ``adc`` codes (default) or volts. SIGTERM is
    turned into a clean stop, like Ctrl-C.

    Args:
        samples: The sample stream (e.g. ``Sampler.samples(duration_s=...)``).
        online: Ring buffer, windowing and model.
        recorder: Optional :class:`whiskerid.hw.Recorder`; closed at the end.
        on_label: Called with each label (on the worker thread when ``background``).
        background: Run the model on a worker thread (:class:`BackgroundClassifier`), so the
            sampling loop never waits for it: right for a real-time clock. ``False`` runs it
            inline, one window at a time (a virtual clock, where nothing waits anyway).

    Returns:
        The summary; labels in time order.
    """
    summary = StreamSummary(record=None if recorder is None else str(recorder.path))
    use_volts = getattr(online.model, "channel", None) in ("voltage", "volts")
    previous = signal.getsignal(signal.SIGTERM)

    def _terminate(signum, frame):
        raise KeyboardInterrupt

    def _labelled(label: WindowLabel) -> None:
        summary.windows.append(label)
        if on_label is not None:
            on_label(label)

    worker = BackgroundClassifier(online, _labelled).start() if background else None
    signal.signal(signal.SIGTERM, _terminate)
    try:
        for s in samples:
            summary.samples += 1
            summary.duration_s = s.t_s
            if recorder is not None:
                recorder.write(s.t_s, s.code)
            pending = online.cut(s.t_s, s.volts if use_volts else s.code)
            if pending is None:
                continue
            if worker is not None:
                worker.submit(pending)
            else:
                _labelled(online.classify(pending))
    except KeyboardInterrupt:
        summary.stopped_by = "signal"
    finally:
        signal.signal(signal.SIGTERM, previous)
        try:
            if worker is not None:
                worker.close()
                summary.dropped_windows = worker.dropped
        finally:
            summary.skipped_windows = online.skipped_windows
            if recorder is not None:
                recorder.close()
    return summary


def terrain_source(record, terrain: str, speed_mps: float, duration_s: float, *, seed: int = 0,
                   amplifier: float = 20.0):  # fmt: skip
    """Hall-sensor voltage ``source(t_s)`` of a whisker driven over a simulated terrain.

    Uses the terrain simulator's base motion and the exact modal model; the emulated ADS1115
    then does the averaging, clipping and quantisation itself.
    """
    import jax.numpy as jnp

    from ..model._response import base_motion_response, observe
    from ..model._sensor import HallSensor
    from ..terrain._terrain import base_acceleration
    from ._emulator import source_from_recording

    rng = np.random.default_rng([seed, 7919])
    t, acc = base_acceleration(terrain, speed_mps, duration_s + 1.0, rng)
    whisker = record.whisker()
    state = base_motion_response(whisker, jnp.asarray(t), jnp.asarray(acc), uniform=True)
    hall = HallSensor(gain_v_per_m=record.hall.gain_v_per_m * amplifier,
                      offset_v=record.hall.offset_v,
                      quadratic_v_per_m2=record.hall.quadratic_v_per_m2 * amplifier)  # fmt: skip
    volts = np.asarray(hall.voltage(observe(whisker, state, "deflection")))
    keep = t >= 0
    return source_from_recording(t[keep], volts[keep])


def open_recorder(path: Path | None, *, rate_hz: float, meta: dict):
    """A crash-safe CSV recorder of ADC codes, or None; never overwrites (``-1``, ``-2``...)."""
    if path is None:
        return None
    from ._recorder import Recorder, unique_path

    return Recorder(unique_path(path), columns=("adc",), rate_hz=rate_hz, units="code",
                    metadata=meta)  # fmt: skip
