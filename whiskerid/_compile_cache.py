"""Where whiskerid keeps what it compiled, so that a second run on the machine loads it.

The folder is ``$WHISKERID_COMPILE_CACHE`` if set (``none``, ``off``, ``0`` or empty switches
the cache off), else ``$XDG_CACHE_HOME/whiskerid/jax`` or ``~/.cache/whiskerid/jax``. It
holds JAX's persistent compilation cache (compiled executables) and, in ``programs/``, the
exported programs of :mod:`whiskerid.fit` (``jax.export`` artefacts, so that a cached
program is neither traced nor lowered again). No JAX here: the command line reads it before
JAX is imported.
"""

import os
from pathlib import Path

#: Environment variable naming the cache folder (``off`` switches it off).
CACHE_ENV = "WHISKERID_COMPILE_CACHE"


def cache_dir() -> Path | None:
    """The cache folder, or None when switched off."""
    env = os.environ.get(CACHE_ENV)
    if env is not None:
        return None if env.strip().lower() in ("", "off", "0", "none") else Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "whiskerid" / "jax"
