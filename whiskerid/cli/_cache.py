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

# JAX's options (lower case; upper case as environment variables) that cache every program.
_CACHE_ALL = {
    "jax_persistent_cache_min_compile_time_secs": 0.0,
    "jax_persistent_cache_min_entry_size_bytes": 0,
}


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
    for name, value in _CACHE_ALL.items():
        os.environ.setdefault(name.upper(), str(value))
    return path


def use_compile_cache(folder: Path | None) -> None:
    """Point JAX's persistent compilation cache at ``folder`` once JAX is imported (a
    command's own option overrides the environment), or switch it off with None."""
    import jax

    if folder is None:
        jax.config.update("jax_enable_compilation_cache", False)
        return
    jax.config.update("jax_compilation_cache_dir", str(folder))
    for name, value in _CACHE_ALL.items():
        jax.config.update(name, value)
