"""``fleet drive`` on inputs that are not a whisker's driving response: a disconnected or
railed sensor, noise, one recording given several times, a whisker far from its record, too
little driving, bad flags and bad files. Each must exit 2 with a message naming what is
wrong, or be logged with a status that is not ``ok``: a dead sensor never reads healthy."""

import json

import numpy as np
import pytest
from generators.driving import drive, save_csv

from whiskerid.cli import main
from whiskerid.fleet import identify_driving
from whiskerid.model import paper_record

RATE = 200.0
N = int(60 * RATE)


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "whisker.toml"
    paper_record().save(path)
    return path


def _f1():
    return float(paper_record().whisker().natural_frequencies_hz[0])


@pytest.fixture(scope="module")
def four_minutes():
    """A good 4-minute drive, made once (SciPy's simulation takes seconds): the tests of bad
    flags and files around it only read it."""
    return drive(np.random.default_rng(1), _f1(), 0.04, minutes=4)


def _run(tmp_path, signals, record, capsys, *extra):
    folder = tmp_path / "drive"
    folder.mkdir(exist_ok=True)
    paths = save_csv(folder, signals)
    code = main(["fleet", "drive", str(tmp_path / "fleet"), *map(str, paths), "--whisker-id",
                 "w1", "--session", "s1", "--whisker", str(record), "--json", "--quiet",
                 *extra])  # fmt: skip
    out = capsys.readouterr()
    return code, (json.loads(out.out) if code == 0 else None), out.err, paths


def _constant(rng, four_minutes):
    return [(f"c{k}", np.full(N, 123.0)) for k in range(8)]


def _rail(rng, four_minutes):
    return [(f"r{k}", np.full(N, 32767.0)) for k in range(8)]


def _rail_noisy(rng, four_minutes):
    return [(f"r{k}", np.minimum(32767, 32767 + np.round(3000 * rng.standard_normal(N))))
            for k in range(8)]  # fmt: skip


def _same(rng, four_minutes):
    (one,) = drive(rng, _f1(), 0.04, minutes=1)
    return [(f"s{k}", one[1]) for k in range(8)]


def _nan(rng, four_minutes):
    signals = [(name, y.copy()) for name, y in four_minutes]
    signals[2][1][100] = np.nan
    return signals


def _short(rng, four_minutes):
    return drive(rng, _f1(), 0.04, minutes=1, seconds=180)


@pytest.mark.parametrize(
    ("make", "needle"),
    [
        (_constant, "c0.csv: the signal is constant"),
        (_rail, "r0.csv: the signal is constant (32767)"),
        (_rail_noisy, "sit at its largest value 32767"),
        (_same, "s1.csv holds the same samples as"),
        (_nan, "minute-2.csv: 1 sample(s) are not finite"),
        (_short, "needs at least 4 blocks, 240 s of driving"),
    ],
)
def test_a_recording_that_is_no_driving_response_exits_2_naming_it(
    tmp_path, record, capsys, make, needle, four_minutes
):
    signals = make(np.random.default_rng(0), four_minutes)
    code, _, err, _ = _run(tmp_path, signals, record, capsys)
    assert code == 2 and needle in err and "Traceback" not in err
    assert not (tmp_path / "fleet" / "health.csv").exists()


@pytest.mark.parametrize("block", ["inf", "nan", "-5", "10", "1e9"])
def test_a_bad_block_exits_2_naming_the_flag(tmp_path, record, capsys, block, four_minutes):
    code, _, err, _ = _run(tmp_path, four_minutes, record, capsys, "--block", block)
    assert code == 2 and "--block" in err and "Traceback" not in err


def test_a_health_log_that_is_not_utf8_is_named(tmp_path, record, capsys, four_minutes):
    (tmp_path / "fleet").mkdir()
    (tmp_path / "fleet" / "health.csv").write_bytes(b"whisker,session\n\xe9t\xe9,x\n")
    code, _, err, _ = _run(tmp_path, four_minutes, record, capsys)
    assert code == 2 and "health.csv" in err and "UTF-8" in err


@pytest.mark.slow
def test_white_noise_is_logged_as_no_resonance(tmp_path, record, capsys):
    rng = np.random.default_rng(3)
    signals = [(f"w{k}", np.round(3000 * rng.standard_normal(N))) for k in range(8)]
    code, out, _, _ = _run(tmp_path, signals, record, capsys)
    assert code == 0 and out["status"] != "ok" and out["problem"]


@pytest.mark.slow
def test_a_whisker_far_from_its_record_is_not_read_at_the_bands_edge(tmp_path, record, capsys):
    """A 59.97 Hz whisker started from the 46 Hz record: its peak lies beyond 1.25 f1."""
    signals = drive(np.random.default_rng(4), 59.97, 0.04, minutes=8)
    code, out, _, _ = _run(tmp_path, signals, record, capsys)
    assert code == 0 and out["status"] != "ok"


@pytest.mark.slow
def test_identical_blocks_never_give_a_zero_sigma():
    (one,) = drive(np.random.default_rng(5), 46.0, 0.04, minutes=1)
    fit = identify_driving([(f"s{k}", one[1]) for k in range(6)], RATE, 46.0, 0.04)
    assert fit.status == "identical blocks"


@pytest.mark.slow
@pytest.mark.parametrize(("f1", "zeta"), [(25.0, 0.06), (46.0, 0.03), (70.0, 0.02)])
def test_a_real_resonance_still_reads_ok(f1, zeta):
    """The checks above leave a healthy drive alone (independent generator, 5 minutes)."""
    fit = identify_driving(drive(np.random.default_rng(6), f1, zeta, minutes=5), RATE,
                           1.02 * f1, 0.04)  # fmt: skip
    assert fit.status == "ok" and abs(fit.f1_hz / f1 - 1) < 0.01
