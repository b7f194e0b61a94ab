"""Has a whisker changed, and since when? Each whisker's history searched for a lasting change.

Per whisker (and per kind of session, plucks or drives: their values are not mixed) and per
parameter p (f_1 or ζ), with the sessions in name order, sessions whose fit is usable (status
``ok`` or ``check`` and a finite, positive value) are read one after another, as a nightly run
would have seen them:

* the **reference** is the usable sessions before this one that were not found changed; the
  first ``K`` (``baseline``, 2 by default) only form it. Its centre ``m`` is their mean;
* the **session-to-session noise** of one session's value, ``σ_day``, is the largest of: the
  scatter of the reference sessions (standard deviation; it holds everything that changes
  from one day to the next: the mount, the temperature, the plucks), the same scatter pooled
  over the fleet's whiskers, relative to each one's centre (with two reference sessions a
  whisker's own scatter has one degree of freedom, the fleet's many), the spread of repeated
  plucks within the reference sessions (pooled standard deviation over ``√n̄``), and the
  median 1σ the reference fits report;
* a session's change ``Δ = v − m`` has ``σ_Δ² = σ_day²/K_ref + max(σ_day², s²/n)`` (the
  reference mean's noise, and the session's own, never below what the spread ``s`` of its
  own ``n`` plucks says), ``z = Δ/σ_Δ``, and the two-sided normal p-value of ``z``;
* a **step** is found where ``|z| ≥ z_min`` and the relative change ``|Δ/m|`` is at least a
  floor (1 % for f_1, 20 % for ζ by default: f_1 moves by a fraction of a percent with
  temperature, ζ by several percent with the pluck's amplitude); a **drift** where a
  two-sided CUSUM of the z's, ``S⁺ = max(0, S⁺ + z − k)``, ``S⁻ = max(0, S⁻ − z − k)``,
  reaches ``h`` (``k = 0.5``, ``h = 5``) and the session's relative change is at least the
  floor. A session that is neither, and whose z is below ``z_min``, joins the reference;
* once found, the change is located by a two-segment search over the whole history (every
  usable session, before and after the one that found it): the session ``c`` maximising
  ``|mean(v_{≥c}) − mean(v_{<c})| / (σ_day √(1/n_< + 1/n_≥))``, with at least ``K``
  sessions before it. That session is where the **change began**: it and every later
  session are flagged (a change that lasts stays flagged), with the change's size
  ``mean(v_{≥c}) − mean(v_{<c})`` and its 1σ ``√(σ_day²/n_< + σ_≥²/n_≥)`` (``σ_≥`` the
  larger of ``σ_day`` and the later sessions' own scatter: a drift's later sessions spread);
  the reference becomes the sessions before ``c``;
* a session whose fit failed (any other status, a value that is not a positive number, a
  torn table row) is flagged as ``fit`` with its status: a whisker that suddenly no longer
  fits is worth a look, and it is never dropped silently.

With fewer than ``K`` usable sessions a whisker is not checked (a note says so). With a
reference of fewer than 3 sessions its own scatter says little, and the fleet's pooled
scatter carries the judgement (a note says so, and each history gives the smallest change
that could be flagged).
"""

import math
from dataclasses import dataclass, field

import numpy as np

from ._calibrate import USABLE
from ._table import COLUMNS, FleetError

#: Parameters checked: table column → per-pluck column.
PARAMETERS = {"f1_hz": "f1_plucks", "zeta": "zeta_plucks"}
#: Default floors on the relative change (fraction) below which no change is flagged.
MIN_CHANGE = {"f1_hz": 0.01, "zeta": 0.20}
#: Default |z| at and above which a single session's change is significant.
Z_MIN = 4.0
#: Default number of usable sessions forming the first reference.
BASELINE = 2
#: The CUSUM's allowance ``k`` and decision interval ``h`` (in units of ``σ_Δ``).
DRIFT_K, DRIFT_H = 0.5, 5.0
#: Reference sessions below which a whisker's own scatter is not trusted alone (a note).
FEW = 3


@dataclass
class WhiskerHistory:
    """One whisker's sessions, values, reference band and changes (for plots and reports).

    Attributes:
        whisker: Its id (with `` (drive)`` for the sessions of a driving health log).
        sessions: Its sessions, in order.
        values: Parameter → values per session (NaN where the fit is not usable).
        errors: Parameter → the 1σ each fit reports.
        plucks: Parameter → per session, the per-pluck (or per-block) values.
        baseline: Number of sessions forming the first reference (0: too few usable).
        centre: Parameter → the final reference's centre ``m``.
        band: Parameter → half-width of the no-flag band around ``m`` (``max(z_min σ_Δ,
            floor |m|)``, ``σ_Δ`` of a session whose plucks agree): the smallest single
            session change that is flagged.
        sigma: Parameter → that ``σ_Δ``.
        reference: Parameter → number of sessions in the final reference.
        began: Parameter → index of the session where the change began (changed ones).
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
    reference: dict[str, int] = field(default_factory=dict)
    began: dict[str, int] = field(default_factory=dict)
    flagged: list[str] = field(default_factory=list)


@dataclass
class FleetCheck:
    """Outcome of :func:`check_fleet`.

    Attributes:
        changes: One dict per session after the first reference and parameter: ``whisker``,
            ``source`` (``pluck`` or ``drive``), ``session``, ``parameter``, ``value``,
            ``baseline`` (the reference centre it is compared with), ``change_pct``,
            ``sigma``, ``z``, ``p_value`` (two-sided, normal), ``cusum``, ``flagged``,
            ``status``, ``began`` (the session where the change began, or ``""``).
        flags: The flagged ones (the ``fit`` parameter for a failed fit).
        events: One dict per change found: ``whisker``, ``source``, ``parameter``,
            ``began``, ``detected`` (the session that found it), ``rule`` (``step`` or
            ``drift``), ``before`` (the mean before), ``size`` and ``size_sigma`` (the
            change and its 1σ, in the parameter's units), ``size_pct``, ``n_before``,
            ``n_after``.
        histories: History name → :class:`WhiskerHistory`.
        notes: Whiskers that could not be checked, or only with a short reference, and
            rows that are not numbers.
        settings: The rule's settings.
    """

    changes: list[dict]
    flags: list[dict]
    events: list[dict]
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


def _row_status(row) -> str:
    """The row's status, or what is wrong with a row whose status says usable but whose
    values are not positive numbers (a torn or edited table)."""
    status = str(row.get("status") or "").strip() or "no status"
    if status not in USABLE:
        return status
    for p in PARAMETERS:
        v = _float(row.get(p))
        if not (math.isfinite(v) and v > 0):
            return f"bad value: {p} = {row.get(p)!r}"
    return status


def refuse_corrupt_values(path, rows: list[dict]) -> None:
    """Refuse a table (as read by :func:`whiskerid.fleet.read_table`) in which a row whose
    status says its fit is usable holds an f1 or a ζ that is not a positive number.

    A failed fit or drive legitimately logs NaN with a status that is not usable (and
    :func:`check_fleet` flags it); NaN, a blank or a negative value beside ``ok`` is a file
    edited or damaged, which would otherwise be flagged as a failed fit and hide the cause.

    Raises:
        FleetError: Naming the file, the line and the column.
    """
    for line, row in enumerate(rows, start=2):
        if str(row.get("status") or "").strip() not in USABLE:
            continue
        for p in PARAMETERS:
            v = _float(row.get(p))
            if not (math.isfinite(v) and v > 0):
                raise FleetError(
                    f"{path}: line {line}, column {COLUMNS.index(p) + 1} ({p}) is "
                    f"{row.get(p)!r} beside status {row.get('status')!r}; a usable fit has a "
                    "positive number there: the file was edited or damaged (restore it, or "
                    "fit the session again)"
                )


def check_fleet(
    rows: list[dict],
    *,
    baseline: int = BASELINE,
    z_min: float = Z_MIN,
    min_change: dict[str, float] | None = None,
    drift_k: float = DRIFT_K,
    drift_h: float = DRIFT_H,
) -> FleetCheck:
    """Search every whisker's history for a lasting change (see the module docstring).

    Args:
        rows: The fleet table's rows (:func:`whiskerid.fleet.read_table`), and those of a
            driving health log (``source`` = ``drive``) if any.
        baseline: Usable sessions forming each whisker's first reference (≥ 1; with 1 the
            fleet's scatter and the repeats within it must give the noise).
        z_min: |z| at and above which a single session's change is significant.
        min_change: Parameter → floor on the relative change (fraction); defaults
            :data:`MIN_CHANGE`.
        drift_k: The CUSUM's allowance (in σ_Δ).
        drift_h: The CUSUM's decision interval (in σ_Δ); ``inf`` turns it off.

    Returns:
        A :class:`FleetCheck`.
    """
    if baseline < 1:
        raise ValueError(f"baseline {baseline} must be at least 1 session")
    if not z_min > 0:
        raise ValueError(f"z_min {z_min} must be positive")
    if not (drift_k >= 0 and drift_h > 0):
        raise ValueError(f"drift_k {drift_k} must be ≥ 0 and drift_h {drift_h} positive")
    floors = {**MIN_CHANGE, **(min_change or {})}
    groups: dict[tuple[str, str], list[dict]] = {}
    notes = []
    for r in rows:
        whisker = str(r.get("whisker") or "").strip()
        if not whisker:
            notes.append(f"a row with no whisker (session {r.get('session')!r}) is left out")
            continue
        groups.setdefault((whisker, str(r.get("source") or "pluck")), []).append(r)
    hists = {key: _history(key, sorted(g, key=lambda r: str(r.get("session"))))
             for key, g in sorted(groups.items())}  # fmt: skip
    settings = {"baseline": baseline, "z_min": z_min, "min_change": floors,
                "drift_k": drift_k, "drift_h": drift_h,
                "p_value": "two-sided, normal z"}  # fmt: skip
    # pass 1: the fleet's scatter from each whisker's first sessions (a robust pool, so a
    # whisker changed early cannot inflate it); pass 2: from each one's final reference
    pooled = _pooled(hists, {key: _first(h, baseline) for key, (h, _) in hists.items()})
    for _ in range(2):
        changes, events, refs = [], [], {}
        for key, (hist, status) in hists.items():
            rule = (baseline, z_min, floors, pooled.get(key[1], {}), drift_k, drift_h)
            ch, ev, refs[key] = _check_history(hist, key, status, *rule)
            changes += ch
            events += ev
        pooled = _pooled(hists, refs)
    for key, (hist, status) in hists.items():
        notes += _notes(hist, status, baseline, key[1], pooled.get(key[1], {}))
        hist.flagged = sorted({c["session"] for c in changes if c["flagged"]
                               and (c["whisker"], c["source"]) == key})  # fmt: skip
    flags = [c for c in changes if c["flagged"]]
    return FleetCheck(changes, flags, events, {h.whisker: h for h, _ in hists.values()},
                      notes, settings)  # fmt: skip


def _history(key, rows) -> tuple[WhiskerHistory, list[str]]:
    whisker, source = key
    status = [_row_status(r) for r in rows]
    usable = [s in USABLE for s in status]
    name = whisker if source == "pluck" else f"{whisker} ({source})"
    hist = WhiskerHistory(
        whisker=name,
        sessions=[str(r.get("session")) for r in rows],
        values={p: np.array([_float(r.get(p)) if u else math.nan for r, u in zip(rows, usable,
                                                                              strict=True)])
                for p in PARAMETERS},
        errors={p: np.array([_float(r.get(p.replace("_hz", "") + "_std")) for r in rows])
                for p in PARAMETERS},
        plucks={p: [_usable_plucks(r, col) if u else [] for r, u in zip(rows, usable,
                                                                       strict=True)]
                for p, col in PARAMETERS.items()},
    )  # fmt: skip
    return hist, status


def _first(hist: WhiskerHistory, k: int) -> dict[str, list[int]]:
    idx = np.flatnonzero(np.isfinite(hist.values["f1_hz"]))
    return {p: idx[: max(k, 2)].tolist() for p in PARAMETERS}


def _pooled(hists, refs) -> dict[str, dict[str, tuple[float, int]]]:
    """Per source and parameter: the fleet's relative session-to-session scatter and its
    degrees of freedom, the median of the whiskers' own variances (each over its
    reference, relative to its centre) scaled to a variance by the median of a χ²."""
    from scipy.stats import chi2

    out: dict[str, dict[str, tuple[float, int]]] = {}
    for p in PARAMETERS:
        per_source: dict[str, list[tuple[float, int]]] = {}
        for key, (hist, _) in hists.items():
            v = hist.values[p][refs[key][p]] if refs[key][p] else np.array([])
            if v.size >= 2 and np.mean(v) != 0:
                rel = v / np.mean(v)
                per_source.setdefault(key[1], []).append((float(np.var(rel, ddof=1)), v.size - 1))
        for source, items in per_source.items():
            ratios = [s2 / (chi2.median(d) / d) for s2, d in items]
            dof = sum(d for _, d in items)
            out.setdefault(source, {})[p] = (math.sqrt(float(np.median(ratios))), dof)
    return out


def _sigma_day(hist, p, ref, pooled) -> float:
    """``σ_day``: the largest of the reference scatter (the whisker's own and the fleet's),
    the repeats' spread and the fits' 1σ."""
    values = hist.values[p][ref]
    between = float(np.std(values, ddof=1)) if values.size > 1 else 0.0
    fleet = pooled.get(p, (0.0, 0))[0] * abs(float(np.mean(values)))
    groups = [np.asarray(hist.plucks[p][i]) for i in ref]
    groups = [g for g in groups if g.size > 1]
    repeats = 0.0
    if groups:
        dof = sum(g.size - 1 for g in groups)
        pooled_sd = math.sqrt(sum(float(np.sum((g - g.mean()) ** 2)) for g in groups) / dof)
        n_mean = float(np.mean([len(hist.plucks[p][i]) or 1 for i in ref]))
        repeats = pooled_sd / math.sqrt(n_mean)
    errors = hist.errors[p][ref]
    errors = errors[np.isfinite(errors)]
    fit = float(np.median(errors)) if errors.size else 0.0
    return max(between, fleet, repeats, fit)


def _sigma_change(sigma_day: float, k: int, plucks: list[float]) -> float:
    """``σ_Δ`` of one session: the reference mean's noise and the session's own, the latter
    no smaller than its own plucks' spread says."""
    own = sigma_day**2
    if len(plucks) > 1:
        own = max(own, float(np.var(plucks, ddof=1)) / len(plucks))
    return math.sqrt(sigma_day**2 / k + own)


def _check_history(hist, key, status, k, z_min, floors, pooled, drift_k, drift_h):
    """The changes of one history; returns its change rows, its events and per parameter
    its final reference (indices)."""
    whisker, source = key
    usable = np.flatnonzero([s in USABLE for s in status])
    hist.began = {}
    if usable.size < k:
        hist.baseline = 0
        return [], [], {p: usable.tolist() for p in PARAMETERS}
    hist.baseline = k
    first_later = int(usable[k - 1]) + 1
    rows, events, refs = {}, [], {}
    for p in PARAMETERS:
        found, per_session, ref = _scan(hist, p, usable, k, z_min, floors[p], pooled,
                                         drift_k, drift_h)  # fmt: skip
        if found is not None:
            event, per_session, ref = _locate(hist, p, usable, k, found, pooled, drift_k)
            event.update(whisker=whisker, source=source, parameter=p)
            events.append(event)
            hist.began[p] = event["_began"]
        refs[p] = ref
        _band(hist, p, ref, pooled, z_min, floors[p])
        for i, d in per_session.items():
            rows[(i, p)] = d
    changes = []
    began = {p: hist.sessions[i] for p, i in hist.began.items()}
    for i in range(first_later, len(hist.sessions)):
        for p in PARAMETERS:
            d = rows.get((i, p))
            if d is None:
                continue
            flagged = p in hist.began and i >= hist.began[p]
            changes.append({"whisker": whisker, "source": source, "session": hist.sessions[i],
                            "parameter": p, **d, "flagged": flagged, "status": status[i],
                            "began": began.get(p, "") if flagged else ""})  # fmt: skip
        if status[i] not in USABLE:
            changes.append({"whisker": whisker, "source": source, "session": hist.sessions[i],
                            "parameter": "fit", "value": math.nan, "baseline": math.nan,
                            "change_pct": math.nan, "sigma": math.nan, "z": math.nan,
                            "p_value": math.nan, "cusum": math.nan, "flagged": True,
                            "status": status[i], "began": ""})  # fmt: skip
    for e in events:
        e.pop("_began")
    return changes, events, refs


def _compare(hist, p, i, ref, pooled) -> tuple[dict, float]:
    """Session ``i`` against the reference ``ref``: its row's numbers, and ``σ_day``."""
    v = float(hist.values[p][i])
    sigma = _sigma_day(hist, p, ref, pooled)
    m = float(np.mean(hist.values[p][ref]))
    s_i = _sigma_change(sigma, len(ref), hist.plucks[p][i])
    z = (v - m) / s_i if s_i > 0 else (math.inf if v != m else 0.0)
    return {"value": v, "baseline": m, "change_pct": 100 * (v / m - 1), "sigma": s_i, "z": z,
            "p_value": math.erfc(abs(z) / math.sqrt(2))}, sigma  # fmt: skip


def _scan(hist, p, usable, k, z_min, floor, pooled, drift_k, drift_h):
    """Sessions in order against the reference of the sessions before them that were not
    found changed: the index of the first session where a step or a drift is found (or
    None), each session's numbers, and the reference."""
    ref = [int(i) for i in usable[:k]]
    per_session = {}
    s_hi = s_lo = 0.0
    for i in (int(j) for j in usable[k:]):
        d, _ = _compare(hist, p, i, ref, pooled)
        z = d["z"]
        s_hi, s_lo = max(0.0, s_hi + z - drift_k), max(0.0, s_lo - z - drift_k)
        d["cusum"] = max(s_hi, s_lo)
        per_session[i] = d
        big = abs(d["change_pct"]) >= 100 * floor
        if big and (abs(z) >= z_min or d["cusum"] >= drift_h):
            return (i, "step" if abs(z) >= z_min else "drift"), per_session, ref
        if abs(z) < z_min and d["cusum"] < drift_h:
            ref.append(i)
    return None, per_session, ref


def _locate(hist, p, usable, k, found, pooled, drift_k):
    """Where the change found at ``found`` began (two-segment search), its size and 1σ,
    and every session's numbers against the sessions before it."""
    detected, rule = found
    v = hist.values[p][usable]
    limit = int(np.searchsorted(usable, detected))  # candidates up to the detecting session
    best, began = -1.0, limit
    for c in range(k, limit + 1):
        before, after = v[:c], v[c:]
        sigma = _sigma_day(hist, p, usable[:c].tolist(), pooled)
        if not sigma > 0:
            continue
        stat = abs(after.mean() - before.mean()) / (sigma * math.sqrt(1 / c + 1 / after.size))
        if stat > best:
            best, began = stat, c
    ref = usable[:began].tolist()
    sigma = _sigma_day(hist, p, ref, pooled)
    before, after = v[:began], v[began:]
    spread = float(np.std(after, ddof=1)) if after.size > 1 else 0.0
    size = float(after.mean() - before.mean())
    size_sigma = math.sqrt(sigma**2 / before.size + max(sigma, spread) ** 2 / after.size)
    per_session = {}
    s_hi = s_lo = 0.0
    for i in (int(j) for j in usable[k:]):
        d, _ = _compare(hist, p, i, [j for j in ref if j < i] if i < usable[began] else ref,
                        pooled)  # fmt: skip
        s_hi, s_lo = max(0.0, s_hi + d["z"] - drift_k), max(0.0, s_lo - d["z"] - drift_k)
        d["cusum"] = max(s_hi, s_lo)
        per_session[i] = d
    event = {
        "began": hist.sessions[usable[began]],
        "detected": hist.sessions[detected],
        "rule": rule,
        "before": float(before.mean()),
        "size": size,
        "size_sigma": size_sigma,
        "size_pct": 100 * size / float(before.mean()),
        "n_before": int(before.size),
        "n_after": int(after.size),
        "_began": int(usable[began]),
    }
    return event, per_session, ref


def _band(hist, p, ref, pooled, z_min, floor) -> None:
    sigma = _sigma_day(hist, p, ref, pooled)
    m = float(np.mean(hist.values[p][ref]))
    s_delta = sigma * math.sqrt(1 + 1 / len(ref))
    hist.centre[p], hist.sigma[p], hist.reference[p] = m, s_delta, len(ref)
    hist.band[p] = max(z_min * s_delta, floor * abs(m))


def _notes(hist, status, k, source, pooled) -> list[str]:
    out = []
    bad = [f"{s}: {st}" for s, st in zip(hist.sessions, status, strict=True)
           if st.startswith(("bad value", "torn"))]  # fmt: skip
    if bad:
        out.append(f"{hist.whisker}: row(s) that are not numbers, flagged as 'fit': "
                   + "; ".join(bad[:3]) + (" …" if len(bad) > 3 else ""))  # fmt: skip
    if not hist.baseline:
        n = sum(st in USABLE for st in status)
        out.append(f"{hist.whisker}: {n} usable session(s), the first reference needs {k}; "
                   "not checked yet")  # fmt: skip
        return out
    short = {p: n for p, n in hist.reference.items() if n < FEW}
    if short:
        widths = ", ".join(
            f"{'f1' if p == 'f1_hz' else 'zeta'} ±{100 * hist.band[p] / abs(hist.centre[p]):.2g} %"
            for p in short
        )
        dof = {p: pooled.get(p, (0.0, 0))[1] for p in short}
        out.append(
            f"{hist.whisker}: a reference of {min(short.values())} session(s): its own "
            f"scatter says little, the fleet's ({max(dof.values())} degrees of freedom) "
            f"judges it; the smallest change flagged is {widths}"
        )
    return out
