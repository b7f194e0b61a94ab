"""Programs compiled once per machine: exported on disk, executables in JAX's persistent cache.

A calibration is one compiled program per structure and shape bucket (module ``_linear._program``).
Calling a jitted function in a fresh interpreter traces it and lowers it to StableHLO before
JAX's persistent compilation cache can even be asked for the executable: about a second for
the calibration's solver, every run. Here the lowered program is kept instead, as a
``jax.export`` artefact (a versioned flatbuffer, no pickle) in ``programs/`` of the cache
folder (:func:`whiskerid._compile_cache.cache_dir`), under a key made of everything the
program depends on: the program's name and static options, the structure and shapes of its
arguments, the versions of JAX, jaxlib, equinox, optimistix and lineax, the float64 switch,
the backend, and a digest of the source of whiskerid's ``fit``, ``model`` and ``io``. A
later run reads the artefact (milliseconds), wraps it in a trivial jitted call and gets the
executable from JAX's persistent compilation cache in the same folder: nothing is traced or
lowered again.

The command line points JAX's cache at that folder before JAX starts. A user's program that
has not configured a JAX cache of its own gets the same folder for these programs only: it is
switched on around their compilation and off again, so that nothing else the program compiles
is cached behind its back; :func:`with_compile_cache` does the same around a whole
calibration and around :func:`whiskerid.fit.observations_from_file` (the small programs they
run eagerly, e.g. the record's mode shapes, were compiled afresh in every process without it:
26 programs, about a second of a fresh interpreter's ``wi.calibrate``, where the command line
loads them from its cache). ``WHISKERID_COMPILE_CACHE=off`` switches all of it off (programs
are then exported and compiled once per process).
"""

import atexit
import contextlib
import functools
import gc
import hashlib
import importlib.metadata
import json
import os
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np

from ..._compile_cache import cache_dir

#: Compiled programs of this process, by key.
_PROGRAMS: dict[str, Callable] = {}
_ENVIRONMENT: list[str] = []
#: Program keys of this process, by name, options, structure and shapes.
_KEYS: dict[tuple, str] = {}
_DEPENDENCIES = ("jax", "jaxlib", "equinox", "optimistix", "lineax")


def cached_call(name: str, fn: Callable, args: tuple, *, static: tuple = ()):
    """``fn(*args)`` through a program compiled once per machine (see the module docstring).

    Args:
        name: The program's name (part of its key).
        fn: A function of arrays only (its static options bound, e.g. by
            :func:`functools.partial`) returning a dict of arrays.
        args: Its arguments: pytrees of arrays; their structure (static fields of
            equinox modules included) and the leaves' shapes and dtypes select the program.
        static: The options bound into ``fn`` (JSON-able), part of the key.

    Returns:
        The dict ``fn`` returns, as arrays.
    """
    leaves, treedef = jax.tree_util.tree_flatten(args)
    # Host arrays of canonical, strong dtypes: the program's key does not depend on where an
    # argument came from (a weakly typed scalar, a Python float, a NumPy array).
    leaves = [np.asarray(x, dtype=_canonical(x)) for x in leaves]
    # the key is a digest of a JSON text (a tenth of a millisecond): kept per structure
    memo = (name, repr(static), treedef, tuple((x.shape, x.dtype.str) for x in leaves))
    entry = _KEYS.get(memo)
    if entry is None:
        entry = _KEYS[memo] = (program_key(name, treedef, leaves, static), _packing(leaves))
    key, packing = entry
    buffers = _pack(leaves, packing)
    program = _PROGRAMS.get(key)
    if program is None:
        program = _PROGRAMS[key] = _load_or_build(key, fn, treedef, packing, buffers)
    return program(buffers)


def _packing(leaves: list) -> tuple:
    """How the leaves travel to a program: one flat buffer per dtype, and for each leaf its
    buffer, offset, size and shape. A call passes each argument to the device on its own:
    a calibration's call took 0.36 ms with its 27 leaves, 0.30 ms with one buffer (packed in
    0.01 ms). The program takes its leaves back by slicing, which moves no number."""
    groups: dict[str, int] = {}
    ends: list[int] = []
    where = []
    for x in leaves:
        g = groups.setdefault(x.dtype.str, len(groups))
        if g == len(ends):
            ends.append(0)
        where.append((g, ends[g], x.size, x.shape))
        ends[g] += x.size
    return tuple(where), len(groups)


def _pack(leaves: list, packing: tuple) -> list[np.ndarray]:
    """The flat buffers of ``leaves`` (see :func:`_packing`)."""
    where, n_buffers = packing
    parts: list[list[np.ndarray]] = [[] for _ in range(n_buffers)]
    for x, (g, _, _, _) in zip(leaves, where, strict=True):
        parts[g].append(x.ravel())
    return [np.concatenate(p) for p in parts]


def _unpack(buffers, packing: tuple) -> list:
    """The leaves of ``buffers`` (traced, inside the program)."""
    where, _ = packing
    return [buffers[g][start : start + size].reshape(shape) for g, start, size, shape in where]


def _lighter_exit() -> None:
    """At the interpreter's exit, collect what is garbage now (finalisers run as usual), then
    freeze the rest, so that the collections while the modules are torn down do not walk
    every object of JAX, XLA and equinox again: 0.25–0.35 s of CPU at the end of every script
    that calibrated (the command line skips the teardown with ``os._exit``). Only objects
    still alive at exit are affected, whose finalisers Python does not promise to run."""
    gc.collect()
    gc.freeze()


atexit.register(_lighter_exit)


def with_compile_cache(fn: Callable) -> Callable:
    """``fn`` run with JAX's persistent compilation cache in whiskerid's folder, unless JAX
    already has one or the cache is off (see the module docstring): what the command line
    gets by pointing JAX at the folder before it starts, for a library call."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with _persistent_cache(cache_dir()):
            return fn(*args, **kwargs)

    return wrapper


def compile_cache():
    """The context of :func:`with_compile_cache` (a ``with`` block)."""
    return _persistent_cache(cache_dir())


def program_key(name: str, treedef, leaves: list, static: tuple) -> str:
    """The key of a program: SHA-256 of everything its compiled code depends on."""
    parts = {
        "name": name,
        "static": repr(static),
        "tree": str(treedef),
        "leaves": [(list(x.shape), str(x.dtype)) for x in leaves],
        "environment": _environment(),
    }
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()[:32]


def _canonical(x):
    dtype = np.dtype(x.dtype) if hasattr(x, "dtype") else np.result_type(x)
    if dtype.kind == "f":
        return np.float64
    if dtype.kind in "iu":
        return np.int64
    return dtype


def _environment() -> list[str]:
    """Versions, the float64 switch, the backend and a digest of whiskerid's source."""
    if not _ENVIRONMENT:
        versions = []
        for dist in _DEPENDENCIES:
            try:
                versions.append(f"{dist}={importlib.metadata.version(dist)}")
            except importlib.metadata.PackageNotFoundError:
                versions.append(f"{dist}=?")
        digest = hashlib.sha256()
        package = Path(__file__).resolve().parents[1]
        # What a fit program is made of: the fit and model packages and the package's own
        # top-level modules (the command line and the other packages are not in it).
        sources = [*package.glob("*.py"), *(package / "fit").rglob("*.py"),
                   *(package / "model").rglob("*.py"), *(package / "io").rglob("*.py")]  # fmt: skip
        for path in sorted(sources):
            digest.update(str(path.relative_to(package)).encode())
            digest.update(path.read_bytes())
        _ENVIRONMENT.extend([
            *versions,
            f"x64={jax.config.jax_enable_x64}",
            f"backend={jax.default_backend()}",
            f"source={digest.hexdigest()}",
        ])  # fmt: skip
    return _ENVIRONMENT


def _load_or_build(key: str, fn: Callable, treedef, packing: tuple, buffers: list) -> Callable:
    from jax import export

    folder = cache_dir()
    path = None if folder is None else folder / "programs" / f"{key}.jaxexport"
    exported = None
    if path is not None and path.is_file():
        try:
            exported = export.deserialize(bytearray(path.read_bytes()))
        except Exception:  # a torn or foreign file: build it again
            exported = None
    if exported is None:

        def flat(buffers):
            return fn(*jax.tree_util.tree_unflatten(treedef, _unpack(buffers, packing)))

        # Every custom call (LAPACK on the CPU) is allowed: an artefact is only ever loaded by
        # the same versions of JAX and jaxlib (they are part of its key).
        allow = [export.DisabledSafetyCheck.custom_call("ALL")]
        exported = export.export(jax.jit(flat), disabled_checks=allow)(buffers)
        if path is not None:
            _write(path, exported.serialize())
    with _persistent_cache(folder):
        return jax.jit(exported.call).lower(buffers).compile()


def _write(path: Path, data: bytes) -> None:
    """Write ``data`` whole or not at all (a reader never sees half a file)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except OSError:
        pass  # a read-only or full cache: the program still runs, it is just not kept


@contextlib.contextmanager
def _persistent_cache(folder: Path | None):
    """JAX's persistent compilation cache in ``folder`` while compiling, unless JAX already
    has one (the command line's, or the user's own) or the cache is off."""
    from jax.experimental.compilation_cache import compilation_cache as cc

    if (
        folder is None
        or jax.config.jax_compilation_cache_dir
        or not getattr(jax.config, "jax_enable_compilation_cache", True)
    ):
        yield
        return
    options = {
        "jax_compilation_cache_dir": str(folder),
        "jax_persistent_cache_min_compile_time_secs": 0.0,
        "jax_persistent_cache_min_entry_size_bytes": 0,
    }
    # each flag read alone: ``jax.config.values`` builds a dict of every flag (8 µs a read,
    # four reads a warm calibration)
    before = {k: getattr(jax.config, k) for k in options}
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        yield
        return
    for k, v in options.items():
        jax.config.update(k, v)
    cc.reset_cache()
    try:
        yield
    finally:
        for k, v in before.items():
            jax.config.update(k, v)
        cc.reset_cache()
