"""The stream's sampling process, started before the command imports what it runs.

Starting a Python process that imports the driver side takes about 0.2 s of CPU, and the
stream's own imports about as much again. Started one after the other, on a machine whose
cores are busy, they put a second or more between the command's start and its first
sample. So ``whiskerid stream`` starts its sampling process as soon as its arguments are
parsed (:func:`prestart`): the child imports its modules while the stream imports its own,
then waits for the sampler's spec on its standard input
(:class:`whiskerid.hw.SamplingProcess` sends it). A stream that stops before it samples
(bad input) ends the waiting child with :func:`discard`; a child whose parent has gone sees
its standard input end and exits.
"""

import subprocess
import sys

#: Where the prestarted child is kept until the stream takes it.
_ATTR = "_sampling_child"


def prestart(args) -> None:
    """Start the sampling child of a stream that will use one (not ``--fast``, not
    ``--simulate``: those sample in the stream's own process or make their terrain first),
    keeping it on ``args``."""
    if args.command != "stream" or args.fast or args.simulate is not None:
        return
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", "whiskerid.hw._sampling_child"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
        )
    except OSError:  # the stream starts one itself later, and says what is wrong
        return
    setattr(args, _ATTR, proc)


def take(args) -> subprocess.Popen | None:
    """The prestarted child, now the caller's (None when there is none)."""
    return args.__dict__.pop(_ATTR, None)


def discard(args) -> None:
    """End a prestarted child the stream did not take: its standard input ends, so it
    exits without sampling."""
    proc = take(args)
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
