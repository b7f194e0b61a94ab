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

from ..classify import fuse_context
from ..io._ads1115_spec import CODE_MAX, CODE_MIN
from ..terrain import AMPLIFIER, amplified_hall, base_acceleration, hall_voltage
from ._emulator import source_from_recording
from ._inputs import Rounds
from ._recorder import Recorder, unique_path
from ._sampler import Gap


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
    """

    t_end_s: float
    label: str
    confidence: float
    latency_s: float
    window_label: str = ""
    reason: str = ""
    speed_mps: float | None = None

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


@dataclass(frozen=True)
class PendingWindow:
    """A window cut from the ring buffer, waiting for the model.

    Attributes:
        t_end_s: Time of the window's last sample (s since the stream started).
        samples: The window on the model's uniform grid.
        arrived_s: Clock reading when its last sample arrived (for the latency).
        fault: ``(label, reason)`` when the window is not fit to classify, else None.
        speed_mps: The robot's speed when the window was cut (None: unknown).
    """

    t_end_s: float
    samples: np.ndarray
    arrived_s: float
    fault: tuple[str, str] | None = None
    speed_mps: float | None = None


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

    def speed_at(self, t_s: float) -> float | None:
        """The robot's speed at stream time ``t_s`` (None when unknown)."""
        v = self.speed(t_s) if callable(self.speed) else self.speed
        return None if v is None or not np.isfinite(v) else float(v)

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
        self.model.window_proba(np.zeros(self.model.window), self.speed_at(0.0))

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
        speed = self.speed_at(t_s)
        in_window = np.count_nonzero(self._t > t_s - self.window_s)
        if in_window < self.min_fill * self.model.window:
            self.skipped_windows += 1
            reason = (f"bus starved the window: {in_window} of {self.model.window} samples "
                      f"arrived")  # fmt: skip
            return PendingWindow(t_s, np.empty(0), arrived, (NO_DATA, reason), speed)
        x = self._window(t_s)
        fault = self._check(x)
        if fault is None and speed is not None and speed < self.stop_speed_mps:
            fault = (STOPPED, f"the robot is stopped ({speed:g} m/s)")
        if fault is None and self.quiet_std is not None and (sd := np.std(x)) < self.quiet_std:
            fault = (STOPPED, f"quiet: the signal varies by {sd:.3g} RMS (whisker at rest?)")
        return PendingWindow(t_s, x, arrived, fault, speed)

    def _check(self, x: np.ndarray) -> tuple[str, str] | None:
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
        if health is not None and (why := health(pending.samples)) is not None:
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
                           speed_mps=pending.speed_mps)  # fmt: skip

    def _fault(self, pending: PendingWindow, label: str, reason: str) -> WindowLabel:
        self._recent.clear()  # what came before the fault says nothing about what follows
        latency = self._clock() - pending.arrived_s
        return WindowLabel(pending.t_end_s, label, 0.0, latency, label, reason,
                           pending.speed_mps)  # fmt: skip

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


#: Latencies kept for the summary's percentiles (the most recent ones; a ring buffer).
LATENCY_KEPT = 65_536


@dataclass
class StreamSummary:
    """What a stream did, as running counts (printed at the end, and as ``--json``).

    Memory stays constant however long the stream runs: counts per label and per fault
    reason, and the latencies of the last :data:`LATENCY_KEPT` windows.
    """

    duration_s: float = 0.0
    samples: int = 0
    windows: int = 0
    label_counts: collections.Counter = field(default_factory=collections.Counter)
    window_label_counts: collections.Counter = field(default_factory=collections.Counter)
    fault_counts: collections.Counter = field(default_factory=collections.Counter)
    fault_episodes: int = 0
    gaps: int = 0
    overruns: int = 0
    bus_errors: dict = field(default_factory=dict)
    skipped_windows: int = 0
    dropped_windows: int = 0
    record: str | None = None
    stopped_by: str = "duration"
    last: WindowLabel | None = None
    _latency: np.ndarray = field(default_factory=lambda: np.zeros(LATENCY_KEPT), repr=False)

    def add(self, w: WindowLabel) -> str | None:
        """Count a window; return ``"start"`` when it begins a fault episode (a run of
        windows with the same fault), ``"end"`` when it ends one, else None."""
        self._latency[self.windows % LATENCY_KEPT] = w.latency_s
        self.windows += 1
        self.label_counts[w.label] += 1
        self.window_label_counts[w.window_label] += 1
        before = self.last
        self.last = w
        if w.fault:
            self.fault_counts[f"{w.label}: {_kind(w.reason)}"] += 1
        was = before is not None and before.fault
        same = was and (before.label, _kind(before.reason)) == (w.label, _kind(w.reason))
        if w.fault and not same:
            self.fault_episodes += 1
            return "start"
        if was and not w.fault:
            return "end"
        return None

    @property
    def all_failed(self) -> bool:
        """True when windows were due and none of them got a terrain."""
        return self.windows > 0 and all(k in FAULT_LABELS for k in self.label_counts)

    def to_dict(self, truth: str | None = None) -> dict:
        """JSON-able summary; with ``truth`` the fraction of windows labelled right."""
        lat = self._latency[: min(self.windows, LATENCY_KEPT)] * 1e3
        counts = dict(sorted(self.label_counts.items()))
        terrains = {k: v for k, v in counts.items() if k not in FAULT_LABELS}
        out = {
            "duration_s": round(self.duration_s, 3),
            "samples": self.samples,
            "achieved_rate_hz": round(self.samples / self.duration_s, 3) if self.duration_s else 0,
            "gaps": self.gaps,
            "overruns": self.overruns,
            "bus_errors": self.bus_errors,
            "windows": self.windows,
            "skipped_windows": self.skipped_windows,
            "dropped_windows": self.dropped_windows,
            "label_counts": counts,
            "faults": dict(sorted(self.fault_counts.items())),
            "fault_episodes": self.fault_episodes,
            "majority_label": max(terrains, key=terrains.get) if terrains else None,
            "latency_ms": {"p50": _pct(lat, 50), "p99": _pct(lat, 99)},
            "record": self.record,
            "stopped_by": self.stopped_by,
        }
        if truth is not None:
            n = self.windows
            out["truth"] = truth
            out["fraction_correct"] = round(self.label_counts[truth] / n, 4) if n else None
            out["fraction_correct_per_window"] = (
                round(self.window_label_counts[truth] / n, 4) if n else None
            )
        return out


def _kind(reason: str) -> str:
    """A fault reason without its numbers (``flat``, ``clipped``, ``bus starved the window``)."""
    return reason.split(":")[0]


def _pct(x: np.ndarray, q: float) -> float | None:
    return round(float(np.percentile(x, q)), 4) if x.size else None


def run_stream(
    samples: Iterable,
    online: OnlineClassifier,
    *,
    recorder=None,
    on_label: Callable[[WindowLabel], None] | None = None,
    background: bool = True,
    channel: int = 0,
    summary: StreamSummary | None = None,
) -> StreamSummary:
    """Feed samples (``hw.Sample``: ``t_s``, ``code``, ``volts``) to the classifier.

    The model's channel decides what is fed: ``adc`` codes (default) or volts. SIGTERM is
    turned into a clean stop, like Ctrl-C. :class:`whiskerid.hw.Gap` items (a sampler's
    ``samples(gaps=True)``) keep the loop turning while the bus is down: the recorder still
    syncs on its timer, and windows that fall due get ``no-data`` labels.

    Args:
        samples: The sample stream (e.g. ``Sampler.samples(duration_s=..., gaps=True)``,
            or a :class:`whiskerid.hw.SamplingProcess` sampling since before the model was
            loaded). A stream with an ``arrived_s`` attribute gives the latest item's
            arrival time: latencies then count the time a sample waited before it was read.
        online: Ring buffer, windowing and model.
        recorder: Optional :class:`whiskerid.hw.Recorder`; closed at the end. With several
            columns it gets one row per complete round of inputs.
        on_label: Called with each label (on the worker thread when ``background``).
        background: Run the model on a worker thread (:class:`BackgroundClassifier`), so the
            sampling loop never waits for it: right for a real-time clock. ``False`` runs it
            inline, one window at a time (a virtual clock, where nothing waits anyway).
        channel: The input that is classified (``Sample.channel``), when several are read.
        summary: A summary to fill (e.g. to read its counts while the stream runs).

    Returns:
        The summary: running counts of labels and faults.
    """
    summary = StreamSummary() if summary is None else summary
    summary.record = None if recorder is None else str(recorder.path)
    use_volts = getattr(online.model, "channel", None) in ("voltage", "volts")
    rounds = Rounds(len(recorder.columns)) if recorder is not None and recorder.own_times else None
    previous = signal.getsignal(signal.SIGTERM)

    def _terminate(signum, frame):
        raise KeyboardInterrupt

    def _labelled(label: WindowLabel) -> None:
        summary.add(label)
        if on_label is not None:
            on_label(label)

    worker = BackgroundClassifier(online, _labelled).start() if background else None
    signal.signal(signal.SIGTERM, _terminate)
    # Samples that waited (in a sampling process's pipe) carry their arrival time.
    waited = samples if hasattr(samples, "arrived_s") else None
    try:
        for s in samples:
            arrived = None if waited is None else waited.arrived_s
            if isinstance(s, Gap):
                if recorder is not None:
                    recorder.maybe_sync()
                pending = online.gap(s.t_s, arrived) if s.channel == channel else None
            else:
                summary.samples += 1
                summary.duration_s = s.t_s
                if rounds is not None:
                    if (row := rounds.push(s)) is not None:
                        recorder.write_round(*row)
                elif recorder is not None:
                    recorder.write(s.t_s, s.code)
                if s.channel != channel:
                    continue
                pending = online.cut(s.t_s, s.volts if use_volts else s.code, arrived)
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


def terrain_source(record, terrain: str, speed_mps: float, duration_s: float | None, *,
                   seed: int = 0, amplifier: float = AMPLIFIER, chunk_s: float = 60.0):  # fmt: skip
    """Hall-sensor voltage ``source(t_s)`` of a whisker driven over a simulated terrain.

    The terrain simulator's base motion, whisker and amplified Hall sensor
    (:func:`whiskerid.terrain.hall_voltage`, the chain the dataset synthesiser uses); the
    emulated ADS1115 then does the averaging, clipping and quantisation itself.

    With ``duration_s`` None the terrain never ends: it is made ``chunk_s`` seconds at a time,
    each chunk fresh terrain (its own seed), the next one made on a worker thread from the
    middle of the current one on, and successive chunks cross-faded over a second.
    """
    if duration_s is not None:
        return _terrain_chunk(record, terrain, speed_mps, duration_s, seed, amplifier)

    def chunk(k: int):
        return _terrain_chunk(record, terrain, speed_mps, chunk_s + 2 * _FADE_S, [seed, k],
                              amplifier)  # fmt: skip

    return _EndlessTerrain(chunk, chunk_s)


#: Cross-fade between chunks of an endless terrain, and the start-up transient each chunk's
#: whisker simulation drops (it starts at rest), in seconds.
_FADE_S = 1.0


def _terrain_chunk(record, terrain, speed_mps, duration_s, seed, amplifier):
    rng = np.random.default_rng([*np.atleast_1d(seed), 7919])
    t, acc = base_acceleration(terrain, speed_mps, duration_s + 1.0, rng)
    volts = np.asarray(hall_voltage(record.whisker(), amplified_hall(record, amplifier), t, acc))
    keep = t >= 0
    return source_from_recording(t[keep], volts[keep])


class _EndlessTerrain:
    """Chunk ``k`` of the terrain plays over ``[k C, (k + 1) C]`` (``C = chunk_s``), taken
    from its own simulation after a second of start-up, and fades into chunk ``k + 1``
    over the first second of the latter."""

    def __init__(self, make: Callable[[int], Callable], chunk_s: float):
        self._make = make
        self.chunk_s = float(chunk_s)
        self._chunks: dict[int, Callable] = {}
        self._ahead: tuple[int, threading.Thread, list] | None = None

    def _chunk(self, k: int) -> Callable:
        if k not in self._chunks:
            if self._ahead is not None and self._ahead[0] == k:
                self._ahead[1].join()
                made = self._ahead[2]
                self._ahead = None
                # A worker that failed left nothing: make it here, where an error is seen.
                self._chunks[k] = made[0] if made else self._make(k)
            else:
                self._chunks[k] = self._make(k)
            for old in [j for j in self._chunks if j < k - 1]:
                del self._chunks[old]  # memory stays at two chunks
        return self._chunks[k]

    def _prefetch(self, k: int) -> None:
        """Start making chunk ``k + 1`` on a worker thread (halfway through chunk ``k``, so
        that the start-up, busy compiling, is left alone)."""
        if self._ahead is None and k + 1 not in self._chunks:
            box: list = []
            thread = threading.Thread(target=lambda: box.append(self._make(k + 1)), daemon=True)
            thread.start()
            self._ahead = (k + 1, thread, box)

    def _play(self, k: int, t: np.ndarray) -> np.ndarray:
        # Chunk k's own time 0 is at stream time k C - 2 FADE: its start-up from rest is
        # over a second before it fades in at k C.
        return np.asarray(self._chunk(k)(t - k * self.chunk_s + 2 * _FADE_S))

    def __call__(self, t_s):
        t = np.asarray(t_s, dtype=np.float64)
        k = int(np.floor(float(np.mean(t)) / self.chunk_s))
        v = self._play(k, t)
        if float(np.mean(t)) - k * self.chunk_s > self.chunk_s / 2:
            self._prefetch(k)
        into = (t - k * self.chunk_s) / _FADE_S
        if k > 0 and float(np.min(into)) < 1.0:
            w = np.clip(into, 0.0, 1.0)
            v = w * v + (1 - w) * self._play(k - 1, t)
        return float(v) if v.ndim == 0 else v


def open_recorder(path: Path | None, *, rate_hz: float, meta: dict):
    """A crash-safe CSV recorder of ADC codes, or None; never overwrites (``-1``, ``-2``...)."""
    if path is None:
        return None
    return Recorder(unique_path(path), columns=("adc",), rate_hz=rate_hz, units="code",
                    metadata=meta)  # fmt: skip
