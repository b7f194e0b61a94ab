"""The stream's links to a robot: its speed in, labels out, as JSON lines.

Speed comes as one JSON object per line, ``{"speed_mps": 0.31}`` (or a bare number), from
standard input or UDP datagrams on a localhost port, or from an odometry CSV (columns ``t``
and ``speed_mps``) when replaying a recording. Labels go out as one JSON object per window,
``{"t_s": 12.5, "label": "brick", "confidence": 0.93, "speed_mps": 0.31, "reason": ""}``,
to standard output or as UDP datagrams to a localhost port. Only localhost is used: the
stream is a component of the robot's own computer, not a network service.
"""

from __future__ import annotations

import json
import math
import socket
import sys
import threading
import time
from typing import Any, TextIO

import numpy as np

from whiskerid.io import read_recording

LOCALHOST = "127.0.0.1"

#: Fastest plausible robot speed (m/s): a wheeled or legged ground robot carrying a whisker
#: moves at up to a few metres per second (the paper's runs: 0.1 to 0.3 m/s). A larger value
#: is a unit error (mm/s, km/h) or a corrupt message, and is never used to label a window.
MAX_SPEED_MPS = 5.0


def check_speed_mps(value: float, what: str) -> float:
    """``value`` if it is a plausible robot speed (finite, 0 to :data:`MAX_SPEED_MPS` m/s).

    Raises:
        ValueError: Otherwise, naming ``what`` (a flag or a file) and what to do.
    """
    v = float(value)
    if not (math.isfinite(v) and 0 <= v <= MAX_SPEED_MPS):
        raise ValueError(
            f"{what} {value!r}: not plausible as a robot speed (0 to {MAX_SPEED_MPS:g} m/s); "
            "give it in metres per second"
        )
    return v


def parse_endpoint(text: str, flag: str) -> str | int:
    """``"-"`` (standard input/output) or the port of ``"udp:PORT"``.

    Raises:
        ValueError: Anything else.
    """
    if text == "-":
        return "-"
    kind, _, port = text.partition(":")
    if kind == "udp" and port.isdigit() and 0 < int(port) < 65536:
        return int(port)
    raise ValueError(f"{flag} {text!r}: use - (standard input/output) or udp:PORT (localhost)")


def speed_of(message: str) -> float | None:
    """The speed in one JSON line (``{"speed_mps": v}``, ``{"speed": v}`` or ``v``), or None."""
    try:
        value: Any = json.loads(message)
    except ValueError:
        return None
    if isinstance(value, dict):
        value = value.get("speed_mps", value.get("speed"))
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) and 0 <= value <= MAX_SPEED_MPS else None


class SpeedFeed:
    """The robot's latest speed, updated by a reader thread; call it for the current value.

    Args:
        where: ``"-"`` for standard input, or a UDP port on localhost.
        stream: Text stream read for ``"-"`` (standard input by default).

    Attributes:
        messages: Lines that gave a speed.
        bad_messages: Lines that did not (ignored).
    """

    def __init__(self, where: str | int, *, stream: TextIO | None = None) -> None:
        self.latest: float | None = None
        self.updated_at: float | None = None  # time.monotonic() of the latest good message
        self.messages = 0
        self.bad_messages = 0
        self._sock: socket.socket | None = None
        if where == "-":
            lines = stream if stream is not None else sys.stdin
            target = lambda: self._read_lines(lines)  # noqa: E731
        else:
            self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self._sock.bind((LOCALHOST, int(where)))
            target = self._read_udp
        self._thread = threading.Thread(target=target, name="whiskerid-speed", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int | None:
        """The UDP port listened on (useful when bound to port 0), or None."""
        return None if self._sock is None else self._sock.getsockname()[1]

    def _take(self, text: str) -> None:
        v = speed_of(text)
        if v is None:
            self.bad_messages += 1
        else:
            self.latest = v
            self.updated_at = time.monotonic()
            self.messages += 1

    def _read_lines(self, lines: TextIO) -> None:
        for line in lines:
            if line.strip():
                self._take(line)

    def _read_udp(self) -> None:
        assert self._sock is not None
        while True:
            try:
                data = self._sock.recv(65536)
            except OSError:  # closed
                return
            for line in data.decode("utf-8", "replace").splitlines():
                if line.strip():
                    self._take(line)

    def __call__(self, t_s: float) -> float | None:
        return self.latest

    def age_s(self) -> float | None:
        """Seconds since the latest good message (None: none yet)."""
        return None if self.updated_at is None else time.monotonic() - self.updated_at

    def close(self) -> None:
        """Stop listening (the stdin reader ends with its stream)."""
        if self._sock is not None:
            self._sock.close()


def odometry_speed(path) -> Any:
    """``speed(t_s)`` interpolated from an odometry CSV with columns ``t`` and ``speed_mps``.

    Where the log says nothing (before its first row, after its last, next to a NaN or an
    implausible value beyond :data:`MAX_SPEED_MPS`) the speed is NaN: the stream then
    labels with the last known speed and says so.

    Raises:
        whiskerid.io.RecordingError: Not readable, or no ``speed_mps`` column.
    """
    rec = read_recording(path)
    t, v = rec.t, np.asarray(rec.signal("speed_mps"), dtype=float)
    v = np.where((v >= 0) & (v <= MAX_SPEED_MPS), v, np.nan)  # NaN stays NaN

    def speed(t_s: float) -> float:
        if not t[0] <= t_s <= t[-1]:
            return float("nan")
        return float(np.interp(t_s, t, v))

    return speed


class LabelSink:
    """Write each window's label as a JSON line to standard output or a localhost UDP port.

    Args:
        where: ``"-"`` or a UDP port.
        stream: Text stream for ``"-"`` (standard output by default).
    """

    def __init__(self, where: str | int, *, stream: TextIO | None = None) -> None:
        self._stream = (stream if stream is not None else sys.stdout) if where == "-" else None
        self._port = None if where == "-" else int(where)
        self._sock = None if self._port is None else socket.socket(socket.AF_INET,
                                                                    socket.SOCK_DGRAM)  # fmt: skip
        self.sent = 0

    def __call__(self, w) -> None:
        msg = {
            "t_s": round(w.t_end_s, 4),
            "label": w.label,
            "confidence": round(w.confidence, 4),
            "speed_mps": w.speed_mps,
            "reason": w.reason,
        }
        if w.speed_note:
            msg["speed_note"] = w.speed_note
        line = json.dumps(msg, allow_nan=False)
        if self._sock is not None:
            try:
                self._sock.sendto(line.encode() + b"\n", (LOCALHOST, self._port))
            except OSError:  # nobody listening yet: a label is not worth stopping for
                return
        else:
            assert self._stream is not None
            self._stream.write(line + "\n")
            self._stream.flush()
        self.sent += 1

    def close(self) -> None:
        """Close the socket, if any."""
        if self._sock is not None:
            self._sock.close()
