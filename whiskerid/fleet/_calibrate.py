"""Calibrate every whisker and session of a fleet, and keep the results in one table.

Each session is fitted by :func:`fit_session`, a pure function of the session's files, its
record and the settings (so the same numbers come out in this process or on a cluster):

* every recording is read as ``whiskerid calibrate`` reads it, one observation per pluck
  (:func:`whiskerid.fit.observations_from_file`);
* pluck windows shorter than 64 samples or 5 periods of the record's f_1 are left out (a
  hand's motion taken for a decay), and a pluck whose own f_1 is more than 10 % from the
  session's is marked ``outlier`` and kept out of the within-session spread;
* each pluck is cut to a *bucket length*, the longest power of two (samples) that fits in
  it: plucks of one bucket are fits of the same shapes, which one compiled program serves
  whatever the whisker (a whisker's numbers are traced leaves), so a fleet compiles a few
  programs, not one per pluck. The decay's start is kept and at most half of its window's
  tail dropped; a window that ends where the decay sinks into the noise (four or more time
  constants) holds over nine tenths of its information (which goes as the squared
  amplitude) in its first half, so little is lost;
* each pluck is calibrated on its own (its f_1 and ζ give the within-session spread that
  change detection needs): the plucks of many sessions at once, those of one bucket in one
  batched program (:func:`whiskerid.fit.calibrate_each`, from the start values calibrate
  would use, a status per pluck);
* all plucks of the session are then calibrated jointly (shared f_1 and ζ, their own
  nuisances; plucks ordered by length so that sessions of the same lengths share one
  compiled program), starting from the single plucks' values when they agree (else from
  its own start search): the joint fit gives the session's values, their 1σ (white noise
  or HAC, as :func:`whiskerid.fit.calibrate` reports) and its calibration record.

:func:`calibrate_fleet` finds the sessions (:func:`whiskerid.fleet.discover`), skips those
already done with the same data, record and settings (a session's *key* is the SHA-256 of its
files' SHA-256, the record's and the settings'), fits the rest in this process or on a Ray
cluster, and writes each session's record ``OUT/<whisker>/<session>.toml`` and the table
``OUT/fleet.csv`` (each atomically: a record as its session finishes, the table at most once a
second and when the run ends or is interrupted, so that an interrupted run keeps what it
finished).
A session whose data cannot be read or fitted gets its own status and never stops the others.
"""

import datetime
import hashlib
import json
import math
import time
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from .._version import __version__
from ..fit import (
    CalibrationError,
    PluckFit,
    calibrate,
    calibrate_each,
    observations_from_file,
    sha256_of,
)
from ..io import RecordingError, atomic_write
from ..model import RecordError, load_record
from ._layout import Session, discover
from ._table import COLUMNS, TABLE_NAME, FleetError, read_table, write_table

#: Statuses of a converged fit whose values may be used (``check``: a check failed, e.g. the
#: correlated residuals of every real recording, with the HAC 1σ reported).
USABLE = ("ok", "check")
#: How the plucks are cut: part of every key, so a change of the rule refits everything.
BUCKET_RULE = "2^j"
#: Pluck windows shorter than this many samples or periods of the record's f_1 are left out:
#: a real pluck rings for many periods (at ζ = 0.1, over six before it sinks 35 dB), a
#: short window is a hand's motion taken for a decay.
MIN_SAMPLES, MIN_PERIODS = 64, 5
#: A single pluck whose f_1 is further than this (relative) from its session's joint fit is
#: an outlier, left out of the within-session spread.
OUTLIER_F1 = 0.1
#: Statuses of a session that has no record (nothing could be fitted).
NO_RECORD = ("bad data", "error")


@dataclass(frozen=True)
class FleetSettings:
    """How the recordings are read and fitted (the options of ``whiskerid calibrate``).

    Attributes:
        n_modes: Modes in the model.
        pin: What fixes EI or C (``auto``, ``geometry``, ``material``).
        solver: Least-squares solver.
        observable: What the signal is, or ``auto`` (column name or ``units`` metadata).
        time_col: Time column (s).
        signal_col: Signal column (the first one by default).
        scale: Multiply the signal by this.
        units_g: The signal is acceleration in g.
        excitation: ``auto`` or ``decay``, ``sine``, ``base``.
        fit_gain: Fit the sensor gain.
        gain_known: Take a voltage's or ADC's gain from the record.
    """

    n_modes: int = 2
    pin: str = "auto"
    solver: str = "levenberg-marquardt"
    observable: str = "auto"
    time_col: str = "t"
    signal_col: str | None = None
    scale: float = 1.0
    units_g: bool = False
    excitation: str = "auto"
    fit_gain: bool = False
    gain_known: bool = False

    def digest(self) -> str:
        """SHA-256 of the settings, the bucket rule and the package version."""
        text = json.dumps(
            {**asdict(self), "bucket_rule": BUCKET_RULE, "version": __version__}, sort_keys=True
        )
        return hashlib.sha256(text.encode()).hexdigest()


# --------------------------------------------------------------------------- one session
def bucket_length(n: int) -> int:
    """The longest power of two not above ``n`` (n ≥ 16)."""
    return 1 << (max(int(n), 16).bit_length() - 1)


def _bucketed(obs):
    n = bucket_length(obs.t.size)
    if n == obs.t.size:
        return obs
    return replace(obs, t=obs.t[:n], y=obs.y[:n],
                   base_acc=None if obs.base_acc is None else obs.base_acc[:n])  # fmt: skip


def _observations(files, record, settings: FleetSettings) -> list:
    out = []
    f1 = float(record.whisker().natural_frequencies_hz[0])
    for path in files:
        out += observations_from_file(
            path,
            record,
            time_col=settings.time_col,
            signal_col=settings.signal_col,
            observable=settings.observable,
            excitation=settings.excitation,
            scale=settings.scale,
            units_g=settings.units_g,
            fit_gain=settings.fit_gain,
            gain_known=settings.gain_known,
        )
    kept = [o for o in out if o.t.size >= MIN_SAMPLES and o.t[-1] - o.t[0] >= MIN_PERIODS / f1]
    if not kept:
        raise CalibrationError(
            f"no pluck window of at least {MIN_SAMPLES} samples and {MIN_PERIODS} periods of "
            f"the record's f1 ({f1:.4g} Hz) in {', '.join(p.name for p in files)}"
        )
    return [_bucketed(o) for o in kept]


def _fit(record, obs, settings, start=None):
    return calibrate(record, obs, n_modes=settings.n_modes, pin=settings.pin,
                     solver=settings.solver, start=start)  # fmt: skip


def _value(cal, name):
    p = cal.params.get(name)
    return (math.nan, math.nan) if p is None else (p["value"], p["std"])


def _join(values, fmt="{:.10g}"):
    return ";".join(fmt.format(v) for v in values)


def fit_session(session: Session, settings: FleetSettings, key: str = "") -> dict:
    """Fit one session: each pluck on its own, then all jointly (see the module docstring).

    Never raises for bad data or a failed fit: the status says what happened (``bad data``
    with the reason in ``checks`` when a file cannot be read or holds no pluck, ``error``
    for anything else that went wrong).

    Args:
        session: The session (:func:`whiskerid.fleet.discover`).
        settings: How to read and fit.
        key: The session's key, written into its record (``[fit.fleet]``).

    Returns:
        ``{"row": ..., "record_toml": ...}``: the table row (:data:`COLUMNS`) and the joint
        fit's calibration record as TOML text (None when nothing was fitted).
    """
    return fit_sessions([session], settings, [key])[0]


def fit_sessions(sessions: list[Session], settings: FleetSettings, keys: list[str]) -> list[dict]:
    """:func:`fit_session` of several sessions, their single plucks batched (one task of a
    cluster; see :func:`iter_fit_sessions`)."""
    return list(iter_fit_sessions(sessions, settings, keys))


#: Sessions whose single plucks are fitted in one batch: the local run and each task of a
#: cluster take the same chunks, so that every fit sees the same batches either way.
SESSION_CHUNK = 16


def iter_fit_sessions(
    sessions: list[Session],
    settings: FleetSettings,
    keys: list[str],
    *,
    stage: Callable[[str], None] | None = None,
):
    """Fit the sessions, yielding each result (as :func:`fit_session`) when it is done.

    Every session is read first; the single plucks of all of them are then calibrated
    together, fits of one shape in one batched program
    (:func:`whiskerid.fit.calibrate_each`); then each session's joint fit starts from its
    single plucks' values.

    Args:
        sessions: The sessions.
        settings: How to read and fit.
        keys: Their keys.
        stage: Called with a few words saying what is being done (a progress bar's text):
            the first batch of each pluck length and the first joint fit of each shape
            compile their programs, which takes tens of seconds with nothing else to show.
    """
    say = stage or (lambda text: None)
    say(f"reading {len(sessions)} session(s)")
    prepared = [_prepare(s, settings, k) for s, k in zip(sessions, keys, strict=True)]
    n = sum(len(p.obs) for p in prepared if p.obs is not None)
    lengths = sorted({o.t.size for p in prepared if p.obs is not None for o in p.obs})
    sizes = ", ".join(map(str, lengths)) or "no"
    say(f"fitting {n} single pluck(s) of {len(sessions)} session(s) in batches of {sizes} "
        "samples (a new length compiles first)")  # fmt: skip
    singles = _singles(prepared, settings)
    for prep, fits in zip(prepared, singles, strict=True):
        say(f"joint fit of {prep.session.whisker}/{prep.session.session}")
        yield _finish(prep, fits, settings)


@dataclass
class _Prepared:
    session: Session
    key: str
    row: dict
    record: object = None
    obs: list | None = None
    seconds: float = 0.0


def _prepare(session: Session, settings: FleetSettings, key: str) -> _Prepared:
    """Read the session's files and record (a bad one gives the row's status)."""
    t0 = time.perf_counter()
    row = {c: "" for c in COLUMNS}
    row.update(whisker=session.whisker, session=session.session, key=key,
               files=";".join(p.name for p in session.files))  # fmt: skip
    try:
        row["sha256"] = ";".join(sha256_of(p) for p in session.files)
        row["record_sha256"] = sha256_of(session.record)
    except OSError:
        pass  # reported below, where the files are read
    prep = _Prepared(session, key, row)
    if session.problem:  # an empty session, a whisker without its record
        row.update(status="bad data", checks=session.problem, n_plucks=0)
        return prep
    try:
        prep.record = load_record(session.record)
        prep.obs = _observations(session.files, prep.record, settings)
    except (RecordingError, CalibrationError, RecordError, OSError, ValueError) as err:
        row.update(status="bad data", checks=" ".join(str(err).split()), n_plucks=0)
        prep.obs = None
    except Exception as err:  # one session's failure must never stop the others
        row.update(status="error", checks=" ".join(str(err).split()) or type(err).__name__)
        prep.obs = None
    prep.seconds = time.perf_counter() - t0
    return prep


def _singles(prepared: list[_Prepared], settings: FleetSettings) -> list[list | None]:
    """Each session's single-pluck fits (:class:`whiskerid.fit.PluckFit`), batched; a
    session whose plucks break the batch is fitted alone, so it cannot spoil the others."""
    todo = [p for p in prepared if p.obs is not None]
    out: dict[int, list | Exception] = {}
    t0 = time.perf_counter()
    try:
        fits = _calibrate_each(todo, settings)
        for p in todo:
            out[id(p)], fits = fits[: len(p.obs)], fits[len(p.obs) :]
    except Exception:
        for p in todo:
            try:
                out[id(p)] = _calibrate_each([p], settings)
            except Exception as err:
                out[id(p)] = err
    share = (time.perf_counter() - t0) / max(sum(len(p.obs) for p in todo), 1)
    for p in todo:
        p.seconds += share * len(p.obs)
    return [out.get(id(p)) for p in prepared]


def _calibrate_each(prepared: list[_Prepared], settings: FleetSettings):
    items = [(p.record, o) for p in prepared for o in p.obs]
    return calibrate_each(items, n_modes=settings.n_modes, pin=settings.pin,
                          solver=settings.solver)  # fmt: skip


def _finish(prep: _Prepared, singles, settings: FleetSettings) -> dict:
    t0 = time.perf_counter()
    row, toml_text = prep.row, None
    if prep.obs is not None:
        try:
            if isinstance(singles, Exception):
                raise singles
            row, toml_text = _fit_plucks(prep, singles, settings)
        except Exception as err:  # one session's failure must never stop the others
            row.update(status="error", checks=" ".join(str(err).split()) or type(err).__name__)
    row["fitted_at"] = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    row["fit_s"] = f"{prep.seconds + time.perf_counter() - t0:.3f}"
    return {"row": row, "record_toml": toml_text}


def _joint_start(obs, singles, ordered):
    """Start values of the joint fit of ``ordered`` from the single plucks' fits (in
    ``obs``'s order), or None (the joint fit then searches its own) when a pluck has no
    usable fit or the plucks disagree on f_1 (one of them may be a spurious window the joint
    fit must judge)."""
    if any(s.status not in USABLE for s in singles):
        return None
    f1 = np.array([s.f1_hz for s in singles])
    if not np.all(np.abs(f1 / np.median(f1) - 1) <= OUTLIER_F1):
        return None
    start = {k: np.median([np.asarray(s.optimum[k]) for s in singles], axis=0)
             for k in ("log_kappa", "zeta_u")}  # fmt: skip
    by_obs = {id(o): s for o, s in zip(obs, singles, strict=True)}
    start["recs"] = [by_obs[id(o)].optimum["recs"][0] for o in ordered]
    return start


def _fit_plucks(prep: _Prepared, singles, settings):
    session, key, record, obs, row = prep.session, prep.key, prep.record, prep.obs, prep.row
    ordered = sorted(obs, key=lambda o: -o.t.size)
    start = _joint_start(obs, singles, ordered)
    joint = _fit(record, ordered, settings, start=start)
    f1, f1_std = _value(joint, "f1_hz")
    zeta, zeta_std = _value(joint, "zeta")
    if len(obs) == 1:  # one pluck: its own fit is the joint one
        singles = [PluckFit(joint.status, f1, zeta)]
    f1_k = [s.f1_hz for s in singles]
    zeta_k = [s.zeta for s in singles]
    # A pluck far from the session's f_1 is not a repeat of it (a spurious window, a higher
    # mode taken for the first): it is kept out of the spread, marked "outlier".
    status_k = [
        "outlier" if s.status in USABLE and not abs(s.f1_hz / f1 - 1) <= OUTLIER_F1 else s.status
        for s in singles
    ]
    usable = [s for s, st in zip(singles, status_k, strict=True) if st in USABLE]
    sd = lambda v: float(np.std(v, ddof=1)) if len(v) > 1 else math.nan  # noqa: E731
    row.update(
        status=joint.status,
        f1_hz=f"{f1:.10g}",
        f1_std=f"{f1_std:.4g}",
        zeta=f"{zeta:.10g}",
        zeta_std=f"{zeta_std:.4g}",
        uncertainty="HAC" if joint.diagnostics["uncertainty"].startswith("HAC") else "white",
        checks="; ".join(f"{k}: {v}" for k, v in joint.checks.items()),
        n_plucks=len(obs),
        f1_plucks=_join(f1_k),
        zeta_plucks=_join(zeta_k),
        f1_pluck_sd=f"{sd([s.f1_hz for s in usable]):.4g}",
        zeta_pluck_sd=f"{sd([s.zeta for s in usable]):.4g}",
        pluck_status=";".join(status_k),
    )
    out = joint.record
    fit = dict(out.extra["fit"])
    fit["fleet"] = {
        "whisker": session.whisker,
        "session": session.session,
        "key": key,
        "settings": {k: v for k, v in asdict(settings).items() if v is not None},
        "joint_start": "single plucks" if start is not None else "start search",
        "plucks": [
            {
                "name": o.name,
                "n_samples": int(o.t.size),
                "status": s.status,
                "f1_hz": s.f1_hz,
                "zeta": s.zeta,
            }
            for o, s in zip(obs, singles, strict=True)
        ],
    }
    out = out.replace(extra={**out.extra, "fit": fit})
    return row, out.to_toml()


def session_key(session: Session, settings_digest: str) -> str:
    """SHA-256 of the session's files (names and SHA-256), its record's and the settings'."""
    parts = [f"{p.name}:{sha256_of(p)}" for p in session.files]
    record = sha256_of(session.record) if session.record.is_file() else "missing"
    parts += [f"record:{record}", f"settings:{settings_digest}"]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


def _ours(path: Path) -> bool:
    """Whether ``path`` is a session record written by a fleet run."""
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False
    return isinstance(data.get("fit", {}).get("fleet"), dict)


@dataclass
class FleetRun:
    """What :func:`calibrate_fleet` did.

    Attributes:
        table: The table's path.
        sessions: Sessions found.
        fitted: Sessions fitted in this run.
        skipped: Sessions already done with the same key.
        failed: Sessions fitted in this run whose status is not ``ok`` or ``check``.
        rows: The table's rows after the run.
        elapsed_s: Wall time of the fits (s).
    """

    table: Path
    sessions: int
    fitted: int
    skipped: int
    failed: int
    rows: list[dict]
    elapsed_s: float


def plan(root, out, record=None, settings: FleetSettings | None = None):
    """The sessions under ``root`` still to fit into ``out``, with their keys, and the rows
    already there (see :func:`calibrate_fleet`)."""
    settings = settings or FleetSettings()
    sessions = discover(root, record)
    out = Path(out)
    rows = {(r["whisker"], r["session"]): r for r in read_table(out / TABLE_NAME)}
    digest = settings.digest()
    todo, keys, foreign = [], [], []
    for s in sessions:
        key = session_key(s, digest)
        target = out / s.whisker / f"{s.session}.toml"
        done = rows.get((s.whisker, s.session))
        # (a session that could not be fitted has no record: its row alone says it is done)
        if done is not None and done["key"] == key and (target.exists() or done["status"]
                                                        in NO_RECORD):  # fmt: skip
            continue
        if target.exists() and not _ours(target):
            foreign.append(str(target))
        todo.append(s)
        keys.append(key)
    if foreign:
        raise FleetError(
            f"{len(foreign)} file(s) where session records go were not written by a fleet run "
            f"(e.g. {foreign[0]}); they are left alone: move them or give another --out folder"
        )
    return sessions, todo, keys, rows


def calibrate_fleet(
    root: str | Path,
    out: str | Path,
    *,
    record: str | Path | None = None,
    settings: FleetSettings | None = None,
    runner: Callable[[list[Session], FleetSettings, list[str]], Iterator[dict]] | None = None,
    progress: bool = False,
) -> FleetRun:
    """Calibrate every session under ``root`` not yet done, into ``out``.

    Args:
        root: ``ROOT/<whisker-id>/<session>/<recordings>`` (see :func:`discover`).
        out: Output folder: ``OUT/<whisker>/<session>.toml`` and ``OUT/fleet.csv``.
        record: One record for every whisker (default: each whisker's ``whisker.toml``).
        settings: How to read and fit (:class:`FleetSettings`).
        runner: Runs the sessions and yields each result as it is done (default: one after
            another in this process; :func:`ray_runner` spreads them over a Ray cluster).
        progress: Show a progress bar on stderr.

    Returns:
        A :class:`FleetRun`.

    Raises:
        LayoutError: ``root`` is not laid out as expected.
        FleetError: ``out`` holds files that are not a fleet run's where it would write.
    """
    settings = settings or FleetSettings()
    out = Path(out)
    sessions, todo, keys, rows = plan(root, out, record, settings)
    run = FleetRun(out / TABLE_NAME, len(sessions), 0, len(sessions) - len(todo), 0,
                   [], 0.0)  # fmt: skip
    runner = runner or local_runner
    t0 = time.perf_counter()
    last_write = 0.0
    bar = ticker = None
    if progress and todo:
        bar, ticker = _progress(len(todo))
    if runner is local_runner and bar is not None:
        results = runner(todo, settings, keys, stage=ticker.stage)
    else:
        if bar is not None and runner is not local_runner:
            ticker.stage("waiting for the first sessions from the workers")
        results = runner(todo, settings, keys)
    try:
        for result in results:
            row = result["row"]
            if result["record_toml"] is not None:
                atomic_write(out / row["whisker"] / f"{row['session']}.toml", result["record_toml"])
            rows[(row["whisker"], row["session"])] = row
            run.fitted += 1
            run.failed += row["status"] not in USABLE
            if time.perf_counter() - last_write > 1.0:
                write_table(run.table, rows.values())
                last_write = time.perf_counter()
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            ticker.stop()
            bar.close()
        if run.fitted or not run.table.exists():
            write_table(run.table, rows.values())
        run.elapsed_s = time.perf_counter() - t0
        run.rows = sorted(rows.values(), key=lambda r: (r["whisker"], r["session"]))
    return run


class _Ticker:
    """Refreshes a progress bar once a second with what is being done and for how long, so
    that a compilation of tens of seconds shows a line that moves."""

    def __init__(self, bar):
        import threading

        self.bar, self.text, self.since = bar, "", time.perf_counter()
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def stage(self, text: str) -> None:
        self.text, self.since = text, time.perf_counter()
        self._show()

    def _show(self) -> None:
        self.bar.set_postfix_str(f"{self.text} ({time.perf_counter() - self.since:.0f} s)",
                                 refresh=True)  # fmt: skip

    def _run(self) -> None:
        while not self._done.wait(1.0):
            self._show()

    def stop(self) -> None:
        self._done.set()
        self._thread.join()


def _progress(total: int):
    from tqdm import tqdm

    bar = tqdm(total=total, unit="session", desc="fleet calibrate", leave=False)
    return bar, _Ticker(bar)


def local_runner(
    sessions: list[Session],
    settings: FleetSettings,
    keys: list[str],
    *,
    stage: Callable[[str], None] | None = None,
):
    """Fit the sessions in this process, :data:`SESSION_CHUNK` at a time (yields each
    result; ``stage`` as :func:`iter_fit_sessions`)."""
    for i in range(0, len(sessions), SESSION_CHUNK):
        chunk = slice(i, i + SESSION_CHUNK)
        yield from iter_fit_sessions(sessions[chunk], settings, keys[chunk], stage=stage)
