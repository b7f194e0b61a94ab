"""Keeping a sampling process on its schedule on a busy machine.

Two things let a sampler keep a 5 ms schedule while other processes use every core:

* **Priority.** :func:`raise_priority` asks the kernel to run this process before ordinary
  ones: the real-time policy ``SCHED_FIFO`` where it is permitted (root, ``CAP_SYS_NICE``, an
  ``RLIMIT_RTPRIO`` above 0, or a systemd unit's ``CPUSchedulingPolicy=fifo``), else a raised
  nice value (``CAP_SYS_NICE`` or ``RLIMIT_NICE``), else nothing. It says which it got. A
  ``SCHED_FIFO`` sampler wakes within microseconds of its deadline whatever else runs, and
  costs the others little: it sleeps between slots (a read is well under a millisecond), and
  the kernel keeps 5 % of every second for ordinary processes in any case
  (``sched_rt_runtime_us``).
* **A hand-off that never waits.** :class:`PipeWriter` writes to the consumer's pipe in
  non-blocking mode, the pipe enlarged to hold minutes of samples: a consumer that is busy
  (compiling, or starved of CPU itself) delays the samples' arrival, never their reading.
  What the pipe cannot take at once is kept in a backlog and sent at the next slot; only a
  consumer stalled for longer than the pipe and the backlog hold loses samples, and they
  are counted.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import select
import time
from collections.abc import Iterator

#: ``fcntl`` command that sets a pipe's capacity (Linux; ``F_SETPIPE_SZ``).
_F_SETPIPE_SZ = getattr(fcntl, "F_SETPIPE_SZ", 1031)

#: Priority of the sampler under ``SCHED_FIFO`` (1..99): above ordinary work, below the
#: kernel's own real-time threads (interrupt handlers run at 50).
RT_PRIORITY = 20
#: Nice value asked for when real time is not permitted (-20 is the highest priority).
NICE = -10


def raise_priority(policy: str = "auto", *, rt_priority: int = RT_PRIORITY,
                   nice: int = NICE) -> str:  # fmt: skip
    """Run this process (its calling thread, and threads it starts later) before ordinary work.

    Args:
        policy: ``"auto"`` tries real time, then nice; ``"realtime"`` and ``"nice"`` try only
            that one; ``"none"`` leaves the priority alone.
        rt_priority: The ``SCHED_FIFO`` priority (1..99).
        nice: The nice value to ask for (-20..19; lower runs first).

    Returns:
        What was granted, in words: ``"SCHED_FIFO 20"``, ``"nice -10"``, or
        ``"normal (...)"`` with why a higher priority was not given.
    """
    if policy not in ("auto", "realtime", "nice", "none"):
        raise ValueError(f"priority {policy!r}: use auto, realtime, nice or none")
    if policy == "none":
        return "normal (asked for none)"
    refused = []
    if policy in ("auto", "realtime"):
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt_priority))
            return f"SCHED_FIFO {rt_priority}"
        except (OSError, AttributeError) as e:  # not permitted, or not Linux
            refused.append(f"SCHED_FIFO: {getattr(e, 'strerror', None) or e}")
    if policy in ("auto", "nice"):
        try:
            os.setpriority(os.PRIO_PROCESS, 0, nice)
            return f"nice {os.getpriority(os.PRIO_PROCESS, 0)}"
        except (OSError, AttributeError) as e:
            refused.append(f"nice {nice}: {getattr(e, 'strerror', None) or e}")
    return f"normal ({'; '.join(refused)})"


@contextlib.contextmanager
def raised_priority(policy: str = "auto", **kw) -> Iterator[str]:
    """:func:`raise_priority` for the time of a ``with`` block; the calling thread's policy
    and nice value are put back after it (a command run from Python leaves its caller as it
    found it)."""
    try:
        before = (os.sched_getscheduler(0), os.sched_getparam(0),
                  os.getpriority(os.PRIO_PROCESS, 0))  # fmt: skip
    except (OSError, AttributeError):  # not Linux: nothing to put back
        before = None
    try:
        yield raise_priority(policy, **kw)
    finally:
        if before is not None:
            with contextlib.suppress(OSError):
                os.sched_setscheduler(0, before[0], before[1])
            with contextlib.suppress(OSError):
                os.setpriority(os.PRIO_PROCESS, 0, before[2])


class PipeWriter:
    """Write bytes to a pipe without ever waiting for its reader.

    Args:
        fd: The pipe's file descriptor (put in non-blocking mode).
        pipe_bytes: Capacity asked for the pipe (the kernel caps it at
            ``/proc/sys/fs/pipe-max-size``, 1 MiB by default: about 80 s of samples as JSON
            lines at 200 Hz).
        max_backlog: Bytes kept here while the pipe is full; beyond them new writes are
            dropped and counted (:attr:`dropped`).

    Attributes:
        dropped: Writes dropped because the reader stalled for longer than everything holds.
        pipe_bytes: The pipe's capacity as granted.
        backlog_peak: The largest backlog held (bytes).
    """

    def __init__(self, fd: int, *, pipe_bytes: int = 1 << 20, max_backlog: int = 16 << 20):
        self.fd = fd
        self.max_backlog = int(max_backlog)
        self.dropped = 0
        self.backlog_peak = 0
        self._pending = bytearray()
        os.set_blocking(fd, False)
        try:
            self.pipe_bytes = fcntl.fcntl(fd, _F_SETPIPE_SZ, pipe_bytes)
        except OSError:  # not a pipe, or above pipe-max-size: keep what it has
            self.pipe_bytes = 0

    @property
    def backlog(self) -> int:
        """Bytes written but not yet in the pipe."""
        return len(self._pending)

    def write(self, data: bytes) -> None:
        """Queue ``data`` and send what the pipe takes now.

        Raises:
            BrokenPipeError: The reader has gone.
        """
        if len(self._pending) + len(data) > self.max_backlog:
            self.dropped += 1
        else:
            self._pending += data
            self.backlog_peak = max(self.backlog_peak, len(self._pending))
        self._send()

    def _send(self) -> None:
        while self._pending:
            try:
                n = os.write(self.fd, self._pending)
            except BlockingIOError:
                return
            del self._pending[:n]

    def drain(self, timeout_s: float = 5.0) -> bool:
        """Wait (at most ``timeout_s``) until the backlog is in the pipe; True when it is."""
        deadline = time.monotonic() + timeout_s
        while self._pending and (left := deadline - time.monotonic()) > 0:
            select.select([], [self.fd], [], min(left, 0.1))
            self._send()
        return not self._pending
