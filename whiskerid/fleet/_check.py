"""Has a whisker changed? Each session's f_1 and ζ against the whisker's own baseline.

The rule, per whisker and per parameter p (f_1 or ζ), with the sessions in name order:

* the **baseline** is the first ``K`` sessions whose fit is usable (status ``ok`` or
  ``check``); its centre ``m`` is the mean of their values;
* the **session-to-session noise** of one session's value, ``σ_day``, is the largest of three
  estimates, so that no single one can make it too small: the scatter of the baseline
  sessions' values (standard deviation, K − 1 degrees of freedom; it holds everything that
  changes from one day to the next: the mount, the temperature, the plucks), the spread of
  repeated plucks within the baseline sessions (pooled standard deviation over
  ``Σ(n_s − 1)`` degrees of freedom, divided by ``√n̄`` for a mean of ``n̄`` plucks), and the
  median 1σ the baseline fits report (their HAC 1σ when the residuals are correlated; on real
  recordings the white-noise 1σ of one fit is far smaller than the repeats' spread);
* a later session's change ``Δ = v − m`` has ``σ_Δ² = σ_day²/K + max(σ_day², s²/n)`` (the
  noise of the baseline's mean, and the session's own: never below what the spread ``s`` of
  its own ``n`` plucks says, so that a session whose repeats disagree, e.g. plucks of very
  different amplitude on a beam whose damping depends on it, cannot show a change smaller
  than their disagreement), ``z = Δ/σ_Δ`` and the two-sided p-value of a normal ``z``;
* the session is **flagged** for p when ``|z| ≥ z_min`` *and* the relative change ``|Δ/m|`` is
  at least a floor (defaults: 1 % for f_1, 20 % for ζ): the floor keeps a baseline whose
  repeats agree by chance to a tiny spread from flagging changes too small to matter (f_1 moves
  by a fraction of a percent with temperature; ζ by several percent with the pluck's
  amplitude);
* a later session whose fit failed (any other status) is flagged as ``fit`` with its status:
  a whisker that suddenly no longer fits is worth a look too.
"""

import math
from dataclasses import dataclass, field

import numpy as np

from ._calibrate import USABLE

#: Parameters checked: table column → (per-pluck column, its name in reports).
PARAMETERS = {"f1_hz": "f1_plucks", "zeta": "zeta_plucks"}
#: Default floors on the relative change (fraction) below which no change is flagged.
MIN_CHANGE = {"f1_hz": 0.01, "zeta": 0.20}
#: Default |z| at and above which a change is significant.
Z_MIN = 4.0
#: Default number of baseline sessions.
BASELINE = 3


@dataclass
class WhiskerHistory:
    """One whisker's sessions, values and baseline band (for plots and reports).

    Attributes:
        whisker: Its id.
        sessions: Its sessions, in order.
        values: Parameter → values per session (NaN where the fit is not usable).
        errors: Parameter → the 1σ each fit reports.
        plucks: Parameter → per session, the per-pluck values.
        baseline: Number of baseline sessions used (0: too few usable sessions).
        centre: Parameter → baseline centre ``m``.
        band: Parameter → half-width of the no-flag band around ``m``
            (``max(z_min σ_Δ, floor |m|)``, with ``σ_Δ`` of a session whose plucks agree).
        sigma: Parameter → that ``σ_Δ``, ``σ_day √(1 + 1/K)``.
        flagged: Sessions flagged (for any parameter).
    """

    whisker: str
    sessions: list[str]
    values: dict[str, np.ndarray]
    errors: dict[str, np.ndarray]
    plucks: dict[str, list[list[float]]]
    baseline: int = 0
    centre: dict[str, float] = field(default_factory=dict)
    band: dict[str, float] = field(default_factory=dict)
    sigma: dict[str, float] = field(default_factory=dict)
    flagged: list[str] = field(default_factory=list)


@dataclass
class FleetCheck:
    """Outcome of :func:`check_fleet`.

    Attributes:
        changes: One dict per later session and parameter: ``whisker``, ``session``,
            ``parameter``, ``value``, ``baseline``, ``change_pct``, ``sigma``, ``z``,
            ``p_value`` (two-sided, normal), ``flagged``, ``status``.
        flags: The flagged ones (the ``fit`` parameter for a failed fit).
        histories: Whisker → :class:`WhiskerHistory`.
        notes: Whiskers that could not be checked, and why.
        settings: The rule's settings.
    """

    changes: list[dict]
    flags: list[dict]
    histories: dict[str, WhiskerHistory]
    notes: list[str]
    settings: dict


def _float(text) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def _floats(text) -> list[float]:
    return [_float(v) for v in str(text or "").split(";") if v != ""]


def _usable_plucks(row, col) -> list[float]:
    status = str(row.get("pluck_status") or "").split(";")
    values = _floats(row.get(col))
    return [v for v, s in zip(values, status, strict=False) if s in USABLE and math.isfinite(v)]


def check_fleet(
    rows: list[dict],
    *,
    baseline: int = BASELINE,
    z_min: float = Z_MIN,
    min_change: dict[str, float] | None = None,
) -> FleetCheck:
    """Compare every whisker's later sessions with its baseline (see the module docstring).

    Args:
        rows: The fleet table's rows (:func:`whiskerid.fleet.read_table`).
        baseline: Number of usable sessions forming each whisker's baseline (≥ 1; with 1
            the repeats within it must give the noise).
        z_min: |z| at and above which a change is significant.
        min_change: Parameter → floor on the relative change (fraction); defaults
            :data:`MIN_CHANGE`.

    Returns:
        A :class:`FleetCheck`.
    """
    if baseline < 1:
        raise ValueError(f"baseline {baseline} must be at least 1 session")
    if not z_min > 0:
        raise ValueError(f"z_min {z_min} must be positive")
    floors = {**MIN_CHANGE, **(min_change or {})}
    by_whisker: dict[str, list[dict]] = {}
    for r in rows:
        by_whisker.setdefault(r["whisker"], []).append(r)
    changes, notes, histories = [], [], {}
    for whisker, wrows in sorted(by_whisker.items()):
        wrows = sorted(wrows, key=lambda r: r["session"])
        hist, ch, note = _check_whisker(whisker, wrows, baseline, z_min, floors)
        histories[whisker] = hist
        changes += ch
        if note:
            notes.append(note)
    flags = [c for c in changes if c["flagged"]]
    settings = {"baseline": baseline, "z_min": z_min, "min_change": floors,
                "p_value": "two-sided, normal z"}  # fmt: skip
    return FleetCheck(changes, flags, histories, notes, settings)


def _check_whisker(whisker, rows, k, z_min, floors):
    usable = np.array([r["status"] in USABLE for r in rows])
    sessions = [r["session"] for r in rows]
    hist = WhiskerHistory(
        whisker=whisker,
        sessions=sessions,
        values={p: np.array([_float(r[p]) if u else math.nan for r, u in zip(rows, usable,
                                                                          strict=True)])
                for p in PARAMETERS},
        errors={p: np.array([_float(r.get(p.replace("_hz", "") + "_std")) for r in rows])
                for p in PARAMETERS},
        plucks={p: [_usable_plucks(r, col) for r in rows] for p, col in PARAMETERS.items()},
    )  # fmt: skip
    base = np.flatnonzero(usable)[:k]
    if base.size < k:
        return (
            hist,
            [],
            (f"{whisker}: {base.size} usable session(s), the baseline needs {k}; not checked yet"),
        )
    hist.baseline = int(base.size)
    later = range(int(base[-1]) + 1, len(rows))
    changes = []
    for p in PARAMETERS:
        sigma = _sigma_day(hist, p, base)
        if not sigma > 0:
            return hist, [], f"{whisker}: no spread to judge {p} by (one pluck per session?)"
        m = float(np.mean(hist.values[p][base]))
        s_delta = sigma * math.sqrt(1 + 1 / k)
        hist.centre[p], hist.sigma[p] = m, s_delta
        hist.band[p] = max(z_min * s_delta, floors[p] * abs(m))
        for i in later:
            row = rows[i]
            if not usable[i]:
                continue
            v = float(hist.values[p][i])
            s_i = _sigma_change(sigma, k, hist.plucks[p][i])
            z = (v - m) / s_i
            rel = v / m - 1
            flagged = bool(abs(z) >= z_min and abs(rel) >= floors[p])
            changes.append(
                {
                    "whisker": whisker,
                    "session": row["session"],
                    "parameter": p,
                    "value": v,
                    "baseline": m,
                    "change_pct": 100 * rel,
                    "sigma": s_i,
                    "z": z,
                    "p_value": math.erfc(abs(z) / math.sqrt(2)),
                    "flagged": flagged,
                    "status": row["status"],
                }
            )
    for i in later:
        if not usable[i]:
            changes.append(
                {
                    "whisker": whisker,
                    "session": rows[i]["session"],
                    "parameter": "fit",
                    "value": math.nan,
                    "baseline": math.nan,
                    "change_pct": math.nan,
                    "sigma": math.nan,
                    "z": math.nan,
                    "p_value": math.nan,
                    "flagged": True,
                    "status": rows[i]["status"],
                }
            )
    hist.flagged = sorted({c["session"] for c in changes if c["flagged"]})
    return hist, changes, None


def _sigma_change(sigma_day: float, k: int, plucks: list[float]) -> float:
    """``σ_Δ`` of one later session: the baseline mean's noise and the session's own, the
    latter no smaller than its own plucks' spread says (a session whose repeats disagree
    cannot show a change smaller than their disagreement)."""
    own = sigma_day**2
    if len(plucks) > 1:
        own = max(own, float(np.var(plucks, ddof=1)) / len(plucks))
    return math.sqrt(sigma_day**2 / k + own)


def _sigma_day(hist: WhiskerHistory, p: str, base: np.ndarray) -> float:
    """``σ_day``: the largest of the baseline scatter, the repeats' spread and the fits' 1σ."""
    values = hist.values[p][base]
    between = float(np.std(values, ddof=1)) if values.size > 1 else 0.0
    groups = [np.asarray(hist.plucks[p][i]) for i in base]
    groups = [g for g in groups if g.size > 1]
    repeats = 0.0
    if groups:
        dof = sum(g.size - 1 for g in groups)
        pooled = math.sqrt(sum(float(np.sum((g - g.mean()) ** 2)) for g in groups) / dof)
        n_mean = float(np.mean([len(hist.plucks[p][i]) or 1 for i in base]))
        repeats = pooled / math.sqrt(n_mean)
    errors = hist.errors[p][base]
    fit = float(np.nanmedian(errors)) if np.any(np.isfinite(errors)) else 0.0
    return max(between, repeats, fit)
