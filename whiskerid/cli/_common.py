"""What the commands share: the error they raise on bad input, stderr output, JSON, help format.

Imports nothing from the library at module level: the parser is built from these helpers and
:mod:`whiskerid._choices` alone, so that ``--help`` does not start JAX.
"""

import argparse
import math
import sys
from pathlib import Path


class CommandError(Exception):
    """Bad input detected by a command (reported on one line, exit status 2)."""


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows each option's default, except where there is none to show (``None``)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.default is None:
            return action.help
        return super()._get_help_string(action)


#: Help of ``--context`` (train, evaluate, classify), completed by each command's default.
CONTEXT_HELP = (
    "signal each label rests on (s): the window and the windows before it, fused (mean "
    "log-probability; the label lags a change of terrain by up to S minus one window)"
)


def say(*parts) -> None:
    """Print human-readable progress and results on stderr (stdout is kept for ``--json``)."""
    print(*parts, file=sys.stderr)


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
