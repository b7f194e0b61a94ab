"""Progress on stderr: the ``--quiet`` policy, the status line (:class:`Ticker`) and the steps
a long command names in it.

Imports nothing from the library, as :mod:`._common` (which re-exports these names): the
parser uses :func:`add_quiet_everywhere` without starting JAX.
"""

import argparse
import sys

QUIET_HELP = (
    "no progress on stderr: no bar and no status line for work that takes a while (results "
    "and errors are still printed)"
)


def show_progress(args) -> bool:
    """The one progress policy: bars on stderr unless ``--quiet``, whatever stdout carries."""
    return not getattr(args, "quiet", False)


def add_quiet_everywhere(parser: argparse.ArgumentParser) -> None:
    """Give every command (every leaf of the sub-command tree) a ``--quiet`` option, unless
    it has its own."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        if "--quiet" not in parser._option_string_actions:
            parser.add_argument("--quiet", action="store_true", help=QUIET_HELP)
        return
    for action in subs:
        for child in dict.fromkeys(action.choices.values()):
            add_quiet_everywhere(child)


class Ticker:
    """A status line on stderr for work that takes a while: what runs and for how long.

    Nothing is shown for the first ``delay_s`` seconds (a quick command stays silent). Then,
    on a terminal, one line (``whiskerid calibrate: fitting … 12 s``) is redrawn every second
    and erased at the end; elsewhere (a log, a pipe) a line is written when a step starts or
    a minute has passed without one, once the work has run three times ``delay_s``.
    :meth:`step` names the current step; :meth:`say` prints a line above the status. Every
    command has one (:func:`progress_step` names its steps); code without a bar of its own
    during a long phase can use one on its own: ``with Ticker("fleet calibrate",
    show=...) as t: t.step("compiling")``.
    """

    def __init__(self, name: str, *, show: bool = True, delay_s: float = 3.0) -> None:
        import threading

        self.name, self.show, self.delay_s = name, show, delay_s
        self.text = ""
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread = None
        self._drawn = False
        self._tty = sys.stderr.isatty()
        self._err = sys.stderr  # where the status goes
        self._start = 0.0
        self._last_line = 0.0

    def __enter__(self) -> "Ticker":
        import threading
        import time

        self._start = self._last_line = time.monotonic()
        if self.show and self._tty:
            # Anything else written to stderr first erases the status line (then it is
            # drawn again on the next tick): no text lands in the middle of it.
            sys.stderr = _Erasing(self._err, self)
        if self.show:
            self._thread = threading.Thread(target=self._run, daemon=True, name="progress")
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        with self._lock:
            self._erase()
        if isinstance(sys.stderr, _Erasing) and sys.stderr.ticker is self:
            sys.stderr = self._err

    def step(self, text: str) -> None:
        """Name the step now running (a line on a log, the status on a terminal)."""
        with self._lock:
            self.text = text
            if self.show and not self._tty and self._elapsed() >= 3 * self.delay_s:
                self._line()

    def say(self, *parts) -> None:
        """Print a line on stderr above the status line."""
        with self._lock:
            self._erase()
            print(*parts, file=self._err, flush=True)

    def _elapsed(self) -> float:
        import time

        return time.monotonic() - self._start

    def _status(self) -> str:
        what = f": {self.text}" if self.text else ""
        return f"{self.name}{what} … {self._elapsed():.0f} s"

    def _line(self) -> None:
        import time

        print(self._status(), file=self._err, flush=True)
        self._last_line = time.monotonic()

    def _erase(self) -> None:
        if self._drawn:
            self._err.write("\r\x1b[K")
            self._err.flush()
            self._drawn = False

    def _run(self) -> None:
        import time

        while not self._stop.wait(1.0):
            if self._elapsed() < (self.delay_s if self._tty else 3 * self.delay_s):
                continue
            with self._lock:
                if self._stop.is_set():
                    return
                if self._tty:
                    self._err.write("\r\x1b[K" + self._status())
                    self._err.flush()
                    self._drawn = True
                elif time.monotonic() - self._last_line >= 60.0:
                    self._line()


class _Erasing:
    """stderr while a status line is shown on a terminal: a write erases the status first."""

    def __init__(self, stream, ticker: Ticker) -> None:
        self.stream, self.ticker = stream, ticker

    def write(self, text: str) -> int:
        with self.ticker._lock:
            self.ticker._erase()
            return self.stream.write(text)

    def __getattr__(self, name):
        return getattr(self.stream, name)


_TICKER: Ticker | None = None
#: Seconds a command runs before its status line appears.
STATUS_DELAY_S = 3.0


def start_progress(name: str, *, show: bool) -> Ticker:
    """The running command's status line (see :class:`Ticker`); use it as a context."""
    global _TICKER
    _TICKER = Ticker(name, show=show, delay_s=STATUS_DELAY_S)
    return _TICKER


def progress_step(text: str) -> None:
    """Name the step the running command is in (shown once it has run a few seconds)."""
    if _TICKER is not None:
        _TICKER.step(text)


def say(*parts) -> None:
    """Print human-readable progress and results on stderr (stdout is kept for ``--json``),
    above the command's status line if one is shown."""
    if _TICKER is not None:
        _TICKER.say(*parts)
    else:
        print(*parts, file=sys.stderr)
