"""The ``whiskerid`` command line: one module per command, parsing and printing only."""

from ._prestart import spawn_early

spawn_early()  # ``whiskerid stream``: its sampling process imports while this one does

from ._main import build_parser as build_parser  # noqa: E402
from ._main import main as main  # noqa: E402
