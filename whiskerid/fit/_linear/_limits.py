"""Parameters a user fixes or bounds (lmfit's habit) in the linear calibration.

A :class:`Parameters` says which reported quantities are held at a value (``fix``) or kept
in an interval (``bound``). The fit has no bounded solver (optimistix has none): it already
keeps ζ in ``(0, 0.95)`` by a logistic transform, and a bound is that transform with the
user's limits, on ζ or on ``log κ`` (f_1 ∝ √κ when the eigenvalues are fixed, i.e. without a
static test). A fixed quantity is the limit ``lo = hi``: the model reads the value and not
the parameter, so the parameter's Jacobian column is zero, it leaves the fit and its
variance (the pseudo-inverse of ``JᵀJ``) is exactly 0.

The problem carries which parameters are limited, and how, as a static field
(:attr:`FitProblem.limits`) and the limits themselves as a traced leaf
(:attr:`FitProblem.limit_values`): a fit with limits compiles one program per kind of limits
(not per value: a profile over fixed values reuses it), and the default fit (no limits)
traces exactly as before.
"""

import math
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from .._data import CalibrationError
from .._numerics import lsq

#: The quantities a user may fix or bound: reported name → the fitted parameter it maps to.
LIMITABLE = {"f1_hz": "log_kappa", "zeta": "zeta_u"}
#: A bounded parameter is reported at its bound when its logistic fraction of the interval
#: is within this of 0 or 1 (its 1σ is then refused, as lmfit refuses it).
AT_BOUND = 1e-3
_ZETA_RANGE = (0.0, 0.95)
_F1_RANGE = (1e-3, 1e5)


@dataclass(frozen=True)
class Parameters:
    """Which reported quantities a calibration holds fixed or keeps within bounds.

    Immutable: :meth:`fix` and :meth:`bound` return a new object, so they chain, e.g.
    ``Parameters().fix("zeta", 0.03).bound("f1_hz", 40, 50)``. Names are the calibration's
    reported names (``f1_hz``, ``zeta``); a later call on a name replaces an earlier one.

    Attributes:
        limits: ``(name, lo, hi)`` per quantity; ``lo == hi`` is a fixed value.
    """

    limits: tuple[tuple[str, float, float], ...] = ()

    def fix(self, name: str, value: float) -> "Parameters":
        """Hold ``name`` at ``value`` (its 1σ is then 0)."""
        value = _number(name, value, "fix")
        _check_range(name, value, value, "fix")
        return self._with(name, value, value)

    def bound(self, name: str, lo: float, hi: float) -> "Parameters":
        """Keep ``name`` strictly inside ``(lo, hi)`` (a 1σ at a bound is refused)."""
        lo, hi = _number(name, lo, "bounds"), _number(name, hi, "bounds")
        if not lo < hi:
            raise CalibrationError(
                f"--bounds {name}: the lower {lo:g} must be below the upper {hi:g}"
            )
        _check_range(name, lo, hi, "bounds")
        return self._with(name, lo, hi)

    def _with(self, name, lo, hi) -> "Parameters":
        kept = tuple(x for x in self.limits if x[0] != name)
        return Parameters((*kept, (name, float(lo), float(hi))))

    def describe(self) -> dict:
        """``{name: {"fixed": v}}`` or ``{name: {"bounds": [lo, hi]}}`` (JSON-able)."""
        return {
            n: ({"fixed": lo} if lo == hi else {"bounds": [lo, hi]}) for n, lo, hi in self.limits
        }


def _number(name: str, value, flag: str) -> float:
    if name not in LIMITABLE:
        raise CalibrationError(
            f"--{flag}: {name!r} is not a parameter one can {flag}; give one of "
            + ", ".join(LIMITABLE)
        )
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise CalibrationError(f"--{flag} {name}: {value!r} is not a number") from None
    if not math.isfinite(out):
        raise CalibrationError(f"--{flag} {name}: {value!r} is not a finite number")
    return out


def _check_range(name: str, lo: float, hi: float, flag: str) -> None:
    a, b = _ZETA_RANGE if name == "zeta" else _F1_RANGE
    if not (a < lo and hi < b) and not (lo == hi and a < lo < b):
        raise CalibrationError(
            f"--{flag} {name}: {lo:g}"
            + ("" if lo == hi else f":{hi:g}")
            + f" is outside the plausible range {a:g} to {b:g} (exclusive)"
        )


def problem_limits(
    parameters: Parameters | None, *, f1_per_sqrt_kappa: float | None
) -> tuple[tuple, np.ndarray | None]:
    """The limits of a :class:`FitProblem`: the static ``(param, fixed)`` per limited
    parameter (sorted), and their ``(lo, hi)`` rows in the fitted parameters' own scale
    (``log κ``, ζ); ``f1_per_sqrt_kappa`` is ``f_1/√κ`` of the problem (None when a static
    test makes it depend on the fit: f_1 cannot be limited). ``((), None)`` for none."""
    if parameters is None or not parameters.limits:
        return (), None
    out = []
    for name, lo, hi in parameters.limits:
        if name == "f1_hz":
            if f1_per_sqrt_kappa is None:
                raise CalibrationError(
                    "--fix/--bounds f1_hz: with a static test f_1 also depends on the fitted "
                    "EI; limit zeta only, or leave the static test out"
                )
            lo, hi = (2.0 * math.log(f / f1_per_sqrt_kappa) for f in (lo, hi))
        out.append((LIMITABLE[name], lo == hi, lo, hi))
    out.sort()
    return tuple((n, f) for n, f, _, _ in out), np.array([[lo, hi] for *_, lo, hi in out])


def limited(limits: tuple, values, key: str, u, default):
    """A parameter through its limit (fixed value, or logistic on the interval), or
    ``default(u)`` when it has none."""
    for i, (name, fixed) in enumerate(limits):
        if name == key:
            lo, hi = values[i, 0], values[i, 1]
            if fixed:
                return lo + 0.0 * u  # a zero Jacobian column: the parameter leaves the fit
            return lsq.to_interval(u, lo, hi)
    return default(u)


def free_start(limits: tuple, values, theta: dict, zeta_max: float) -> dict:
    """Start parameters (unlimited meaning: ``log κ``, logistic ζ on (0, zeta_max)) in the
    limited parametrisation: each moved inside its interval and mapped back through it."""
    theta = dict(theta)
    for i, (name, fixed) in enumerate(limits):
        lo, hi = values[i, 0], values[i, 1]
        if name == "log_kappa":
            x = theta["log_kappa"]
        else:
            x = lsq.to_interval(theta["zeta_u"], 0.0, zeta_max)
        if fixed:
            u = jnp.zeros_like(x)
        else:
            margin = 0.01 * (hi - lo)
            u = lsq.from_interval(jnp.clip(x, lo + margin, hi - margin), lo, hi)
        theta[name] = u
    return theta


def at_bound(limits: tuple, optimum: dict) -> dict[str, bool]:
    """Per bounded parameter (``log_kappa``, ``zeta_u``), whether the optimum sits at a
    bound (its logistic fraction within :data:`AT_BOUND` of 0 or 1)."""
    out = {}
    for name, fixed in limits:
        if fixed:
            continue
        u = float(np.clip(np.ravel(np.asarray(optimum[name]))[0], -700.0, 700.0))
        p = 1.0 / (1.0 + math.exp(-u))
        out[name] = bool(min(p, 1.0 - p) < AT_BOUND)
    return out
