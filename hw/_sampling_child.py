"""The sampling child process's entry point (``python -m whiskerid.hw._sampling_child SPEC``):
see :mod:`whiskerid.hw._sampling_process`. A module of its own, so that running it does not
import the module that defines it a second time.

Without ``SPEC`` it imports its modules, then reads the spec as the first line of its
standard input (``whiskerid stream`` starts it so before its own imports, and sends the spec
once it has one); when its standard input ends first it exits without sampling."""

import signal

# Ignored from the start, as :func:`serve` does: Ctrl-C and systemd's SIGTERM reach the
# whole process group, and the parent decides when sampling ends.
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGTERM, signal.SIG_IGN)

import json  # noqa: E402
import sys  # noqa: E402

from ._sampling_process import SamplerSpec, serve  # noqa: E402

if __name__ == "__main__":
    spec = sys.argv[1] if len(sys.argv) > 1 else sys.stdin.readline()
    if not spec.strip():  # the stream stopped before it sampled
        sys.exit(0)
    sys.exit(serve(SamplerSpec(**json.loads(spec)), sys.stdout.fileno()))
