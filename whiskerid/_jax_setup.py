"""JAX settings every model needs, applied once before the first array is made.

The modal sums near the clamp and the eigenvalue bisection lose their accuracy in float32, so
float64 (``jax_enable_x64``) is switched on by every sub-package that computes with JAX.

The command line (:mod:`whiskerid.cli`) silences XLA's own log (its "Very slow compile? If you
want to file a bug…" banner among it) and asks, through :data:`SLOW_COMPILE_ENV`, for a short
note of its own instead when one program takes long to compile; a user's program that imports
whiskerid sees neither.
"""

import math
import os
import sys

import jax
import jax.monitoring

jax.config.update("jax_enable_x64", True)

#: Seconds of one compilation above which the command line prints a note (unset: no note).
SLOW_COMPILE_ENV = "WHISKERID_SLOW_COMPILE_NOTE_S"
#: The event JAX records for each compilation by XLA (jax.monitoring).
_COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"


def _slow_after() -> float:
    try:
        value = float(os.environ.get(SLOW_COMPILE_ENV, "nan"))
    except ValueError:
        return math.nan
    return value if value > 0 else math.nan


_SLOW_S = _slow_after()


def _note_slow_compile(event: str, duration: float, **kwargs) -> None:
    if event == _COMPILE_EVENT and duration > _SLOW_S:
        name = kwargs.get("fun_name") or "a program"
        print(
            f"note: compiling {name} took {duration:.0f} s on this machine; it is kept in the "
            "compilation cache, so later runs load it instead",
            file=sys.stderr,
            flush=True,
        )


if not math.isnan(_SLOW_S):
    jax.monitoring.register_event_duration_secs_listener(_note_slow_compile)
