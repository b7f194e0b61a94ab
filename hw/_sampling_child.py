"""The sampling child process's entry point (``python -m whiskerid.hw._sampling_child SPEC``):
see :mod:`whiskerid.hw._sampling_process`. A module of its own, so that running it does not
import the module that defines it a second time."""

import json
import sys

from ._sampling_process import SamplerSpec, serve

if __name__ == "__main__":
    sys.exit(serve(SamplerSpec(**json.loads(sys.argv[1])), sys.stdout.fileno()))
