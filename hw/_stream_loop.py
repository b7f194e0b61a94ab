"""The stream loop of ``whiskerid stream``: samples in, windows cut, the model on a worker
thread, labels and running counts out (:func:`run_stream`)."""

import collections
import contextlib
import queue
import signal
import sys
import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._inputs import Rounds
from ._recorder import Recorder, unique_path
from ._sampler import Gap
from ._stream import FAULT_LABELS, STOPPED, OnlineClassifier, PendingWindow, WindowLabel


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
    record_stopped: str | None = None
    stopped_by: str = "duration"
    signal: int | None = None
    stale_speed_windows: int = 0
    last: WindowLabel | None = None
    _latency: np.ndarray = field(default_factory=lambda: np.zeros(LATENCY_KEPT), repr=False)

    def add(self, w: WindowLabel) -> str | None:
        """Count a window; return ``"start"`` when it begins a fault episode (a run of
        windows with the same fault), ``"end"`` when it ends one, else None."""
        self._latency[self.windows % LATENCY_KEPT] = w.latency_s
        self.windows += 1
        self.label_counts[w.label] += 1
        self.window_label_counts[w.window_label] += 1
        self.stale_speed_windows += bool(w.speed_note)
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
        # A terrain is the stream's majority only when most windows the robot was moving in
        # carried one: a dead or unplugged whisker whose checks let a few windows through
        # must not be summed up as a terrain.
        moving = sum(v for k, v in counts.items() if k != STOPPED)
        unlabelled = moving - sum(terrains.values())
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
            "majority_label": (
                max(terrains, key=terrains.get)
                if terrains and unlabelled < sum(terrains.values())
                else None
            ),
            "terrain_windows": sum(terrains.values()),
            "unlabelled_windows": unlabelled,
            "latency_ms": {"p50": _pct(lat, 50), "p99": _pct(lat, 99)},
            "record": self.record,
            "record_stopped": self.record_stopped,
            "windows_without_fresh_speed": self.stale_speed_windows,
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
    stop: Callable[[], bool] | None = None,
    on_note: Callable[[str], None] | None = None,
) -> StreamSummary:
    """Feed samples (``hw.Sample``: ``t_s``, ``code``, ``volts``) to the classifier.

    The model's channel decides what is fed: ``adc`` codes (default) or volts.
    :class:`whiskerid.hw.Gap` items (a sampler's ``samples(gaps=True)``) keep the loop
    turning while the bus is down: the recorder still syncs on its timer, and windows that
    fall due get ``no-data`` labels.

    Ctrl-C (SIGINT) and SIGTERM stop the stream cleanly. Their handlers only raise a flag
    that the loop reads at every sample (and a :class:`whiskerid.hw.SamplingProcess` every
    0.2 s while none comes), so a signal is never lost, wherever it lands (an exception
    raised in a garbage-collection callback, as JAX registers, is printed and dropped by
    Python), and no window is cut after it. A recording that fails (a full disk) stops
    recording, not labelling: the stream goes on, says so once, and the summary keeps why.

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
        stop: The caller's own stop flag (it then owns the signal handlers); by default
            SIGINT and SIGTERM are handled here while the stream runs.
        on_note: Called with a sentence when something changes that the user must know
            (the recording stopped).

    Returns:
        The summary: running counts of labels and faults.
    """
    summary = StreamSummary() if summary is None else summary
    summary.record = None if recorder is None else str(recorder.path)
    use_volts = getattr(online.model, "channel", None) in ("voltage", "volts")
    own = _StopFlag() if stop is None else None
    should_stop = own.is_set if own is not None else stop
    assert should_stop is not None
    if hasattr(samples, "stop_when"):
        samples.stop_when(should_stop)
    rec = None if recorder is None else _GuardedRecorder(recorder, summary, on_note)

    def _labelled(label: WindowLabel) -> None:
        summary.add(label)
        if on_label is not None:
            on_label(label)

    worker = BackgroundClassifier(online, _labelled).start() if background else None
    # Samples that waited (in a sampling process's pipe) carry their arrival time.
    waited = samples if hasattr(samples, "arrived_s") else None
    with contextlib.nullcontext() if own is None else own.installed():
        try:
            for s in samples:
                if should_stop():
                    break
                arrived = None if waited is None else waited.arrived_s
                if isinstance(s, Gap):
                    if rec is not None:
                        rec.maybe_sync(s.t_s)
                    pending = online.gap(s.t_s, arrived) if s.channel == channel else None
                else:
                    summary.samples += 1
                    summary.duration_s = s.t_s
                    if rec is not None:
                        rec.write(s)
                    if s.channel != channel:
                        continue
                    pending = online.cut(s.t_s, s.volts if use_volts else s.code, arrived)
                if pending is None:
                    continue
                if worker is not None:
                    worker.submit(pending)
                else:
                    _labelled(online.classify(pending))
        except KeyboardInterrupt:  # the caller's handler raised (a second signal)
            summary.stopped_by = "signal"
        finally:
            if should_stop():
                summary.stopped_by = "signal"
                summary.signal = None if own is None else own.signum
            try:
                if worker is not None:
                    worker.close()
                    summary.dropped_windows = worker.dropped
            finally:
                summary.skipped_windows = online.skipped_windows
                if rec is not None:
                    rec.close()
    return summary


class _StopFlag:
    """SIGINT and SIGTERM handlers that only note the signal: they never raise, so a signal
    that arrives inside a callback whose exceptions are ignored is not lost."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def is_set(self) -> bool:
        return self.signum is not None

    def _handle(self, signum, frame) -> None:
        self.signum = signum

    @contextlib.contextmanager
    def installed(self):
        if threading.current_thread() is not threading.main_thread():
            yield self  # signals are only delivered to the main thread's handlers
            return
        previous = {sig: signal.signal(sig, self._handle) for sig in (signal.SIGINT,
                                                                      signal.SIGTERM)}  # fmt: skip
        try:
            yield self
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)


class _GuardedRecorder:
    """The stream's recorder, which stops recording on an I/O error (a full disk, a removed
    card) instead of stopping the stream: labels matter more than the file."""

    def __init__(self, recorder, summary: StreamSummary, on_note) -> None:
        self.recorder = recorder
        self.summary = summary
        self.on_note = on_note
        self.rounds = Rounds(len(recorder.columns)) if recorder.own_times else None

    def write(self, s) -> None:
        self._guard(s.t_s, self._write, s)

    def _write(self, s) -> None:
        if self.rounds is None:
            self.recorder.write(s.t_s, s.code)
        elif (row := self.rounds.push(s)) is not None:
            self.recorder.write_round(*row)

    def maybe_sync(self, t_s: float) -> None:
        self._guard(t_s, self.recorder.maybe_sync)

    def _guard(self, t_s: float, fn, *args) -> None:
        if self.summary.record_stopped is not None:
            return
        try:
            fn(*args)
        except OSError as e:
            why = e.strerror or str(e)
            self.summary.record_stopped = (f"recording stopped at t = {t_s:.1f} s: {why}; "
                                           "labelling goes on")  # fmt: skip
            self.close()
            if self.on_note is not None:
                self.on_note(self.summary.record_stopped)

    def close(self) -> None:
        # The file that failed may fail again as it is closed: it is closed all the same.
        with contextlib.suppress(OSError, ValueError):
            self.recorder.close()


def open_recorder(path: Path | None, *, rate_hz: float, meta: dict):
    """A crash-safe CSV recorder of ADC codes, or None; never overwrites (``-1``, ``-2``...)."""
    if path is None:
        return None
    return Recorder(unique_path(path), columns=("adc",), rate_hz=rate_hz, units="code",
                    metadata=meta)  # fmt: skip
