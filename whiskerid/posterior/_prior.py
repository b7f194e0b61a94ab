"""Priors of the posterior: the record's ``[prior]`` table checked, and log-densities."""

import math

import jax.numpy as jnp

from ..fit import ZETA_MAX

DISTS = ("uniform", "loguniform", "normal", "lognormal")
PRIOR_KEYS = ("zeta", "f1_hz", "kappa", "sigma_rel")
_DIST_ARGS = {
    "uniform": ("low", "high"),
    "loguniform": ("low", "high"),
    "normal": ("mu", "sigma"),
    "lognormal": ("mu", "sigma"),
}


class PosteriorError(ValueError):
    """Input that cannot be sampled (message says what)."""


# --------------------------------------------------------------------------- priors
def parse_prior(table: dict | None) -> dict[str, tuple[str, float, float]]:
    """Check a ``[prior]`` table: name → ``(dist, a, b)``.

    Args:
        table: e.g. ``{"zeta": {"dist": "uniform", "low": 0, "high": 0.5}}``.

    Raises:
        PosteriorError: unknown names or distributions, missing or invalid arguments.
    """
    out = {}
    for key, spec in (table or {}).items():
        if key not in PRIOR_KEYS:
            raise PosteriorError(f"prior: unknown parameter {key!r} (known: {PRIOR_KEYS})")
        if not isinstance(spec, dict) or spec.get("dist") not in DISTS:
            raise PosteriorError(f"prior {key}: give dist = one of {DISTS}")
        dist = spec["dist"]
        names = _DIST_ARGS[dist]
        try:
            a, b = (float(spec[n]) for n in names)
        except (KeyError, TypeError, ValueError):
            raise PosteriorError(f"prior {key}: {dist} needs numbers {names}") from None
        if dist in ("uniform", "loguniform") and not a < b:
            raise PosteriorError(f"prior {key}: need low < high")
        if dist == "loguniform" and not a > 0:
            raise PosteriorError(f"prior {key}: loguniform needs low > 0")
        if dist in ("normal", "lognormal") and not b > 0:
            raise PosteriorError(f"prior {key}: sigma must be > 0")
        out[key] = (dist, a, b)
    if "f1_hz" in out and "kappa" in out:
        raise PosteriorError("prior: give f1_hz or kappa, not both")
    return out


def prior_log_norm(dist: str, a, b):
    """The constant term of :func:`prior_logpdf` (log of the normalisation)."""
    if dist == "uniform":
        return -jnp.log(b - a)
    if dist == "loguniform":
        return -jnp.log(jnp.log(b / a))
    if dist in ("normal", "lognormal"):
        return -jnp.log(b) - 0.5 * math.log(2 * math.pi)
    raise PosteriorError(f"unknown prior {dist!r}")


def prior_logpdf(dist: str, x, a, b, log_norm=None):
    """Log-density of a prior at ``x`` (−inf outside a bounded support).

    ``log_norm``: :func:`prior_log_norm` of ``(dist, a, b)`` if already known (the
    log-probability passes it in with the data: computed from ``a`` and ``b`` on every call
    it took a few small XLA kernels per call).
    """
    if log_norm is None:
        log_norm = prior_log_norm(dist, a, b)
    if dist == "uniform":
        return jnp.where((x >= a) & (x <= b), log_norm, -jnp.inf)
    if dist == "loguniform":
        inside = (x >= a) & (x <= b)
        return jnp.where(inside, -jnp.log(x) + log_norm, -jnp.inf)
    if dist == "normal":
        return -0.5 * ((x - a) / b) ** 2 + log_norm
    if dist == "lognormal":
        lx = jnp.log(jnp.where(x > 0, x, 1.0))
        val = -lx - 0.5 * ((lx - a) / b) ** 2 + log_norm
        return jnp.where(x > 0, val, -jnp.inf)
    raise PosteriorError(f"unknown prior {dist!r}")


def default_prior(f1_hz: float) -> dict[str, tuple[str, float, float]]:
    """Priors used for the names the record's ``[prior]`` does not give."""
    return {
        "zeta": ("uniform", 0.0, ZETA_MAX),
        "f1_hz": ("loguniform", f1_hz / 10, f1_hz * 10),
        "sigma_rel": ("loguniform", 1e-6, 10.0),
    }


def prior_table(f1_hz: float, user: dict) -> dict[str, dict]:
    """The priors of a posterior, name → ``{"dist", "a", "b", "default"}``: the record's
    ``[prior]`` (``user``, parsed) over :func:`default_prior`; a prior on ``kappa`` replaces
    the default one on ``f1_hz`` (the same stiffness)."""
    priors = {
        k: {"dist": v[0], "a": v[1], "b": v[2], "default": True}
        for k, v in default_prior(f1_hz).items()
    }
    if "kappa" in user:
        priors.pop("f1_hz")
    for k, v in user.items():
        priors[k] = {"dist": v[0], "a": v[1], "b": v[2], "default": False}
    return priors


def prior_arrays(priors: dict[str, dict]) -> dict:
    """``{name: [a, b, log normaliser]}`` of :func:`prior_table`'s entries, as the
    log-probability's arguments take them."""
    return {
        k: jnp.asarray([p["a"], p["b"], float(prior_log_norm(p["dist"], p["a"], p["b"]))])
        for k, p in priors.items()
    }
