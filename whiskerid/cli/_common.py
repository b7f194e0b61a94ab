"""What the commands share: the error they raise on bad input, stderr output, JSON, help format.

Imports nothing from the library at module level: the parser is built from these helpers and
:mod:`whiskerid._choices` alone, so that ``--help`` does not start JAX.
"""

import argparse
import math
import os
import sys
from pathlib import Path

from ._progress import (  # noqa: F401  (re-exported: the commands import them from here)
    QUIET_HELP,
    STATUS_DELAY_S,
    Ticker,
    add_quiet_everywhere,
    progress_step,
    say,
    show_progress,
    start_progress,
)


class CommandError(Exception):
    """Bad input detected by a command (reported on one line, exit status 2)."""


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows each option's default, except where there is none to show (``None``, a flag's
    ``False``, or a required option)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.default is None or action.default is False or action.required:
            return action.help
        return super()._get_help_string(action)


#: Help of ``--context`` (train, evaluate, classify), completed by each command's default.
CONTEXT_HELP = (
    "signal each label rests on (s): the window and the windows before it, fused (mean "
    "log-probability; the label lags a change of terrain by up to S minus one window)"
)


def record_or_paper(path: Path | None):
    """The whisker record at ``path`` (TOML), or the paper's whisker when ``path`` is None."""
    from ..model import load_record, paper_record

    return paper_record() if path is None else load_record(path)


def load_model(path: Path, context_s: float | None = None):
    """A trained classifier, with the signal its labels rest on overridden if ``context_s``."""
    from ..classify import ClassifierModel

    model = ClassifierModel.load(path)
    if context_s is not None:
        model.context_s = context_s  # checked by the model
    return model


def json_safe(value):
    """``value`` with every non-finite float (NaN, ±inf, NumPy's too) replaced by None.

    Standard JSON has no NaN or Infinity; ``null`` is what other tools can read.
    """
    import numpy as np

    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def one_line(err: BaseException) -> str:
    """The error's message on one line (its type's name if it has none)."""
    return " ".join(str(err).split()) or type(err).__name__


# --------------------------------------------------------------------------- output policy
#: The sentence each writing command's ``--force`` help starts with.
FORCE_HELP = (
    "replace outputs that already exist (without it an existing output is refused); an output "
    "that is, or lies inside, one of the command's inputs is refused even with --force"
)


class _Watch:
    """The outputs of the running command, so that an interrupt can say what was written."""

    def __init__(self) -> None:
        self.outputs: list[Path] = []
        self.start_ns = 0
        self.notes: list = []  # callables returning a sentence (or None) for the report

    def reset(self) -> None:
        import time

        self.outputs, self.notes, self.start_ns = [], [], time.time_ns()

    def written(self) -> list[str]:
        """The outputs written (or changed) since the command started, as short phrases."""
        done = []
        for p in self.outputs:
            if p.is_file() and p.stat().st_mtime_ns >= self.start_ns:
                done.append(str(p))
            elif p.is_dir():
                new = sum(
                    1 for f in p.rglob("*") if f.is_file() and f.stat().st_mtime_ns >= self.start_ns
                )
                if new:
                    done.append(f"{new} file(s) under {p}")
        return done


WATCH = _Watch()


def _as_list(given) -> list[Path]:
    if given is None:
        return []
    return [Path(p) for p in (given if isinstance(given, list | tuple) else [given])]


def _within(inner: Path, outer: Path) -> bool:
    """Whether ``inner`` is ``outer`` or lies inside it (through links too)."""
    from ..io import same_file

    if same_file(inner, outer):
        return True
    try:
        a, b = inner.resolve(), outer.resolve()
    except OSError:
        return False
    return b in a.parents


def model_folder(path: Path) -> Path:
    """The folder of a model given as its folder or as its ``model.json``."""
    path = Path(path)
    return path.parent if path.is_file() and path.name == "model.json" else path


def check_outputs(
    outputs: dict[str, Path | None],
    inputs: dict[str, Path | list | None],
    *,
    force: bool,
    folders: tuple[str, ...] = (),
    exists_hint: str = "pass --force to replace it",
    min_free_bytes: int = 0,
) -> None:
    """The one output policy of every command that writes; call it before any work.

    Refused, with a one-line reason:

    - an output that is, or lies inside, anything the command reads or may be asked to
      read (a recording, a record, a model folder, a dataset tree, a chain), even with
      ``force``: writing it would destroy what the command needs;
    - an input that lies inside a folder output (the folder would be replaced);
    - an output that already exists (a folder output: one that is not empty), unless
      ``force``;
    - two outputs that are the same file;
    - an output whose folder cannot be written, or a file where a folder is needed (and
      the other way round), or less free space than ``min_free_bytes``.

    The outputs are remembered, so that an interrupted command can say what it kept.

    Args:
        outputs: Option name → path to write (None for an option not given).
        inputs: Option name → path(s) read: files or folders (None for one not given).
        force: Whether existing outputs may be replaced.
        folders: The names in ``outputs`` that are folders.
        exists_hint: What to do about an existing output, for the message.
        min_free_bytes: Free space the outputs need at least.

    Raises:
        CommandError: What is wrong and what to do.
    """
    given = {flag: Path(p) for flag, p in outputs.items() if p is not None}
    for flag, out in given.items():
        for name, value in inputs.items():
            for src in _as_list(value):
                if _within(out, src):
                    what = "is also" if _within(src, out) else "lies inside"
                    raise CommandError(
                        f"{flag} {out} {what} the input {name} {src}: it would be overwritten, "
                        "destroying what this command reads (even with --force); give another path"
                    )
                if flag in folders and _within(src, out):
                    raise CommandError(
                        f"the input {name} {src} lies inside the output folder {flag} {out}; "
                        "give another folder"
                    )
    seen: dict[Path, str] = {}
    for flag, out in given.items():
        key = out.resolve()
        if key in seen:
            raise CommandError(f"{flag} and {seen[key]} are the same path {out}; give two")
        seen[key] = flag
        _check_one(flag, out, is_folder=flag in folders, force=force, hint=exists_hint)
        if not force and not (out.exists() or out.is_symlink()):
            from ..io import expect_new

            expect_new(out)  # published only if still absent: no check-then-write race
        if min_free_bytes:
            _check_space(flag, out, min_free_bytes)
    WATCH.outputs.extend(given.values())


def _check_one(flag: str, out: Path, *, is_folder: bool, force: bool, hint: str) -> None:
    import os

    if is_folder:
        if out.exists() and not out.is_dir():
            raise CommandError(f"{flag} {out} is a file; give a folder")
        if out.is_dir() and any(out.iterdir()) and not force:
            raise CommandError(f"{flag} {out} already exists and is not empty; {hint}")
    else:
        if out.is_dir():
            raise CommandError(f"{flag} {out} is a folder; give a file name")
        if out.exists() and not out.is_file():  # even with --force: not ours to replace
            raise CommandError(
                f"{flag} {out} is not a regular file (a device, pipe or socket); give a file name"
            )
        if out.is_symlink() and not out.exists() and not force:
            raise CommandError(
                f"{flag} {out} is a link to {os.readlink(out)}, which does not exist; "
                f"{hint} (the link is replaced, not its target)"
            )
        if out.exists() and not force:
            raise CommandError(f"{flag} {out} already exists; {hint}")
    parent = next((p for p in [out, *out.parents] if p.exists()), Path("."))
    if parent != out and not parent.is_dir():
        raise CommandError(f"{flag} {out}: {parent} is a file, not a folder")
    if not os.access(parent if parent.is_dir() else parent.parent, os.W_OK | os.X_OK):
        raise CommandError(f"{flag} {out}: {parent} cannot be written (no permission)")


def _check_space(flag: str, out: Path, need: int) -> None:
    import shutil

    parent = next((p for p in [out, *out.parents] if p.exists()), Path("."))
    free = shutil.disk_usage(parent).free
    if free < need:
        raise CommandError(
            f"{flag} {out}: {free / 1e6:.3g} MB free, and the output needs about "
            f"{need / 1e6:.3g} MB; free some space or choose another place"
        )


# --------------------------------------------------------------------------- interrupts
class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived (a KeyboardInterrupt, so loops that stop on Ctrl-C stop)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


class InterruptPolicy:
    """SIGINT and SIGTERM: stop, say in one line what was kept, exit 128 + the signal.

    By default a signal raises :class:`Interrupted` at once. Inside :meth:`deferred`, the
    first signal only sets :attr:`requested` (the code polls :meth:`stop_requested` at a safe
    point, such as between two MCMC steps, and stops there); a second one raises at once.

    A signal can land inside a callback whose exceptions Python only reports ("Exception
    ignored in ...": JAX's garbage-collection callback, a ``__del__``): the
    :data:`sys.unraisablehook` installed here notices the swallowed interrupt and raises it
    again at the next point where it can propagate. Whatever happens, :attr:`signum` stays
    set, and the command's caller checks it before it exits (:meth:`lost`).

    With ``keep`` (the command line's own process), the handlers stay after the command has
    stopped on a signal, until the process exits: a later signal then ends the process at
    once with the same status (128 + the first signal), never by the default action. They
    stay after a command that ended normally too: a signal in the interpreter's teardown
    (its last half second, JAX's and XLA's exit) ends the process at once with 128 + the
    signal and one line (:attr:`command` names it), its outputs complete.
    """

    def __init__(self, *, keep: bool = False) -> None:
        self.signum: int | None = None
        self.requested = False
        self.stopping = False  # set once the command has caught its interrupt
        self.keep = keep
        self.exit_status: int | None = None  # once the command has stopped on a signal
        self.finished = False  # the command ended normally; the process is exiting
        self.command = ""  # the command as typed, for the line said in the teardown
        self._defer = False
        self._previous: dict = {}
        self._hook = None
        self._in_hook = False  # in the unraisable hook: a signal is passed on, not raised
        self._pending = False  # a swallowed signal is to be raised again

    def __enter__(self) -> "InterruptPolicy":
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._previous[sig] = signal.signal(sig, self._handle)
            self._hook = sys.unraisablehook
            sys.unraisablehook = self._unraisable
        return self

    def __exit__(self, *exc) -> None:
        import signal

        if self.keep and (self.stopping or self.signum is not None):
            self.stopping = True  # the handlers stay, until the process exits
            return
        if self.keep and exc[0] is None:
            self.finished = True  # the handlers stay: the teardown is this command's too
            return
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous = {}
        if self._hook is not None:
            sys.unraisablehook, self._hook = self._hook, None

    def _handle(self, signum, frame) -> None:
        if self.finished and not self.stopping:
            # The command ended and the process is exiting: raised here, the interrupt would
            # be a traceback from an exit handler (or the default action's -15).
            self.stopping = True
            self.signum = signum
            self.exit_status = 128 + int(signum)
            try:
                line = self.report(Interrupted(signum)).replace(")", ") as it exited", 1)
                print(f"whiskerid {self.command}: {line}", file=sys.stderr)
            finally:
                exit_now(self.exit_status)
        if self.stopping:
            # The command has stopped: it is saying what it kept and tearing down. A signal
            # raised there would land in native code being torn down (a crash): the process
            # ends now, with the first signal's status.
            if self.keep:
                exit_now(self.exit_status or 128 + int(signum))
            return
        if self._in_hook:  # inside the unraisable hook: raised here, it would be lost
            self._again()
            return
        first = self.signum is None
        self.signum = signum
        self._pending = False
        if self._defer and first:
            self.requested = True
            say("stopping after the current step (send the signal again to stop at once)")
            return
        raise Interrupted(signum)

    def _unraisable(self, unraisable) -> None:
        """An exception Python could not propagate: a swallowed interrupt is raised again."""
        if isinstance(unraisable.exc_value, KeyboardInterrupt) and self.signum is not None:
            if not self.stopping:
                self._in_hook = True
                try:
                    self._again()
                finally:
                    self._in_hook = False
            return
        (self._hook or sys.__unraisablehook__)(unraisable)

    def _again(self) -> None:
        """The signal again, from another thread a moment later (raised in the hook it would
        be swallowed again): the main thread takes it at its next point outside a callback."""
        import _thread
        import threading

        def trip():
            if self._pending and not self.stopping:
                _thread.interrupt_main(self.signum)

        self._pending = True
        timer = threading.Timer(0.01, trip)
        timer.daemon = True
        timer.start()

    def lost(self) -> bool:
        """Whether a signal came that the command did not stop on (swallowed where it could
        not propagate, or as the command ended): it must still exit 128 + the signal."""
        return self.signum is not None and not self.stopping

    def stop_requested(self) -> bool:
        """Whether a signal asked to stop (polled by code that stops at safe points)."""
        return self.requested

    def deferred(self):
        """A context in which the first signal is only recorded, not raised."""
        import contextlib

        @contextlib.contextmanager
        def ctx():
            self._defer = True
            try:
                yield self
            finally:
                self._defer = False

        return ctx()

    def status(self, err: BaseException) -> int:
        """The exit status for the interrupt ``err``: 130 for SIGINT, 143 for SIGTERM."""
        import signal

        signum = getattr(err, "signum", None) or self.signum or signal.SIGINT
        self.exit_status = 128 + int(signum)
        return self.exit_status

    def report(self, err: BaseException) -> str:
        """One line: which signal, and what was kept (or that nothing was written)."""
        import signal

        signum = getattr(err, "signum", None) or self.signum or signal.SIGINT
        name = signal.Signals(signum).name
        notes = [n for n in (note() for note in WATCH.notes) if n]
        kept = WATCH.written()
        what = "; ".join(notes) if notes else (
            f"kept (complete): {', '.join(kept)}" if kept else "nothing was written"
        )  # fmt: skip
        return f"interrupted ({name}); {what}"


_POLICY = InterruptPolicy()


def exit_now(status: int) -> None:
    """End the process now, stdout and stderr flushed where they can be (the command's files
    are already closed; a stream closed by its reader, or caught mid-write by a signal in the
    teardown, is left as it is)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except BaseException:  # a closed pipe, or a flush interrupted mid-write
            pass
    os._exit(status)


def start_command(*, keep: bool = False) -> InterruptPolicy:
    """A fresh interrupt policy and output watch for a command about to run (``keep``: the
    process ends with the command, see :class:`InterruptPolicy`)."""
    global _POLICY
    from ..io import clear_expected

    WATCH.reset()
    clear_expected()
    _POLICY = InterruptPolicy(keep=keep)
    return _POLICY


def interrupts() -> InterruptPolicy:
    """The running command's interrupt policy."""
    return _POLICY
