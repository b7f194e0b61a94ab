"""Change detection in a fleet's table: lasting steps and drifts, found where they began.

The tables are drawn here (numpy, seeded) with the noise a fleet shows: f1 moving 0.2 % and ζ
5 % from one session to the next, the single plucks of a session 0.05 % and 4 % apart.
"""

import math

import numpy as np
import pytest

from whiskerid.fleet import check_fleet, read_table, write_table


def _row(whisker, session, f1_k, zeta_k, status="ok"):
    return {
        "whisker": whisker, "session": session, "status": status,
        "f1_hz": repr(float(np.mean(f1_k))), "f1_std": "0.004",
        "zeta": repr(float(np.mean(zeta_k))), "zeta_std": "0.0004",
        "f1_plucks": ";".join(map(repr, f1_k)), "zeta_plucks": ";".join(map(repr, zeta_k)),
        "pluck_status": ";".join(["ok"] * len(f1_k)),
    }  # fmt: skip


def _fleet(seed, *, whiskers=8, sessions=4, plucks=3, damage=None):
    """Rows of a fleet; ``damage``: whisker index → (first session, f1 factor or a drift
    per session, ζ factor)."""
    rng = np.random.default_rng(seed)
    rows = []
    for w in range(whiskers):
        f1_w, zeta_w = rng.uniform(40, 50), 0.04 * math.exp(rng.normal(0, 0.25))
        first, f1_factor, zeta_factor = (damage or {}).get(w, (sessions, 1.0, 1.0))
        for s in range(sessions):
            f1 = f1_w * (1 + 0.002 * rng.normal())
            zeta = zeta_w * math.exp(0.05 * rng.normal())
            if s >= first:
                drift = callable(f1_factor)
                f1 *= f1_factor(s - first + 1) if drift else f1_factor
                zeta *= zeta_factor
            f1_k = f1 * (1 + 0.0005 * rng.normal(size=plucks))
            zeta_k = zeta * (1 + 0.04 * rng.normal(size=plucks))
            rows.append(_row(f"w{w}", f"2026-11-{3 + 7 * s:02d}", f1_k, zeta_k))
    return rows


def test_the_issue_case_a_damage_in_the_third_of_four_sessions_stays_flagged():
    # one whisker's ζ × 1.5 and another's f1 × 0.97 from the third weekly session on
    rows = _fleet(3, damage={2: (2, 1.0, 1.5), 5: (2, 0.97, 1.0)})
    result = check_fleet(rows)
    flagged = {(f["whisker"], f["session"], f["parameter"]) for f in result.flags}
    assert flagged == {(w, s, p) for w, p in (("w2", "zeta"), ("w5", "f1_hz"))
                       for s in ("2026-11-17", "2026-11-24")}  # fmt: skip
    events = {(e["whisker"], e["parameter"]): e for e in result.events}
    assert set(events) == {("w2", "zeta"), ("w5", "f1_hz")}
    f1 = events[("w5", "f1_hz")]
    assert f1["began"] == "2026-11-17" and f1["rule"] == "step"
    # its size against its 1σ: the truth is -3 % of the whisker's f1 (±0.2 % day to day)
    assert abs(f1["size_pct"] + 3.0) < 4 * 100 * f1["size_sigma"] / f1["before"]
    assert f1["size_sigma"] > 0
    # a two-session reference: the note says what can be flagged
    assert any("reference of 2 session" in n for n in result.notes)


@pytest.mark.parametrize("first", [2, 3, 4, 5, 6, 7])
def test_a_step_is_found_where_it_began_at_every_position(first):
    rows = _fleet(first, sessions=8, damage={1: (first, 0.97, 1.0), 4: (first, 1.0, 1.6)})
    result = check_fleet(rows)
    began = {(e["whisker"], e["parameter"]): e["began"] for e in result.events}
    session = f"2026-11-{3 + 7 * first:02d}"  # (names that sort, if not dates)
    assert began == {("w1", "f1_hz"): session, ("w4", "zeta"): session}
    for f in result.flags:  # every session from the change on, none before
        assert f["session"] >= session and f["began"] == session


def test_a_slow_drift_is_found_by_the_cusum():
    # f1 falls 0.3 % a session from the fourth on: no single session is 4σ from the last
    rows = _fleet(11, whiskers=6, sessions=10, damage={3: (3, lambda n: 1 - 0.003 * n, 1.0)})
    result = check_fleet(rows)
    (event,) = result.events
    assert (event["whisker"], event["parameter"]) == ("w3", "f1_hz")
    assert event["size_pct"] < -1.0
    sessions = sorted({r["session"] for r in rows})
    assert sessions.index(event["began"]) in (3, 4, 5) and event["rule"] == "drift"


def test_healthy_fleets_give_few_false_alarms():
    flagged = checked = 0
    for seed in range(20):
        result = check_fleet(_fleet(100 + seed, whiskers=10, sessions=8))
        flagged += len({(c["whisker"], c["session"]) for c in result.flags})
        checked += len({(c["whisker"], c["session"]) for c in result.changes})
    assert checked == 20 * 10 * 6
    assert flagged <= 0.01 * checked, flagged


def test_a_baseline_of_one_session_uses_the_fleet_and_the_repeats():
    rows = _fleet(5, sessions=3, damage={0: (1, 0.96, 1.0)})
    result = check_fleet(rows, baseline=1)
    assert {(e["whisker"], e["began"]) for e in result.events} == {("w0", "2026-11-10")}


def test_a_nan_value_or_a_torn_row_is_flagged_and_no_whisker_is_dropped(tmp_path):
    rows = _fleet(7, whiskers=3, sessions=5)
    rows[3]["f1_hz"] = "nan"  # w0's fourth session: a NaN f1 with status ok
    table = tmp_path / "fleet.csv"
    write_table(table, rows)
    lines = table.read_text().splitlines()
    lines[7] = lines[7][: len(lines[7]) // 3]  # w1's second session torn mid-row
    lines.append("w2,2026-12-08")  # a row cut after its session
    table.write_text("\n".join(lines) + "\n")
    result = check_fleet(read_table(table))
    assert set(result.histories) == {"w0", "w1", "w2"}
    fits = {(f["whisker"], f["session"]): f["status"] for f in result.flags
            if f["parameter"] == "fit"}  # fmt: skip
    assert fits[("w0", "2026-11-24")].startswith("bad value: f1_hz")
    assert fits[("w2", "2026-12-08")].startswith("torn row")
    assert not [f for f in result.flags if f["parameter"] != "fit"]
    assert any("w0" in n and "not numbers" in n for n in result.notes)
    # the torn row in w1's reference is left out of it, and said so
    assert any("w1" in n and "torn row" in n for n in result.notes)


def _damped_pluck(rng, f1, zeta, *, rate_hz=860.0, duration_s=0.74):
    """A held-then-released pluck in volts, written with numpy alone: a first mode (and a
    second, 6.27 times higher, with 3 % of the amplitude) released from rest at 0.15-0.3 s
    after a hold, the sensor's offset, white noise at 35 dB SNR."""
    t = np.arange(round(duration_s * rate_hz)) / rate_hz
    release = rng.uniform(0.15, 0.3)
    amp = rng.uniform(0.15, 0.3)  # V
    y = np.full(t.size, amp)
    after = t >= release
    tau = t[after] - release
    y[after] = 0.0
    for f, z, a in ((f1, zeta, 1.0), (6.27 * f1, zeta, 0.03)):
        w, wd = 2 * np.pi * f, 2 * np.pi * f * math.sqrt(1 - z * z)
        decay = np.exp(-z * w * tau) * (np.cos(wd * tau) + z / math.sqrt(1 - z * z)
                                        * np.sin(wd * tau))  # fmt: skip
        y[after] += a / 1.03 * amp * decay
    rms = amp / math.sqrt(2) * math.sqrt(0.5 / (2 * math.pi * f1 * zeta) / duration_s)
    return t, 1.65 + y + rng.normal(0, rms * 10 ** (-35 / 20), t.size)


@pytest.mark.slow
def test_the_issue_fleet_end_to_end_from_plucks_written_with_numpy(tmp_path):
    """8 whiskers, 4 weekly sessions of 3 held-then-released plucks in volts at 860 Hz;
    whisker 2's ζ × 1.5 and whisker 5's f1 × 0.97 from the third session on."""
    from whiskerid.fleet import calibrate_fleet
    from whiskerid.model import paper_record

    rng = np.random.default_rng(30)
    root = tmp_path / "root"
    for w in range(8):
        folder = root / f"whisker-{w}"
        paper_record().save(folder / "whisker.toml")
        f1_w, zeta_w = rng.uniform(43, 49), 0.04 * math.exp(rng.normal(0, 0.2))
        for s in range(4):
            f1 = f1_w * (1 + 0.002 * rng.normal()) * (0.97 if w == 5 and s >= 2 else 1.0)
            zeta = zeta_w * math.exp(0.05 * rng.normal()) * (1.5 if w == 2 and s >= 2 else 1.0)
            for k in range(3):
                t, v = _damped_pluck(rng, f1, zeta)
                path = folder / f"2026-11-{3 + 7 * s:02d}" / f"pluck-{k + 1}.csv"
                path.parent.mkdir(parents=True, exist_ok=True)
                np.savetxt(path, np.column_stack([t, v]), delimiter=",", header="t,voltage",
                           comments="", fmt="%.9g")  # fmt: skip
    run = calibrate_fleet(root, tmp_path / "out")
    assert all(r["status"] in ("ok", "check") for r in run.rows), run.rows
    result = check_fleet(run.rows)
    flagged = {(f["whisker"], f["session"], f["parameter"]) for f in result.flags}
    assert flagged == {(w, s, p) for w, p in (("whisker-2", "zeta"), ("whisker-5", "f1_hz"))
                       for s in ("2026-11-17", "2026-11-24")}  # fmt: skip
    assert {e["began"] for e in result.events} == {"2026-11-17"}
