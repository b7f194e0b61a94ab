"""Running emcee: walkers from the Laplace approximation, moves, HDF5 backend and resume."""

import errno
import shutil
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
    for _ in sampler.sample(state, iterations=steps, progress=progress):
        if stop is not None and stop():
            raise KeyboardInterrupt
    return sampler


#: Free space a chain file's disk must keep before each step is written. HDF5 cannot survive
#: a write that fails for want of space (it crashed the process, leaving the chain at a
#: torn step), so a step is never begun short of it: the run stops with the chain whole.
CHAIN_FREE_BYTES = 8 << 20


def _checked_backend(emcee):
    """emcee's HDF5 backend, checking the free space before it writes anything."""

    class CheckedHDFBackend(emcee.backends.HDFBackend):
        def _check_space(self) -> None:
            folder = Path(self.filename).resolve().parent
            disk = shutil.disk_usage(folder).free
            free = min(disk, _size_limit_room(self.filename))
            if free < CHAIN_FREE_BYTES:
                where = "on its disk" if free == disk else "under the file-size limit (ulimit -f)"
                raise OSError(
                    errno.ENOSPC if free == disk else errno.EFBIG,
                    f"{free / 1e6:.3g} MB left {where}: stopped before writing step "
                    f"{self.iteration + 1}, the chain whole to there; free some space and "
                    "continue it with --resume",
                )

        def grow(self, ngrow, blobs):
            self._check_space()
            super().grow(ngrow, blobs)

        def save_step(self, state, accepted):
            self._check_space()
            super().save_step(state, accepted)

    return CheckedHDFBackend


def _size_limit_room(path) -> float:
    """Bytes the file at ``path`` may still grow by under the process's file-size limit
    (``ulimit -f``; a write beyond it fails as a full disk's does): infinite without one."""
    try:
        import resource

        limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    except (ImportError, OSError, ValueError):  # no such limit on this system
        return float("inf")
    if limit == resource.RLIM_INFINITY:
        return float("inf")
    size = Path(path).stat().st_size if Path(path).exists() else 0
    return float(limit - size)


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
