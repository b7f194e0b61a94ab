"""The ``whiskerid`` command line: the parser, the entry point, errors and JSON output.

Every command has ``--help``; ``--json`` prints one JSON object on stdout while human text
and progress bars go to stderr; the exit status is 0 on success, 2 with a one-line reason on
bad input, and 130 (SIGINT, Ctrl-C) or 143 (SIGTERM) with one line saying what was kept
when a signal stops the command.
Each command is one module of this package (options, and a ``run`` function that calls the
library and prints). Building the parser imports no part of the library, so that ``--help``
answers without starting JAX: the run functions import what they use.
"""

import argparse
import gc
import json
import os
import signal
import sys
import time
import zipfile

from . import (
    _analyze,
    _calibrate,
    _classify,
    _dataset,
    _demo,
    _evaluate,
    _fleet,
    _posterior,
    _record,
    _simulate,
    _stream,
    _train,
)
from ._cache import enable_compile_cache, quiet_xla
from ._common import (
    CommandError,
    Interrupted,
    add_quiet_everywhere,
    exit_now,
    interrupts,
    json_safe,
    one_line,
    show_progress,
    start_command,
    start_progress,
)
from ._prestart import prestart

# Reported on one line with exit status 2. The library's own errors (RecordError,
# RecordingError, CalibrationError, ModelError, PosteriorError) are ValueErrors. The readers
# turn corrupt archives into RecordingErrors with the path; BadZipFile, EOFError and
# MemoryError are a safety net.
_EXPECTED = (
    CommandError,
    ValueError,
    OSError,
    RuntimeError,
    zipfile.BadZipFile,
    EOFError,
    MemoryError,
)


class _VersionAction(argparse.Action):
    """``--version``: reads the installed version only when asked."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help="show program's version number and exit"):  # fmt: skip
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from .._version import __version__

        parser._print_message(f"whiskerid {__version__}\n", sys.stdout)
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``whiskerid`` command."""
    parser = argparse.ArgumentParser(
        prog="whiskerid",
        description=(
            "Differentiable system identification for compliant whisker sensors: beam "
            "models in JAX (the paper's Eq. 1 and the exact modal model), Hall sensor and "
            "ADS1115 models, simulation, calibration, damping posteriors, terrain "
            "classification and online streaming on a Raspberry Pi. Start with "
            "'whiskerid demo'."
        ),
    )
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _demo.add_parser(sub)
    _simulate.add_parser(sub)
    _calibrate.add_calibrate(sub, CommandError)
    _posterior.add_posterior(sub, CommandError)
    _dataset.add_parser(sub)
    _train.add_parser(sub)
    _evaluate.add_parser(sub)
    _classify.add_parser(sub)
    _record.add_parser(sub)
    _analyze.add_parser(sub)
    _stream.add_parser(sub)
    _fleet.add_parser(sub)
    add_quiet_everywhere(parser)
    return parser


#: Commands that show progress of their own (a bar, a line per window) instead of the
#: status line every other command shows once it has run a few seconds.
_OWN_PROGRESS = ("posterior", "stream", "record", "fleet calibrate")
#: Commands that end the process at once after their outputs are closed and flushed: the
#: interpreter's own exit (JAX's and XLA's teardown) takes about half a second more, and
#: these commands leave nothing that needs it (no open HDF5 file, no worker thread).
_FAST_EXIT = ("calibrate", "simulate")


def _name(args) -> str:
    """The command as typed: ``calibrate``, ``dataset synth``, ``fleet check``."""
    sub = getattr(args, "dataset_command", None) or getattr(args, "fleet_command", None)
    return f"{args.command} {sub}" if sub else args.command


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``whiskerid`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    prestart(args)  # a stream's sampling process imports while this one does
    quiet_xla()
    enable_compile_cache()
    start = time.perf_counter()
    try:
        status = _run(args, start, fast_exit=argv is None)
        if argv is None and interrupts().exit_status is not None:
            # Stopped on a signal, its outputs closed and the line said: the interpreter's
            # teardown (JAX's, XLA's) is where a crash or another signal would land.
            gc.collect()  # files a traceback kept open are closed (and flushed) first
            exit_now(status)
        return status
    except BrokenPipeError:
        # The reader left (``| head``): what it read is all it wanted. No traceback, and
        # nothing more written to the closed pipe at exit.
        devnull = os.open(os.devnull, os.O_WRONLY)
        for stream in (sys.stdout, sys.stderr):
            try:
                os.dup2(devnull, stream.fileno())
            except (OSError, ValueError):
                pass
        return 128 + signal.SIGPIPE


def _run(args, start: float, *, fast_exit: bool) -> int:
    """Run the parsed command; its exit status."""
    name = _name(args)
    ticker = start_progress(
        f"whiskerid {name}", show=show_progress(args) and name not in _OWN_PROGRESS
    )
    with start_command(keep=fast_exit) as policy:
        policy.command = name
        try:
            with ticker:
                result = args.func(args)
        except _EXPECTED as err:
            if policy.signum is not None:  # the interrupt, wrapped (a JAX host callback's)
                return _interrupted(args, policy, Interrupted(policy.signum))
            print(f"whiskerid {args.command}: error: {one_line(err)}", file=sys.stderr)
            return 2
        except KeyboardInterrupt as err:
            return _interrupted(args, policy, err)
        except Exception:
            if policy.signum is None:
                raise
            # A signal came, and the command failed after it (the interrupt swallowed by a
            # library that then went on with what it had): the signal's status, no traceback.
            return _interrupted(args, policy, Interrupted(policy.signum))
        if policy.lost():  # swallowed where it landed, or it came as the command ended
            return _interrupted(args, policy, Interrupted(policy.signum))
        if getattr(args, "json", False):
            result = {
                "command": args.command,
                **result,
                "elapsed_s": round(time.perf_counter() - start, 3),
            }
            print(json.dumps(json_safe(result), indent=2, allow_nan=False))
            sys.stdout.flush()  # here, not at exit: a closed pipe is reported in main
    if fast_exit and name in _FAST_EXIT:
        exit_now(0)
    return 0


def _interrupted(args, policy, err: BaseException) -> int:
    """Say in one line, no traceback, what was kept (or that nothing was written); the exit
    status for the signal."""
    policy.stopping = True  # from here on a signal would land in the teardown
    status = policy.status(err)  # before the line: a signal after it exits with this status
    print(f"whiskerid {args.command}: {policy.report(err)}", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
