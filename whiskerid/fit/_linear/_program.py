"""The numbers of a calibration as one compiled program, per structure and shape bucket.

From the start grid to the covariance, everything a calibration computes with JAX is one
traced function (:func:`fit_core`): the profile cost over the start grid and the best point
(module ``_start``), the least squares (Levenberg–Marquardt over the nonlinear parameters
with the linear coefficients solved at every point, module ``_varpro``; optimistix for the
other solvers), the weight of each block (recording,
static test) from its own residual scale and, with more than one block, the second solve,
the residuals and Jacobian at the optimum, ``(JᵀJ)⁻¹`` through the SVD, ``s²``, MINPACK's
gradient test, each recording's fitted curve and modal parts, and the reported quantities
with their Jacobian. One program is traced, lowered and compiled once per machine (module
``_aot``), instead of dozens of small ones per process.

Shape buckets: a free-decay recording is padded to the next of 64·2^k·(1, 1.25, 1.5, 1.75)
samples with zero-weight samples (its last instant repeated, so the design's time span is the
recording's own), so recordings of 5 s and 6 s share a program; the padding enters no sum,
no cost and no count (its residuals and Jacobian rows are zero and ``s²`` divides by the real
number of samples). Sine and base-motion recordings keep their length (their forced columns
are normalised over the whole record).
"""

import functools
import math
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ...model import mode_shape
from .._numerics import cached_call, lsq
from . import _varpro as _varpro
from ._limits import free_start
from ._problem import ZETA_MAX, FitProblem, recording_design
from ._start import start_from_grid, start_grid

_BUCKET_STEPS = (1.0, 1.25, 1.5, 1.75)
#: The optimistix solvers' tolerances (steps below ``atol + rtol·|θ|`` in every parameter;
#: Levenberg–Marquardt has MINPACK's tests instead, module ``_varpro``). Tighter ones
#: only add steps at rounding level (a 2000-sample pluck: 10 steps at 1e-8, 13 to 24 at
#: 1e-10, to the same optimum within 1e-16); 1e-8 of f_1 is far below its 1σ.
RTOL, ATOL = 1e-8, 1e-10
#: A fit is converged when the solver says so, or when no parameter direction has a cosine
#: with the residuals above this (MINPACK's ``gtol``).
GTOL = 1e-6


def bucket(n: int) -> int:
    """The padded length of a recording of ``n`` samples (at most 25 % more, at least 64)."""
    if n <= 64:
        return 64
    k = math.floor(math.log2(n / 64))
    for base in (64 * 2**k, 64 * 2 ** (k + 1)):
        for s in _BUCKET_STEPS:
            if round(base * s) >= n:
                return round(base * s)
    raise AssertionError("unreachable")  # pragma: no cover


@dataclass
class CoreResult:
    """What :func:`fit_problem` returns, in NumPy, with the padding removed.

    Attributes:
        value: Flat parameters at the optimum.
        optimum: The same as a parameter pytree (NumPy).
        ok: Whether the solver reported success (last pass).
        steps: Solver steps (last pass).
        cost: Half the weighted sum of squares at the optimum.
        problem: The problem with each block weighted by its own residual scale.
        resid: Weighted residuals at the optimum, recordings then the static test.
        jac: Their Jacobian in the flat parameters.
        bread: ``(JᵀJ)⁻¹`` (see :func:`whiskerid.fit.covariance`).
        s2: Residual variance ``‖r‖²/(n − p)``.
        gcos: MINPACK's gradient cosine at the optimum.
        models: Per recording, the normalised model ``D c + g`` and its modal parts
            ``(n, n_modes)``.
        reported: The reported quantities (:meth:`FitProblem.reported`) as a vector, and
            their Jacobian in the flat parameters.
        amplitude: What the amplitude test (module ``_amplitude``) reads of the whisker at
            the optimum: mode 1's ``w0`` (rad/s) and ``zeta0``, and per recording ``tip``
            (mode 1's tip deflection per unit at the sensor), ``mode1`` (the design's two
            mode-1 columns, ``(n, 2)``) and ``dc`` (the design times the linear
            coefficients), so that the test runs in NumPy; and ``svd``, the SVD of the
            column-scaled Jacobian behind ``bread`` (``(scale, U, S, Vᵀ)``, real rows of
            ``U``), which the test projects on instead of taking it again.
        host_work_result: What ``fit_problem``'s ``host_work`` returned.
    """

    value: np.ndarray
    optimum: dict
    ok: bool
    steps: int
    cost: float
    problem: FitProblem
    resid: np.ndarray
    jac: np.ndarray
    bread: np.ndarray
    s2: float
    gcos: float
    models: list[tuple[np.ndarray, np.ndarray]]
    reported: tuple[np.ndarray, np.ndarray]
    amplitude: dict
    host_work_result: object = None


def fit_problem(
    problem: FitProblem,
    observations,
    nominal,
    *,
    solver: str,
    max_steps: int,
    f1_start_hz: float | None = None,
    start: dict | None = None,
    host_work=None,
) -> CoreResult:
    """Start values, least squares, weights, covariance and reported values of ``problem``
    in one compiled program (see the module docstring).

    Args:
        problem: The fit problem (unpadded).
        observations: Its recordings (the start grid reads their spectra).
        nominal: The record's whisker with the problem's number of modes.
        solver: Least-squares solver name.
        max_steps: Solver step limit.
        f1_start_hz: Centre of the start search (the record's f_1 when None).
        start: Start parameters instead of the grid search (a parameter pytree).
        host_work: A function of no arguments run while the program runs (JAX returns
            before the program ends): host work that does not need its results.
    """
    sizes = [r.t.shape[0] for r in problem.recordings]
    padded, masks = padded_problem(problem)
    if start is None:
        # the grid searches the unlimited parameters (fit_core maps its best point inside)
        unlimited = replaced(problem, limits=()) if problem.limits else problem
        first = start_grid(unlimited, observations, nominal, f1_hz=f1_start_hz)
    else:
        first = {"flat0": np.asarray(problem.flatten(start))}
    fn = functools.partial(fit_core, solver=solver, max_steps=max_steps)
    out = cached_call("calibrate", fn, (padded, masks, first), static=(solver, max_steps))
    extra = host_work() if host_work is not None else None
    out = {k: np.asarray(v) for k, v in out.items()}
    rows = padded_rows(sizes, [m.size for m in masks], out["resid"].size)
    weights = [np.asarray(w) for w in out["weights"]]
    recs = zip(problem.recordings, weights, strict=True)
    reweighted = replaced(problem, recordings=tuple(replaced(r, weight=w) for r, w in recs))
    optimum = unflatten_numpy(problem, out["value"])
    share_layout(problem, reweighted)
    models = [(out[f"model_{i}"][:n], out[f"modal_{i}"][:n]) for i, n in enumerate(sizes)]
    return CoreResult(
        value=out["value"],
        optimum=optimum,
        ok=bool(out["ok"]),
        steps=int(out["steps"]),
        cost=float(out["cost"]),
        problem=reweighted,
        resid=out["resid"][rows],
        jac=out["jac"][rows],
        bread=out["bread"],
        s2=float(out["s2"]),
        gcos=float(out["gcos"]),
        models=models,
        reported=(out["reported"], out["reported_jac"]),
        amplitude={
            "w0": float(out["w0"]),
            "zeta0": float(out["zeta0"]),
            "tip": [float(out[f"tip_{i}"]) for i in range(len(sizes))],
            "mode1": [out[f"mode1_{i}"][:n] for i, n in enumerate(sizes)],
            "dc": [out[f"dc_{i}"][:n] for i, n in enumerate(sizes)],
            "svd": (out["svd_d"], out["svd_u"][rows], out["svd_s"], out["svd_vt"]),
        },
        host_work_result=extra,
    )


def unflatten_numpy(problem: FitProblem, flat: np.ndarray) -> dict:
    """:meth:`FitProblem.unflatten` in NumPy (JAX's would compile a few programs in a fresh
    process; the layout is the same: leaves in tree order, each raveled)."""
    shapes, treedef = _layout(problem)
    parts, start = [], 0
    for shape in shapes:
        size = int(np.prod(shape, dtype=int))
        parts.append(np.asarray(flat[start : start + size]).reshape(shape))
        start += size
    return jax.tree_util.tree_unflatten(treedef, parts)


#: The last problems' parameter layouts (a calibration unflattens four times: its optimum,
#: the score tests' steps, where κ and ζ sit); each entry keeps its problem alive, so that
#: its ``id`` is not reused while it is here.
_LAYOUTS: dict[int, tuple] = {}


def _layout(problem: FitProblem):
    """``(leaf shapes, treedef)`` of ``problem.zero_params()``."""
    hit = _LAYOUTS.get(id(problem))
    if hit is not None and hit[0] is problem:
        return hit[1]
    leaves, treedef = jax.tree_util.tree_flatten(problem.zero_params())
    layout = ([np.shape(leaf) for leaf in leaves], treedef)
    _remember(problem, layout, {})
    return layout


def _remember(problem: FitProblem, layout, found: dict) -> None:
    """Keep ``problem``'s layout and positions, the oldest of the last eight let go."""
    if len(_LAYOUTS) >= 8:
        _LAYOUTS.pop(next(iter(_LAYOUTS)))
    _LAYOUTS[id(problem)] = (problem, layout, found)


def share_layout(problem: FitProblem, other: FitProblem) -> None:
    """Give ``other`` the layout (and positions found so far) of ``problem``, whose
    parameters it shares: the same problem with other weights, for one, whose layout the
    score tests would otherwise build again (its zero parameters flattened, a position
    found by unflattening: 0.2–0.3 ms of a warm fit)."""
    _layout(problem)
    _, layout, found = _LAYOUTS[id(problem)]
    _remember(other, layout, found)


def positions(problem: FitProblem, name: str) -> np.ndarray:
    """Where parameter ``name`` (a top-level entry, e.g. ``log_kappa``) sits in the flat
    vector: an int array of its shape (kept per problem, as its layout; the score tests ask
    it of every fit, where unflattening a whole step took a tenth of a millisecond)."""
    shapes, _ = _layout(problem)
    found = _LAYOUTS[id(problem)][2]
    if name not in found:
        size = sum(int(np.prod(shape, dtype=int)) for shape in shapes)
        found[name] = np.asarray(unflatten_numpy(problem, np.arange(size))[name])
    return found[name]


def padded_problem(problem: FitProblem):
    """The problem with every free decay padded to its bucket, and the masks (1 = sample)."""
    recs, masks = [], []
    for r in problem.recordings:
        n = r.t.shape[0]
        size = bucket(n) if r.excitation == "decay" else n
        pad = size - n
        t, y = np.asarray(r.t), np.asarray(r.y)
        if pad:
            t = np.concatenate([t, np.full(pad, t[-1])])
            y = np.concatenate([y, np.zeros(pad)])
            r = replaced(r, t=t, y=y)
        recs.append(r)
        masks.append(np.concatenate([np.ones(n), np.zeros(pad)]))
    return replaced(problem, recordings=tuple(recs)), masks


def replaced(module: eqx.Module, **changes) -> eqx.Module:
    """A copy of an equinox module with some fields changed, built as JAX builds one when it
    unflattens a pytree (its fields set on a new object; ``__init__`` and its checks, which
    ran when ``module`` was made, do not run again): ``eqx.tree_at`` of those fields, the
    same pytree, in 3 µs instead of 45–80 µs (it flattens the whole module and maps over it
    several times; a warm fit took three)."""
    new = object.__new__(type(module))
    for name, value in vars(module).items():
        object.__setattr__(new, name, changes.pop(name, value))
    if changes:
        raise AttributeError(f"{type(module).__name__} has no field {', '.join(changes)}")
    return new


def padded_rows(sizes, padded_sizes, total) -> np.ndarray:
    """Indices of the real rows (samples, then the static test's) of a padded residual."""
    idx, start = [], 0
    for n, size in zip(sizes, padded_sizes, strict=True):
        idx.append(np.arange(start, start + n))
        start += size
    idx.append(np.arange(start, total))
    return np.concatenate(idx)


def solve_masked(problem: FitProblem, masks, flat0, *, solver: str, max_steps: int):
    """The least squares of a calibration, traceable: ``(flat, ok, steps)`` from ``flat0``.

    Levenberg–Marquardt runs by variable projection (module ``_varpro``, over the nonlinear
    parameters only), the other solvers are optimistix's over every parameter. Calibrate and
    the batched fits (module ``_batch``) both solve here, so that the same recording from the
    same start meets the same convergence test in the same number of steps: on a pluck of
    pure noise, optimistix's LM crawled towards ζ = 0 for its 400 steps (``not converged``)
    where variable projection stops in tens (``poor fit``).

    Args:
        problem: The (padded, weighted) fit problem.
        masks: Per recording, 1 for a sample and 0 for padding.
        flat0: Start parameters, flat.
        solver: Least-squares solver name.
        max_steps: Solver step limit.
    """
    if solver == "levenberg-marquardt":
        return _varpro.varpro_least_squares(problem, masks, flat0, max_steps=max_steps)
    res = lsq.least_squares(
        _masked_residuals, flat0, (problem, _mask_vector(problem, masks)),
        solver=lsq.make_solver(solver, rtol=RTOL, atol=ATOL), max_steps=max_steps,
    )  # fmt: skip
    return res.value, res.ok, res.steps


def solve_status(ok, gcos: float, cov_diag, cost: float) -> tuple[str, bool]:
    """A solve's status before any check of the fit, and whether it is ``ok``: converged
    (the solver's own test, or MINPACK's gradient test below ``GTOL`` where the solver's
    stalls at rounding level) with a finite covariance; else ``non-finite`` or
    ``not converged``. Shared by calibrate and the batched fits."""
    converged = bool(ok) or gcos < GTOL
    good = converged and bool(np.all(np.isfinite(cov_diag)))
    if good:
        return "ok", True
    return ("non-finite" if not np.isfinite(float(cost)) else "not converged"), False


def _mask_vector(problem, masks):
    parts = list(masks)
    if problem.static_test is not None:
        parts.append(jnp.ones(problem.static_test.force.shape[0]))
    return jnp.concatenate(parts)


def _masked_residuals(flat, args):
    problem, mask = args
    return problem.residuals(problem.unflatten(flat)) * mask


def _block_weights(problem, params, masks):
    """``1/σ`` of each recording's own residuals at ``params`` (σ² = RSS/(n − columns))."""
    weights = []
    for (D, g), r, p, m in zip(
        problem.design(params), problem.recordings, params["recs"], masks, strict=True
    ):
        res = (D @ p["c"] + g - r.y) * m
        dof = jnp.maximum(jnp.sum(m) - D.shape[1], 1.0)
        weights.append(1.0 / jnp.maximum(jnp.sqrt(jnp.sum(res**2) / dof), 1e-12))
    return jnp.stack(weights)


def _weighted(problem, weights):
    return eqx.tree_at(
        lambda q: [r.weight for r in q.recordings],
        problem,
        [weights[i] for i in range(len(problem.recordings))],
    )


def fit_core(problem: FitProblem, masks, first: dict, *, solver: str, max_steps: int) -> dict:
    """Everything a calibration computes with JAX, traceable (see the module docstring).

    Args:
        problem: The (padded) fit problem.
        masks: Per recording, 1 for a sample and 0 for padding.
        first: The start grid (:func:`._start.start_grid`), or ``{"flat0": …}``.
        solver: Least-squares solver name.
        max_steps: Solver step limit.

    Returns:
        A dict of arrays (see :class:`CoreResult`; weights per recording, padded rows).
    """
    if "flat0" in first:
        flat0 = first["flat0"]
    else:
        # variable projection (the default solver) solves the linear coefficients itself
        unlimited = replaced(problem, limits=()) if problem.limits else problem
        theta = start_from_grid(unlimited, first, masks,
                                coefficients=solver != "levenberg-marquardt")  # fmt: skip
        flat0 = problem.flatten(theta)
    if problem.limits:  # the start (grid or given) moved inside the user's limits
        theta = free_start(problem.limits, problem.limit_values, problem.unflatten(flat0),
                           ZETA_MAX)  # fmt: skip
        flat0 = problem.flatten(theta)
    mask = _mask_vector(problem, masks)
    # One block (a recording, no static test): its weight is one factor on every residual,
    # which moves neither the optimum nor s²(JᵀJ)⁻¹, so one solve; more blocks are solved
    # again with each weighted by its own residual scale, so that they combine fairly.
    n_blocks = len(problem.recordings) + (problem.static_test is not None)

    def one_pass(carry, _):
        flat, weights = carry
        value, ok, steps = solve_masked(_weighted(problem, weights), masks, flat, solver=solver,
                                 max_steps=max_steps)  # fmt: skip
        new = _block_weights(problem, problem.unflatten(value), masks)
        return (value, new), (ok, steps)

    ones = jnp.ones(len(problem.recordings))
    (flat, weights), (ok, steps) = jax.lax.scan(
        one_pass, (flat0, ones), None, length=1 if n_blocks == 1 else 2
    )
    weighted = _weighted(problem, weights)
    resid = _masked_residuals(flat, (weighted, mask))
    jac = jax.jacfwd(_masked_residuals)(flat, (weighted, mask))
    n_real = jnp.sum(mask)
    bread, svd = lsq.scaled_inverse_gram_svd(jac)
    out = {
        "value": flat,
        "ok": ok[-1],
        "steps": steps[-1],
        "cost": 0.5 * jnp.sum(resid**2),
        "weights": weights,
        "resid": resid,
        "jac": jac,
        "bread": bread,
        # the SVD behind it, for the score tests (the host took it again: module _projector)
        "svd_d": svd[0],
        "svd_u": svd[1],
        "svd_s": svd[2],
        "svd_vt": svd[3],
        "s2": jnp.sum(resid**2) / jnp.maximum(n_real - flat.size, 1.0),
        "gcos": lsq.gradient_cosine_from(jac, resid),
    }
    params = problem.unflatten(flat)
    w = problem.whisker(params)
    nm = problem.n_modes
    for i, (r, p) in enumerate(zip(problem.recordings, params["recs"], strict=True)):
        D, g = recording_design(r, w, p)
        out[f"model_{i}"] = D @ p["c"] + g
        cols = D[:, 2 : 2 + 2 * nm] * p["c"][2 : 2 + 2 * nm]
        out[f"modal_{i}"] = cols[:, :nm] + cols[:, nm:]  # each mode's part of the signal
        # for the amplitude test: mode 1's columns and its tip deflection per sensor unit
        out[f"mode1_{i}"] = jnp.stack([D[:, 2], D[:, 2 + nm]], axis=1)
        out[f"dc_{i}"] = D @ p["c"]
        shape = mode_shape(w.beta, jnp.stack([r.x_m / w.length_m, 1.0]))[:, 0]
        out[f"tip_{i}"] = shape[1] / shape[0]
    out["w0"], out["zeta0"] = w.omega_rad_s[0], w.zeta[0]

    def reported(f):
        return jnp.stack(list(problem.reported(problem.unflatten(f)).values()))

    out["reported"], out["reported_jac"] = reported(flat), jax.jacfwd(reported)(flat)
    return out
