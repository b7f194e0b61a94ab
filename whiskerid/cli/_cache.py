"""JAX's persistent compilation cache for the command line: a second run on the machine
loads the compiled programs instead of compiling them again.

The folder is ``$WHISKERID_COMPILE_CACHE`` if set (``none``, ``off`` or empty switches the
cache off), else ``$XDG_CACHE_HOME/whiskerid/jax`` or ``~/.cache/whiskerid/jax``. It is set
through JAX's own environment variables before JAX is imported, so a user's
``JAX_COMPILATION_CACHE_DIR`` wins, and ``import whiskerid`` in a user's program changes
nothing.
"""

import os
from pathlib import Path

#: Environment variable naming the folder of JAX's persistent compilation cache.
CACHE_ENV = "WHISKERID_COMPILE_CACHE"


def cache_dir() -> Path | None:
    """The cache folder the command line uses, or None when switched off."""
    env = os.environ.get(CACHE_ENV)
    if env is not None:
        return None if env.strip().lower() in ("", "off", "0", "none") else Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "whiskerid" / "jax"


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
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES", "0")
    return path
