"""The ``whiskerid`` command line: one module per command, parsing and printing only."""

from ._main import build_parser as build_parser
from ._main import main as main
