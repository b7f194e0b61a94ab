"""Sampling in a child process, so that the schedule never waits for the model.

A stream's own process imports JAX, loads the model and runs it. Parts of that hold the
interpreter's lock (the GIL) for many milliseconds at a time (loading a compiled library,
deserialising a program, a model call), and a sampling thread of the same process misses its
slots meanwhile: the first window after a start would come out short of samples. The child
imports only the driver side (numpy, and smbus2 on a Pi), opens the bus, raises its own
priority (real time where permitted, else nice: :func:`whiskerid.hw.raise_priority`), samples
on its own schedule and writes each sample to its standard output as one JSON line, without
ever waiting for the parent (:class:`whiskerid.hw.PipeWriter`: a non-blocking pipe that holds
over a minute of samples); the parent reads them in order. The child starts before the parent
imports JAX, so the first window fills while the model loads; other processes busy on every
core delay the samples' arrival, not their reading.

Protocol, one JSON value per line on the child's standard output:

* ``{"priority": "SCHED_FIFO 20"}``: the priority the child got; the first line;
* ``[t_s, code, volts, channel, round, sent_ns]``: a :class:`~whiskerid.hw.Sample`, and
  when it was sent (``time.monotonic_ns()``, the system's monotonic clock, shared by the two
  processes), from which the parent counts latencies;
* ``{"gap": [t_s, channel, error, sent_ns]}``: a :class:`~whiskerid.hw.Gap`;
* ``{"end": {...}, "handoff": {...}}``: the sampler's :class:`~whiskerid.hw.SamplerStats`,
  and the hand-off's (lines dropped, largest backlog, pipe size); the last line;
* ``{"error": "..."}``: the child could not start (bus or recording not opened).

The child stops when its standard input gives a line or ends: the parent's :meth:`close`, or
the parent's death (even by ``kill -9``), so a sampling child is never left behind. It ignores
Ctrl-C and SIGTERM: the terminal, and systemd stopping a service, send them to the whole
process group, and the parent decides when the samples end (a child that stopped first would
leave the parent's last windows without samples).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import queue
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator

from ._ads1115 import DEFAULT_CONFIG, Config, open_bus
from ._emulator import replay_sources
from ._inputs import Input, converter, data_rate_for, emulated_bus, parse_inputs
from ._realtime import PipeWriter, raise_priority
from ._sampler import Gap, Sample, Sampler, SamplerStats


class SamplingError(RuntimeError):
    """The sampling process could not start or ended without its closing line."""


@dataclasses.dataclass(frozen=True)
class SamplerSpec:
    """What a sampler reads: plain values, so that a child process can be given them as JSON.

    Attributes:
        inputs: The inputs, as ``whiskerid stream --inputs`` takes them (``A0``, ``A0,A1``).
        address: The chip's 7-bit I2C address for inputs named without one.
        rate_hz: Samples per second of each input.
        duration_s: Stop after this many seconds; None runs until stopped.
        i2c_bus: Read a real chip on ``/dev/i2c-<i2c_bus>``.
        replay: Else replay this recording through the emulated chip.
        seed: Seed of the emulated chip's noise.
        priority: The sampling process's priority: ``auto`` (real time where permitted,
            else nice), ``realtime``, ``nice`` or ``none`` (see
            :func:`whiskerid.hw.raise_priority`).
    """

    inputs: str = "A0"
    address: int = 0x48
    rate_hz: float = 200.0
    duration_s: float | None = None
    i2c_bus: int | None = None
    replay: str | None = None
    seed: int = 0
    priority: str = "auto"

    def to_json(self) -> str:
        """The spec as one line of JSON."""
        return json.dumps(dataclasses.asdict(self))


def stream_config(inputs: tuple[Input, ...], rate_hz: float) -> Config:
    """The chip's configuration for a stream: the driver's default on the first input, and
    for several inputs the slowest data rate whose conversion fits one slot.

    Raises:
        ValueError: When no data rate is fast enough for the inputs at this rate.
    """
    cfg = DEFAULT_CONFIG.replace(mux=inputs[0].mux)
    if len(inputs) > 1:
        cfg = cfg.replace(data_rate_sps=data_rate_for(1.0 / (len(inputs) * rate_hz)))
    return cfg


def open_sampler(spec: SamplerSpec, *, sources: list | None = None, **timing):
    """The bus, converter and sampler a spec describes.

    Args:
        spec: What to read.
        sources: One ``source(t_s) -> volts`` per input for the emulated chip (e.g. the
            terrain simulator); by default the spec's replay, else a real chip.
        **timing: ``clock`` and ``sleep`` for the chip and the sampler (a virtual clock).

    Returns:
        ``(sampler, bus, config, inputs)``; the caller closes the bus.

    Raises:
        ValueError: Unknown inputs, a rate the inputs cannot reach, or a recording that
            cannot be replayed.
        OSError, ImportError: A real bus that cannot be opened.
    """
    inputs = parse_inputs(spec.inputs, default_address=spec.address)
    cfg = stream_config(inputs, spec.rate_hz)
    if sources is None and spec.i2c_bus is None:
        if spec.replay is None:
            raise ValueError("a sampler needs a bus, a recording to replay or sources")
        sources = replay_sources(spec.replay, [i.name for i in inputs])
    if sources is None:
        bus = open_bus(spec.i2c_bus)
    else:
        bus = emulated_bus(inputs, sources, seed=spec.seed, **timing)
    adc = converter(bus, inputs, config=cfg, **timing)
    return Sampler(adc, spec.rate_hz, **timing), bus, cfg, inputs


class SamplingProcess:
    """A sampler run by a child process from now on; iterate it for its samples, in order.

    Iterating yields :class:`~whiskerid.hw.Sample` and :class:`~whiskerid.hw.Gap` items
    until the spec's duration ends or :meth:`close` is called; :attr:`arrived_s` is the
    latest item's arrival on ``clock`` (so that a window's latency counts the time its last
    sample waited in the pipe), :attr:`stats` the child's counters once it has ended,
    :attr:`priority` the priority it got and :attr:`handoff` the hand-off's counters.
    Iteration also ends, within 0.2 s, when the callable given to :meth:`stop_when` says so
    (a signal's flag), whether or not samples arrive.

    Args:
        spec: What the child samples.
        python: The interpreter to run the child with.
        clock: Seconds on a monotonic clock: the clock latencies are measured on.
        process: A child already started without a spec (``python -m
            whiskerid.hw._sampling_child``, its standard input and output pipes in text
            mode), waiting for one on its standard input: it is sent the spec and used
            instead of a new one (a new one when it has gone).

    Raises:
        SamplingError: While iterating, when the child could not start or died.
    """

    def __init__(
        self,
        spec: SamplerSpec,
        *,
        python: str = sys.executable,
        clock: Callable[[], float] = time.perf_counter,
        process: subprocess.Popen | None = None,
    ) -> None:
        self.spec = spec
        self.stats = SamplerStats()
        self.arrived_s: float | None = None
        self.priority: str | None = None
        self.handoff: dict = {}
        self._clock = clock
        self._ended = False
        self._stop: Callable[[], bool] = lambda: False
        self._proc = _given(process, spec) or subprocess.Popen(
            [python, "-m", "whiskerid.hw._sampling_child", spec.to_json()],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
        )
        # A thread empties the pipe into a queue as lines come: were the child's writes to
        # wait for a busy parent (the pipe holds a few seconds of samples), it would miss
        # slots.
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._reader = threading.Thread(target=self._read, name="whiskerid-sampling-pipe",
                                        daemon=True)  # fmt: skip
        self._reader.start()

    def stop_when(self, stop: Callable[[], bool]) -> None:
        """End the iteration as soon as ``stop()`` is true (polled at least every 0.2 s)."""
        self._stop = stop

    def _read(self) -> None:
        assert self._proc.stdout is not None
        for line in self._proc.stdout:
            msg = json.loads(line)
            if isinstance(msg, dict) and "priority" in msg:
                self.priority = msg["priority"]
                continue
            sent = msg[-1] if isinstance(msg, list) else msg.get("gap", [0])[-1]
            self._queue.put((msg, self._arrival(sent) if sent else None))
            if isinstance(msg, dict) and ("end" in msg or "error" in msg):
                return
        self._queue.put((None, None))  # the pipe closed without the closing line

    def __iter__(self) -> Iterator[Sample | Gap]:
        while not self._ended and not self._stop():
            try:
                # A timeout keeps the wait interruptible by Ctrl-C and SIGTERM everywhere.
                msg, arrived = self._queue.get(timeout=0.2)
            except queue.Empty:
                continue
            if msg is None:
                self._died()
            item = self._item(msg)
            if item is None:
                return
            self.arrived_s = arrived
            yield item

    def _item(self, msg) -> Sample | Gap | None:
        if isinstance(msg, list):
            t_s, code, volts, channel, rnd, _ = msg
            return Sample(t_s, code, volts, channel, rnd)
        if "gap" in msg:
            t_s, channel, error, _ = msg["gap"]
            return Gap(t_s, channel, error)
        if "end" in msg:
            self.stats = SamplerStats(**msg["end"])
            self.handoff = msg.get("handoff", {})
            self._ended = True
            return None
        self._ended = True  # nothing follows the error: close() need not wait for its end
        raise SamplingError(f"the sampling process could not start: {msg['error']}")

    def _arrival(self, sent_ns: int) -> float:
        # How long ago it was sent, on the shared monotonic clock, moved onto ours.
        return self._clock() - max(time.monotonic_ns() - sent_ns, 0) * 1e-9

    def _died(self) -> None:
        self._ended = True
        code = self._proc.wait()
        raise SamplingError(f"the sampling process ended unexpectedly (exit status {code})")

    def close(self, timeout_s: float = 5.0) -> None:
        """Stop the child, take its counters and wait for it (at most ``timeout_s``, then it
        is killed); idempotent."""
        proc = self._proc
        if proc.stdin is not None and not proc.stdin.closed:
            # A child that has already ended breaks the pipe: the write fails, and so does the
            # close's flush of "stop", which still closes the pipe (left open, the collector
            # would close it later and fail in whatever code runs then).
            with contextlib.suppress(OSError):
                proc.stdin.write("stop\n")
            with contextlib.suppress(OSError):
                proc.stdin.close()
        deadline = time.monotonic() + timeout_s
        while not self._ended and time.monotonic() < deadline:
            try:
                msg, _ = self._queue.get(timeout=max(deadline - time.monotonic(), 0.01))
            except queue.Empty:
                break
            if msg is None:
                break
            if isinstance(msg, dict) and "end" in msg:
                self._item(msg)
        try:
            proc.wait(max(deadline - time.monotonic(), 0.1))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        # The child has ended, so the reader meets the pipe's end at once; on a loaded machine
        # that can take over a second, and a pipe left open is closed only by the collector.
        self._reader.join(max(timeout_s, 1.0))
        if proc.stdout is not None and not self._reader.is_alive():
            proc.stdout.close()


def _given(proc: subprocess.Popen | None, spec: SamplerSpec) -> subprocess.Popen | None:
    """A started child sent its spec, or None when there is none or it has gone."""
    if proc is None:
        return None
    try:
        assert proc.stdin is not None
        proc.stdin.write(spec.to_json() + "\n")
        proc.stdin.flush()
        return proc
    except OSError:  # it died (a broken pipe): a new one is started instead
        proc.kill()
        proc.wait()
        for pipe in (proc.stdin, proc.stdout):
            with contextlib.suppress(OSError):
                pipe.close()
        return None


def serve(spec: SamplerSpec, fd: int) -> int:
    """The child: sample and write JSON lines to ``fd`` until the duration ends or stdin
    says stop."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    out = PipeWriter(fd)

    def send(msg) -> None:
        out.write((json.dumps(msg) + "\n").encode())

    try:
        sampler, bus, _, _ = open_sampler(spec)
    except Exception as e:  # reported to the parent, which says it in its own words
        send({"error": f"{type(e).__name__}: {e}"})
        out.drain()
        return 1
    try:
        send({"priority": raise_priority(spec.priority)})

        def watch_stdin() -> None:
            sys.stdin.readline()  # a line, or its end: the parent has gone
            sampler.stop()

        threading.Thread(target=watch_stdin, daemon=True).start()
        for item in sampler.samples(duration_s=spec.duration_s, gaps=True):
            sent = time.monotonic_ns()
            if isinstance(item, Gap):
                send({"gap": [item.t_s, item.channel, item.error, sent]})
            else:
                send([item.t_s, int(item.code), float(item.volts), item.channel, item.round,
                      sent])  # fmt: skip
        handoff = {"dropped": out.dropped, "backlog_peak_bytes": out.backlog_peak,
                   "pipe_bytes": out.pipe_bytes}  # fmt: skip
        send({"end": dataclasses.asdict(sampler.stats), "handoff": handoff})
        out.drain()
    except BrokenPipeError:  # the parent has gone: nothing to report to
        return 0
    finally:
        bus.close()
    return 0
