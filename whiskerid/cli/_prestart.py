"""The stream's sampling process, started before the command imports what it runs.

Starting a Python process that imports the driver side takes about 0.2 s of CPU, and the
stream's own imports (the command line, NumPy, the driver side, the classifier) about 0.3 s.
Started one after the other, on a machine whose cores are busy, they put a second or more
between the command's start and its first sample. So ``whiskerid stream`` starts its
sampling process first (:func:`spawn_early`, from this package's ``__init__``, before the
command line and NumPy are imported): the child imports its modules while the stream imports
its own, then waits for the sampler's spec on its standard input
(:class:`whiskerid.hw.SamplingProcess` sends it). A stream that stops before it samples (bad
input) ends the waiting child (:func:`discard`); a child whose parent has gone sees its
standard input end and exits.
"""

import os
import subprocess
import sys

#: Where the child is kept until the stream takes it.
_ATTR = "_sampling_child"
#: A child started by :func:`spawn_early`, before the arguments were parsed.
_early: list[subprocess.Popen] = []
#: Options after which a stream samples in its own process or does not run.
_NO_CHILD = ("-h", "--help", "--fast", "--simulate")


def _spawn() -> subprocess.Popen | None:
    try:
        return subprocess.Popen(
            [sys.executable, "-m", "whiskerid.hw._sampling_child"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
        )
    except OSError:  # the stream starts one itself later, and says what is wrong
        return None


def spawn_early() -> None:
    """Start the sampling child now when this process is ``whiskerid stream`` (the command,
    or ``python -m whiskerid.cli``: ``-m`` while the package is imported) and its options
    leave the sampling to a child; the parsed arguments decide later (:func:`prestart`)."""
    argv = sys.argv
    if os.path.basename(argv[0]) not in ("whiskerid", "-m") or argv[1:2] != ["stream"]:
        return
    if any(a.split("=")[0] in _NO_CHILD for a in argv[2:]):
        return
    proc = _spawn()
    if proc is not None:
        _early.append(proc)


def prestart(args) -> None:
    """Keep on ``args`` the sampling child of a stream that will use one (not ``--fast``, not
    ``--simulate``: those sample in the stream's own process or make their terrain first):
    the one started early, else one started now. An early child this command does not use
    is ended."""
    early = _early.pop() if _early else None
    if args.command != "stream" or args.fast or args.simulate is not None:
        _end(early)
        return
    proc = early or _spawn()
    if proc is not None:
        setattr(args, _ATTR, proc)


def take(args) -> subprocess.Popen | None:
    """The started child, now the caller's (None when there is none)."""
    return args.__dict__.pop(_ATTR, None)


def discard(args) -> None:
    """End a started child the stream did not take: its standard input ends, so it exits
    without sampling."""
    _end(take(args))


def _end(proc: subprocess.Popen | None) -> None:
    if proc is None:
        return
    for pipe in (proc.stdin, proc.stdout):
        if pipe is not None:
            pipe.close()
    try:
        proc.wait(5.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
