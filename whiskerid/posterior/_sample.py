"""Running emcee: walkers from the Laplace approximation, moves, HDF5 backend and resume."""

import errno
import io
import math
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from .._choices import MOVES
from ..fit import Observation
from ..model import WhiskerRecord
from ._arviz import import_arviz
from ._prior import PosteriorError
from ._problem import Problem
from ._setup import setup_posterior
from ._summary import Posterior, summarize


# --------------------------------------------------------------------------- sampling
def initial_walkers(prob: Problem, n_walkers: int, rng: np.random.Generator) -> np.ndarray:
    """Walkers drawn from the Laplace approximation, all with a finite log-probability.

    Draws ``z0 + L ε`` (``L Lᵀ = Σ``); walkers outside the support are drawn again, with
    the spread halved each round; the centre itself is moved inside a bounded prior.
    """
    ndim = prob.z0.size
    cov = 0.5 * (prob.cov + prob.cov.T)
    jitter = 1e-12 * max(float(np.max(np.abs(np.diag(cov)))), 1e-12)
    try:
        chol = np.linalg.cholesky(cov + jitter * np.eye(ndim))
    except np.linalg.LinAlgError:
        chol = np.diag(np.sqrt(np.maximum(np.abs(np.diag(cov)), 1e-12)))
    p = prob.z0 + rng.standard_normal((n_walkers, ndim)) @ chol.T
    scale = 1.0
    for _ in range(60):
        bad = ~np.isfinite(prob.log_prob(p))
        if not bad.any():
            return p
        scale *= 0.5
        p[bad] = prob.z0 + scale * rng.standard_normal((int(bad.sum()), ndim)) @ chol.T
    raise PosteriorError(
        "could not start the walkers with a finite log-probability: is the calibrated value "
        "inside the prior's support?"
    )


def emcee_moves(move: str):
    """The emcee moves for a name in :data:`MOVES`.

    ``de``: differential evolution (ter Braak 2006; emcee's ``DEMove``, after Nelson et al.
    2014): a walker steps by ``γ (x_j − x_k)`` for two walkers ``j ≠ k`` of the other half,
    ``γ ~ N(γ₀, (10⁻⁵ γ₀)²)``, ``γ₀ = 2.38/√(2 ndim)``. The differences carry the ensemble's
    spread and correlations, as the stretch move's lines do, and ``γ₀`` is the optimal
    random-walk scale for a Gaussian target in ``ndim`` dimensions, where the stretch move's
    scale (``a = 2``) is the same in any dimension; on these nearly Gaussian posteriors the
    autocorrelation times come out about three times shorter. ``stretch``: emcee's default
    (Goodman & Weare 2010), as in lmfit's ``Minimizer.emcee``. ``de-snooker``: DE 80 %,
    DE-snooker 20 % (ter Braak & Vrugt 2008; for posteriors with several modes).
    """
    import emcee

    if move == "de":
        return emcee.moves.DEMove()
    if move == "stretch":
        return emcee.moves.StretchMove()
    if move == "de-snooker":
        return [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    raise PosteriorError(f"move must be one of {', '.join(MOVES)}; got {move!r}")


def run_sampler(
    prob: Problem,
    *,
    walkers: int = 32,
    steps: int = 2000,
    seed: int = 0,
    backend: str | Path | None = None,
    resume: bool = False,
    progress: bool = False,
    move: str = "de",
    stop=None,
    name: str = "whiskerid",
):
    """Run emcee (vectorised) and return the sampler.

    Args:
        prob: From :func:`setup_posterior`.
        walkers: Number of walkers (at least twice the dimension).
        steps: Steps to run (added to the backend's when resuming).
        seed: Seeds the start and emcee's own random state.
        backend: HDF5 file for the chain (needs ``h5py``).
        resume: Continue the chain in ``backend`` instead of starting afresh.
        progress: emcee's progress bar (tqdm).
        move: emcee's proposal, one of :data:`MOVES` (:func:`emcee_moves`).
        stop: Called after every step; when it returns True the run stops there with
            :class:`KeyboardInterrupt` (raised between steps, never inside the
            log-probability, so the backend holds every finished step and resumes).
        name: The chain's group in the HDF5 file (one per independent ensemble).
    """
    import emcee

    ndim = prob.z0.size
    if walkers < 2 * ndim:
        raise PosteriorError(f"need at least {2 * ndim} walkers for {ndim} parameters")
    if steps < 1:
        raise PosteriorError("steps must be >= 1")
    moves = emcee_moves(move)  # refused before a backend file is touched
    be = None
    if backend is not None:
        try:
            import h5py  # noqa: F401
        except ImportError:
            raise PosteriorError("the HDF5 backend needs h5py (pip install h5py)") from None
        be = _checked_backend(emcee)(str(backend), name=name)
        if resume:
            if not Path(backend).exists() or be.iteration == 0:
                raise PosteriorError(f"{backend}: nothing to resume")
            if be.shape != (walkers, ndim):
                raise PosteriorError(
                    f"{backend}: holds {be.shape[0]} walkers × {be.shape[1]} parameters, "
                    f"not {walkers} × {ndim}"
                )
        else:
            be.reset(walkers, ndim)
    sampler = emcee.EnsembleSampler(
        walkers, ndim, prob._emcee_log_prob(), vectorize=True, backend=be, moves=moves
    )
    if resume:
        state = be.get_last_sample()
        if state.random_state is None:
            state.random_state = np.random.RandomState(seed).get_state()
    else:
        p0 = initial_walkers(prob, walkers, np.random.default_rng(seed))
        state = emcee.State(p0, random_state=np.random.RandomState(seed).get_state())
    sampler.whiskerid_move = move  # for the provenance (summarize)
    try:
        for _ in sampler.sample(state, iterations=steps, progress=progress):
            if stop is not None and stop():
                raise KeyboardInterrupt
    finally:
        if be is not None:
            be.checkpoint()  # every finished step, also when stopped or refused
    return sampler


#: Free space a chain file's disk must keep before a checkpoint is written (a refusal
#: that names the disk rather than a failed write).
CHAIN_FREE_BYTES = 1 << 20

#: Seconds between checkpoints of the chain file (and one at the end of every run, stopped,
#: interrupted or not): what a killed process can lose at most.
CHECKPOINT_S = 2.0


def _checked_backend(emcee):
    """emcee's HDF5 backend, with HDF5 kept off the disk.

    HDF5 cannot survive a write that fails for want of space: a full disk (or ``ulimit -f``)
    under an open chain file crashed the process (SIGSEGV in h5py's "Can't decrement id ref
    count"), at any write, so a free-space check before each write could only narrow the
    race. Here the file lives in memory (an HDF5 image in a :class:`io.BytesIO`, loaded
    from the file when there is one) and reaches the disk only as a whole file written by
    plain Python to a temporary name and renamed over the old one (:func:`checkpoint`): a
    full disk then fails as an ordinary :class:`OSError`, and the file on disk is always
    the last whole checkpoint, which ``--resume`` continues. Same format as emcee's.
    """

    class CheckedHDFBackend(emcee.backends.HDFBackend):
        def __init__(self, filename, *args, **kwargs):
            super().__init__(filename, *args, **kwargs)
            path = Path(filename)
            self._image = io.BytesIO(path.read_bytes() if path.is_file() else b"")
            self._saved = -math.inf  # the first step is saved at once

        @property
        def initialized(self):
            return self._image.getbuffer().nbytes > 0 and super().initialized

        def open(self, mode="r"):
            import h5py

            if self.read_only and mode != "r":
                raise RuntimeError("the chain was opened read-only")
            f = h5py.File(self._image, mode)
            if not self.dtype_set and self.name in f and "chain" in f[self.name]:
                self.dtype = f[self.name]["chain"].dtype
                self.dtype_set = True
            return f

        def checkpoint(self) -> None:
            """Write the chain file whole (atomically); on a full disk the old one stays."""
            _check_space(self.filename, self._image.getbuffer().nbytes)
            write_image(self.filename, self._image.getvalue())
            self._saved = time.monotonic()

        def save_step(self, state, accepted):
            super().save_step(state, accepted)
            if time.monotonic() - self._saved >= CHECKPOINT_S:
                self.checkpoint()

    return CheckedHDFBackend


def write_image(path: str | Path, data: bytes) -> None:
    """Write an HDF5 file image over ``path`` atomically (no HDF5 call touches the disk):
    a temporary file beside it, synced, renamed over it; on a failure it is removed and
    ``path`` is left as it was."""
    path = Path(path)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        if path.exists():  # keep the old file's permissions
            shutil.copymode(path, name)
        os.replace(name, path)
    except BaseException:
        Path(name).unlink(missing_ok=True)
        raise


def _check_space(filename: str | Path, size: int) -> None:
    """Refuse a checkpoint of ``size`` bytes short of :data:`CHAIN_FREE_BYTES` beyond it."""
    folder = Path(filename).resolve().parent
    disk = shutil.disk_usage(folder).free
    free = min(disk, _size_limit_room(filename))
    if free < size + CHAIN_FREE_BYTES:
        where = "on its disk" if free == disk else "under the file-size limit (ulimit -f)"
        raise OSError(
            errno.ENOSPC if free == disk else errno.EFBIG,
            f"{free / 1e6:.3g} MB left {where}, too little to save {size / 1e6:.3g} MB",
        )


def _size_limit_room(path) -> float:
    """Bytes a new file next to ``path`` may hold under the process's file-size limit
    (``ulimit -f``; a write beyond it fails as a full disk's does): infinite without one."""
    try:
        import resource

        limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    except (ImportError, OSError, ValueError):  # no such limit on this system
        return float("inf")
    if limit == resource.RLIM_INFINITY:
        return float("inf")
    return float(limit)  # the file is written whole, from size 0


def sample_posterior(
    record: WhiskerRecord,
    observations: list[Observation] | Observation,
    *,
    walkers: int = 32,
    steps: int = 2000,
    seed: int = 0,
    backend: str | Path | None = None,
    resume: bool = False,
    progress: bool = False,
    move: str = "de",
    stop=None,
    chains: int = 1,
    **setup,
) -> Posterior:
    """Posterior of ζ, f_1, κ (EI or C) and the noise, jointly over recordings of one whisker.

    Args:
        record: The whisker's record (``[prior]`` table optional, see the module docstring).
        observations: One or more recordings.
        walkers: emcee walkers.
        steps: Steps per walker.
        seed: Makes the run reproducible (start and emcee's random state).
        backend: HDF5 file to store the chain in (``h5py``).
        resume: Continue the chain stored in ``backend``.
        progress: Show emcee's progress bar.
        move: emcee's proposal, one of :data:`MOVES` (:func:`emcee_moves`).
        stop: Polled between steps; True stops the run (:func:`run_sampler`).
        chains: Independent ensembles of ``walkers`` each, seeded ``seed``, ``seed + 1``, …
            (in ``backend`` as groups ``whiskerid``, ``whiskerid_2``, …): their walkers are
            pooled and ArviZ (``whiskerid[arviz]``) gives R-hat and bulk/tail ESS across them.
        **setup: Passed to :func:`setup_posterior` (``likelihood``, ``nu``, ``prior``,
            ``n_modes``, ``pin``, ``static``, ``marginalize``, ...).

    Returns:
        A :class:`Posterior` (``diagnostics["converged"]`` says whether the run was long
        enough: at least 50 autocorrelation times).
    """
    if chains < 1:
        raise PosteriorError("chains must be >= 1")
    if chains > 1:
        try:
            import_arviz()  # refused before minutes of sampling, not after
        except ImportError as err:
            raise PosteriorError(f"R-hat across chains needs ArviZ: {err}") from None
    prob = setup_posterior(record, observations, **setup)
    samplers = [
        run_sampler(
            prob,
            walkers=walkers,
            steps=steps,
            seed=seed + k,
            backend=backend,
            resume=resume,
            progress=progress,
            move=move,
            stop=stop,
            name="whiskerid" if k == 0 else f"whiskerid_{k + 1}",
        )
        for k in range(chains)
    ]
    return summarize(prob, samplers if chains > 1 else samplers[0], seed=seed)
