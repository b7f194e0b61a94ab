"""Fleet calibration and change detection, on a tiny simulated fleet on disk.

Three whiskers × three sessions × two plucks (one file each), from
:func:`whiskerid.fleet.simulate_fleet` (the exact model, Hall sensor, ADS1115), one whisker
with ζ × 1.5 from its last session on, and a session holding a corrupt file.
"""

import dataclasses
import json
import math
import shutil
import subprocess
import sys

import jax
import numpy as np
import pytest

from whiskerid.cli import main
from whiskerid.fit import calibrate, calibrate_each, observations_from_recording
from whiskerid.fleet import (
    COLUMNS,
    LayoutError,
    bucket_length,
    calibrate_fleet,
    check_fleet,
    discover,
    local_runner,
    read_table,
    simulate_fleet,
    write_table,
)
from whiskerid.io import read_recording
from whiskerid.model import load_record

#: The module's tests check what stays compiled from the fixture's run to theirs.
KEEP_COMPILED = True
_COMPILES: list[str] = []


def _listen(event, duration, **kwargs):
    if event == "/jax/core/compile/backend_compile_duration":
        _COMPILES.append(event)


jax.monitoring.register_event_duration_secs_listener(_listen)


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """The simulated fleet, its truth, and one calibration run of it."""
    base = tmp_path_factory.mktemp("fleet")
    root, out = base / "root", base / "out"
    truth = simulate_fleet(root, whiskers=3, sessions=3, plucks=2, damaged=1, baseline=2, seed=1)
    bad = root / "whisker-001" / "session-99"
    bad.mkdir()
    (bad / "pluck-1.csv").write_text("t,adc\n0.0,12\nnot a number,\n")
    per_session = []
    runner = _counting(local_runner, per_session)
    run = calibrate_fleet(root, out, runner=runner)
    return {"root": root, "out": out, "truth": truth, "run": run, "compiles": per_session}


def _counting(runner, counts):
    """``runner`` that records the compilations of each session it fits."""

    def run(sessions, settings, keys):
        before = len(_COMPILES)
        for result in runner(sessions, settings, keys):
            counts.append(len(_COMPILES) - before)
            before = len(_COMPILES)
            yield result

    return run


def _copy(fleet, tmp_path):
    root, out = tmp_path / "root", tmp_path / "out"
    shutil.copytree(fleet["root"], root)
    shutil.copytree(fleet["out"], out)
    return root, out


def test_calibrate_recovers_the_truth_and_keeps_a_bad_file_apart(fleet):
    run, truth = fleet["run"], fleet["truth"]
    assert (run.sessions, run.fitted, run.skipped, run.failed) == (10, 10, 0, 1)
    rows = {(r["whisker"], r["session"]): r for r in read_table(fleet["out"] / "fleet.csv")}
    bad = rows.pop(("whisker-001", "session-99"))
    assert bad["status"] == "bad data" and "pluck-1.csv" in bad["checks"]
    assert not (fleet["out"] / "whisker-001" / "session-99.toml").exists()
    for t in truth.sessions:
        row = rows[(t["whisker"], t["session"])]
        assert row["status"] in ("ok", "check"), row
        assert float(row["f1_hz"]) == pytest.approx(t["f1_hz"], rel=3e-3)
        assert float(row["zeta"]) == pytest.approx(t["zeta"], rel=0.1)
        assert int(row["n_plucks"]) == 2 and len(row["f1_plucks"].split(";")) == 2
        assert row["pluck_status"] in ("ok;ok", "ok;check", "check;ok", "check;check")
        assert len(row["sha256"].split(";")) == 2
        assert (fleet["out"] / t["whisker"] / f"{t['session']}.toml").exists()


def test_sessions_of_one_shape_compile_once(fleet):
    # later sessions are other whiskers' plucks of the lengths already compiled
    counts = fleet["compiles"]
    assert counts[0] > 0 and counts[1:] == [0] * 9, counts


def _plucks(root, whisker, sessions):
    """The plucks of a whisker's sessions as the fleet fits them (cut to their bucket)."""
    record = load_record(root / whisker / "whisker.toml")
    out = []
    for s in sessions:
        for path in sorted((root / whisker / s).glob("*.csv")):
            for o in observations_from_recording(read_recording(path), record):
                n = bucket_length(o.t.size)
                out.append(dataclasses.replace(o, t=o.t[:n], y=o.y[:n]))
    return record, out


def test_batched_plucks_match_calibrate_and_a_bad_one_fails_alone(fleet):
    record, good = _plucks(fleet["root"], "whisker-002", ["session-01"])
    flat = dataclasses.replace(good[1], y=np.full(good[1].y.size, 7.0), name="flat")
    fits = calibrate_each([(record, o) for o in [good[0], flat, *good[1:]]])
    fit_flat = fits.pop(1)
    assert fit_flat.status == "error" and "constant" in fit_flat.message
    # the batch solves what calibrate solves, from its start values; both stop where a step
    # is below 1e-10 of the parameters, on paths of their own (calibrate solves twice)
    for o, fit in zip(good, fits, strict=True):
        cal = calibrate(record, [o])
        assert fit.status == cal.status and fit.status in ("ok", "check"), o.name
        assert fit.f1_hz == pytest.approx(cal.params["f1_hz"]["value"], rel=1e-7)
        assert fit.zeta == pytest.approx(cal.params["zeta"]["value"], rel=1e-6)
        # the batch's 1σ is the white-noise one; calibrate keeps it beside a robust one
        white = cal.params["f1_hz"].get("std_white", cal.params["f1_hz"]["std"])
        assert fit.f1_std == pytest.approx(white, rel=1e-4)


@pytest.mark.slow  # a noise lane takes up to ten times the steps, and every lane waits for it
def test_a_fit_to_noise_gets_the_verdict_of_calibrate_beside_a_good_one(fleet):
    record, good = _plucks(fleet["root"], "whisker-002", ["session-00"])
    # seeds 5 and 7 drive ζ to its bound: a solver other than calibrate's ran out of steps
    # there ("not converged") where calibrate stops and says "poor fit"
    seeds = (3, 5, 7, 9)
    y = [np.random.default_rng(seed).normal(size=good[0].y.size) for seed in seeds]
    noises = [
        dataclasses.replace(good[0], y=v, name=f"noise-{k}") for k, v in zip(seeds, y, strict=True)
    ]
    fit_good, *fits = calibrate_each([(record, good[0])] + [(record, n) for n in noises])
    for noise, fit in zip(noises, fits, strict=True):
        assert fit.status == calibrate(record, [noise]).status, noise.name
        assert fit.status not in ("ok", "check"), noise.name
    assert fit_good.f1_hz == pytest.approx(calibrate(record, [good[0]]).params["f1_hz"]["value"],
                                           rel=1e-7)  # fmt: skip


def test_rerun_fits_only_what_is_new(fleet, tmp_path):
    root, out = _copy(fleet, tmp_path)
    again = calibrate_fleet(root, out)
    assert (again.fitted, again.skipped) == (0, 10)
    new = root / "whisker-000" / "session-03"
    shutil.copytree(root / "whisker-000" / "session-02", new)
    counts = []
    third = calibrate_fleet(root, out, runner=_counting(local_runner, counts))
    assert (third.fitted, third.skipped) == (1, 10) and counts == [0]
    rows = {(r["whisker"], r["session"]): r for r in third.rows}
    old = rows[("whisker-000", "session-02")]
    assert rows[("whisker-000", "session-03")]["f1_hz"] == old["f1_hz"]


def test_an_interrupted_run_keeps_what_it_finished(fleet, tmp_path):
    root, out = _copy(fleet, tmp_path)
    rows = read_table(out / "fleet.csv")
    kept = [r for r in rows if r["whisker"] != "whisker-000"]  # its 3 sessions to fit again
    write_table(out / "fleet.csv", kept)

    def stop_after_two(sessions, settings, keys):
        for k, result in enumerate(local_runner(sessions, settings, keys)):
            if k == 2:
                raise KeyboardInterrupt
            yield result

    with pytest.raises(KeyboardInterrupt):
        calibrate_fleet(root, out, runner=stop_after_two)
    assert len(read_table(out / "fleet.csv")) == len(kept) + 2
    asked = []

    def spy(sessions, settings, keys):
        asked.append(len(sessions))
        return iter(())

    calibrate_fleet(root, out, runner=spy)
    assert asked == [len(rows) - len(kept) - 2]


def test_a_foreign_file_is_never_overwritten(fleet, tmp_path):
    root, out = _copy(fleet, tmp_path)
    (out / "fleet.csv").unlink()
    mine = out / "whisker-000" / "session-00.toml"
    mine.write_text("name = 'mine'\n")
    with pytest.raises(ValueError, match="not written by a fleet run"):
        calibrate_fleet(root, out)
    assert mine.read_text() == "name = 'mine'\n"


def test_check_flags_the_damaged_whisker_only(fleet):
    rows = [r for r in fleet["run"].rows if r["session"] != "session-99"]
    result = check_fleet(rows, baseline=2)
    (whisker, (first, kind)), = fleet["truth"].damage.items()  # fmt: skip
    flagged = {(f["whisker"], f["session"], f["parameter"]) for f in result.flags}
    assert flagged == {(whisker, first, "zeta" if kind == "zeta" else "f1_hz")}


# Synthetic tables: per-pluck scatter 0.1 % (f1) and 4 % (ζ), day-to-day 0.2 % and 5 %.
@pytest.mark.parametrize(
    ("f1_factor", "zeta_factor", "expected"),
    [(0.97, 1.0, {"f1_hz"}), (1.0, 1.5, {"zeta"}), (1.0, 1.0, set()), (0.995, 1.1, set())],
)
def test_check_rule(f1_factor, zeta_factor, expected):
    rng = np.random.default_rng(0)
    rows = []
    for s in range(6):
        hurt = s >= 4
        f1_day = 46.0 * (1 + 0.002 * rng.normal()) * (f1_factor if hurt else 1.0)
        zeta_day = 0.04 * (1 + 0.05 * rng.normal()) * (zeta_factor if hurt else 1.0)
        f1_k = f1_day * (1 + 0.001 * rng.normal(size=3))
        zeta_k = zeta_day * (1 + 0.04 * rng.normal(size=3))
        rows.append({
            "whisker": "w", "session": f"s{s}", "status": "ok", "f1_hz": str(f1_k.mean()),
            "f1_std": "0.001", "zeta": str(zeta_k.mean()), "zeta_std": "0.0001",
            "f1_plucks": ";".join(map(str, f1_k)), "zeta_plucks": ";".join(map(str, zeta_k)),
            "pluck_status": "ok;ok;ok",
        })  # fmt: skip
    result = check_fleet(rows, baseline=3)
    assert {f["parameter"] for f in result.flags} == expected
    assert all(f["session"] in ("s4", "s5") for f in result.flags)
    for f in result.flags:
        assert f["p_value"] == pytest.approx(math.erfc(abs(f["z"]) / math.sqrt(2)))


def _layouts(tmp_path):
    ok = tmp_path / "ok" / "w1"
    (ok / "s1").mkdir(parents=True)
    (ok / "whisker.toml").write_text("")
    (ok / "s1" / "a.csv").write_text("")
    return ok


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda w: (w / "x.csv").write_text(""), "not in a session folder"),
        (lambda w: (w.parent / "y.npy").write_text(""), "directly"),
        (lambda w: shutil.rmtree(w.parent), "does not exist"),
    ],
)
def test_a_bad_layout_says_what_was_found_and_expected(tmp_path, damage, message):
    w = _layouts(tmp_path)
    assert [s.session for s in discover(w.parent)] == ["s1"]
    damage(w)
    with pytest.raises(LayoutError, match=message) as err:
        discover(w.parent)
    assert "expected" in str(err.value) or "record" in str(err.value)


def test_an_empty_session_or_a_missing_record_is_isolated(fleet, tmp_path):
    root, out = _copy(fleet, tmp_path)
    (root / "whisker-000" / "session-07").mkdir()  # an empty session folder
    (root / "whisker-001" / "whisker.toml").unlink()  # a whisker without its record
    run = calibrate_fleet(root, out)
    rows = {(r["whisker"], r["session"]): r for r in run.rows}
    empty = rows[("whisker-000", "session-07")]
    assert empty["status"] == "bad data" and "holds no recordings" in empty["checks"]
    orphans = [r for (w, _), r in rows.items() if w == "whisker-001"]
    assert len(orphans) == 4
    assert all(r["status"] == "bad data" and "no record" in r["checks"] for r in orphans)
    assert all(r["status"] in ("ok", "check") for (w, s), r in rows.items()
               if w == "whisker-002")  # fmt: skip
    assert (run.fitted, run.skipped) == (5, 6)  # nothing else fitted again


def test_cli_writes_the_table_flags_and_plots(fleet, tmp_path, capsys):
    root, out = _copy(fleet, tmp_path)
    (out / "whisker-002" / "session-01.toml").unlink()
    before = (out / "fleet.csv").read_text()
    assert main(["fleet", "calibrate", str(root), "--out", str(out), "--quiet", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert (summary["fitted"], summary["skipped"]) == (1, 9)
    assert (out / "whisker-002" / "session-01.toml").exists()
    after = (out / "fleet.csv").read_text()
    assert after != before and len(after.splitlines()) == len(before.splitlines()) == 11
    check = tmp_path / "check"
    args = ["fleet", "check", str(out), "--baseline", "2", "--out", str(check), "--json"]
    assert main(args) == 0
    result = json.loads(capsys.readouterr().out)
    (whisker, _), = fleet["truth"].damage.items()  # fmt: skip
    assert result["flagged_whiskers"] == 1
    assert (check / f"{whisker}.png").stat().st_size > 1000
    lines = (check / "flags.csv").read_text().splitlines()
    assert lines[0].startswith("whisker,source,session,parameter") and whisker in lines[1]
    assert result["events"][0]["whisker"] == whisker
    assert main(["fleet", "check", str(tmp_path / "nowhere")]) == 2
    assert "fleet calibrate" in capsys.readouterr().err


def test_ray_with_no_cluster_names_our_option_and_writes_nothing(fleet, tmp_path, capsys):
    pytest.importorskip("ray")
    out = tmp_path / "out"
    args = ["fleet", "calibrate", str(fleet["root"]), "--out", str(out), "--ray", "no-such:x"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--ray no-such:x" in err and "--address" not in err and "--ray local" in err
    assert not out.exists()


@pytest.mark.slow
def test_ray_with_two_workers_gives_the_local_table(fleet, tmp_path):
    pytest.importorskip("ray")
    out = tmp_path / "ray-out"
    cmd = [sys.executable, "-m", "whiskerid.cli", "fleet", "calibrate", str(fleet["root"]),
           "--out", str(out), "--ray", "local", "--workers", "2", "--quiet"]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    local = read_table(fleet["out"] / "fleet.csv")
    remote = read_table(out / "fleet.csv")
    same = [c for c in COLUMNS if c not in ("fitted_at", "fit_s")]
    assert [[r[c] for c in same] for r in remote] == [[r[c] for c in same] for r in local]


def test_the_progress_line_moves_while_a_stage_lasts():
    import time

    from whiskerid.fleet._calibrate import _Ticker

    class Bar:
        def __init__(self):
            self.shown = []

        def set_postfix_str(self, text, refresh=True):
            self.shown.append(text)

    bar = Bar()
    ticker = _Ticker(bar)
    ticker.stage("fitting 3 single pluck(s)")
    time.sleep(1.3)  # a compilation, with nothing else to show
    ticker.stop()
    assert bar.shown[0] == "fitting 3 single pluck(s) (0 s)"
    assert len(bar.shown) >= 2 and bar.shown[-1].endswith("(1 s)")
