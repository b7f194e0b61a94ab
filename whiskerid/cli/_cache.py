"""JAX's persistent compilation cache for the command line: a second run on the machine
loads the compiled programs instead of compiling them again.

The folder is :func:`whiskerid._compile_cache.cache_dir` (``$WHISKERID_COMPILE_CACHE``, else
``~/.cache/whiskerid/jax``). It is set through JAX's own environment variables before JAX is
imported, so a user's ``JAX_COMPILATION_CACHE_DIR`` wins. In a user's program, ``import
whiskerid`` changes nothing; the calibration's own program is cached in the same folder
when it is compiled (:mod:`whiskerid.fit._aot`).
"""

import os
from pathlib import Path

from .._compile_cache import CACHE_ENV as CACHE_ENV
from .._compile_cache import cache_dir as cache_dir

# JAX's options (lower case; upper case as environment variables) that cache every program.
_CACHE_ALL = {
    "jax_persistent_cache_min_compile_time_secs": 0.0,
    "jax_persistent_cache_min_entry_size_bytes": 0,
}


#: XLA's C++ log level for the command line: 3 keeps its errors and warnings (the "Very slow
#: compile?" banner is one) off the terminal; what goes wrong still arrives as a Python error,
#: and a slow compile gets the project's own note (whiskerid._jax_setup).
_XLA_LOG_LEVEL = "3"
#: One compilation longer than this (s) gets that note.
SLOW_COMPILE_S = 20.0


def quiet_xla() -> None:
    """Before JAX starts: XLA's own log off (unless the user set its level), the project's
    note on a slow compile on."""
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", _XLA_LOG_LEVEL)
    os.environ.setdefault("WHISKERID_SLOW_COMPILE_NOTE_S", f"{SLOW_COMPILE_S:g}")


def enable_compile_cache() -> Path | None:
    """Point JAX's persistent compilation cache at :func:`cache_dir` (before JAX starts).

    Every program is cached, however quick to compile: a calibration compiles dozens of
    small ones, which together take most of its time.
    """
    path = cache_dir()
    if path is None:
        return None
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None  # a read-only home: run without the cache rather than fail
    os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(path))
    for name, value in _CACHE_ALL.items():
        os.environ.setdefault(name.upper(), str(value))
    return path


def use_compile_cache(folder: Path | None) -> None:
    """Point JAX's persistent compilation cache at ``folder`` once JAX is imported (a
    command's own option overrides the environment), or switch it off with None. whiskerid's
    own saved programs (``programs/``, :mod:`whiskerid.fit`'s window fits among them) follow
    the same choice, through :data:`CACHE_ENV`."""
    import jax

    os.environ[CACHE_ENV] = "off" if folder is None else str(folder)
    if folder is None:
        jax.config.update("jax_enable_compilation_cache", False)
        return
    jax.config.update("jax_compilation_cache_dir", str(folder))
    for name, value in _CACHE_ALL.items():
        jax.config.update(name, value)
