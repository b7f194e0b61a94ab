"""``whiskerid analyze`` and its sideband test on signals whose answer is known."""

import json

import numpy as np
import pytest

import whiskerid as wi
from whiskerid.classify import sideband_test, welch_dof, welch_power
from whiskerid.cli import main

FS = 200.0
SEG = 800  # 4 s segments: 0.25 Hz bins


def _spectra(x, window=2 * SEG):
    out = [welch_power(x[s : s + window], SEG) for s in range(0, x.size - window + 1, window)]
    return np.stack([p for p, _ in out]), welch_dof(out[0][1])


def _test(x, carrier_hz):
    powers, dof = _spectra(x)
    return sideband_test(powers, FS / SEG, carrier_hz, dof)


T = np.arange(0, 64, 1 / FS)


def _carrier(rng, am=0.0, f_c=30.0, delta=5.0, noise=0.5):
    x = (1 + am * np.cos(2 * np.pi * delta * T + 1.0)) * np.sin(2 * np.pi * f_c * T)
    return x + noise * rng.standard_normal(T.size)


def _ringing(rng, f1=46.0, zeta=0.04, taps=150):
    """A whisker struck at random times, ringing freely at f1: no drive, no modulation."""
    x = np.zeros(T.size)
    wd = 2 * np.pi * f1 * np.sqrt(1 - zeta**2)
    for t0 in rng.uniform(0, T[-1], taps):
        after = T >= t0
        s = T[after] - t0
        x[after] += rng.normal() * np.exp(-zeta * 2 * np.pi * f1 * s) * np.sin(wd * s)
    return x + 0.05 * rng.standard_normal(T.size)


def test_amplitude_modulated_carrier_has_symmetric_sidebands():
    res = _test(_carrier(np.random.default_rng(0), am=0.3), 30.0)
    assert res["present"] and res["p_value"] < 1e-6
    assert abs(res["delta_hz"] - 5.0) < 0.1 and res["asymmetry_hz"] < 0.25
    assert res["consistency"] == 1.0
    # AM with index m: each sideband m/2 of the carrier's amplitude, (m/2)² in power
    assert abs(res["level_db"] - 10 * np.log10(0.15**2)) < 2.0


def test_carrier_alone_and_unrelated_lines_have_no_sidebands():
    rng = np.random.default_rng(1)
    assert not _test(_carrier(rng), 30.0)["present"]
    x = _carrier(rng) + 0.3 * np.sin(2 * np.pi * 22 * T) + 0.3 * np.sin(2 * np.pi * 41 * T)
    assert not _test(x, 30.0)["present"]  # lines 8 and 11 Hz away: no symmetric pair


def test_harmonic_and_slow_undulation_are_no_sidebands():
    """A drivetrain's tone with its second harmonic, on a whisker that follows a slow
    undulation of the ground: at Δ ≈ f_c, ``2f_c`` and the undulation are symmetric about
    the carrier to within a bin (0.5 Hz here), a pair the test must not count (without its
    2 Hz lower limit on the lower side, it does: ``min_hz=0``)."""
    rng = np.random.default_rng(6)
    x = _carrier(rng, f_c=21.3) + 0.4 * np.sin(4 * np.pi * 21.3 * T)
    x = x + 3 * np.sin(2 * np.pi * 0.3 * T)
    out = [welch_power(x[s : s + 800], 400) for s in range(0, x.size - 799, 800)]
    powers, dof = np.stack([p for p, _ in out]), welch_dof(out[0][1])
    assert not sideband_test(powers, 0.5, 21.3, dof)["present"]
    assert sideband_test(powers, 0.5, 21.3, dof, min_hz=0.0)["present"]


def test_free_ringing_at_f1_has_no_sidebands():
    """Around a broad resonance both skirts rise above the floor: they are no peaks."""
    x = _ringing(np.random.default_rng(2))
    powers, _ = _spectra(x)
    dominant = np.argmax(powers.mean(axis=0)) * FS / SEG
    assert abs(dominant - 46.0) < 1.0
    assert not _test(x, dominant)["present"]


def test_false_alarm_rate_is_at_most_alpha():
    """Carrier in white noise, 120 draws: the test at α = 0.01 fires at most a few times
    (binomial: P(≥ 5 | 120, 0.01) ≈ 0.3 %)."""
    rng = np.random.default_rng(3)
    fired = sum(_test(_carrier(rng), 30.0)["present"] for _ in range(120))
    assert fired < 5


def _dataset(root, rng):
    """Two terrains at two speeds; ``mod`` modulates its line (the perturbation, given in
    the metadata), ``plain`` does not; two 16 s runs per group."""
    t = np.arange(0, 16, 1 / FS)
    for label, am in (("mod", 0.4), ("plain", 0.0)):
        for v in (0.1, 0.3):
            f_b = 48 * v / (np.pi * 0.07)
            for run in range(2):
                x = (1 + am * np.cos(2 * np.pi * 3.0 * t)) * np.sin(2 * np.pi * f_b * t)
                x = x + 0.3 * rng.standard_normal(t.size)
                meta = {"speed_mps": str(v), "perturbation_hz": f"{f_b:.4f}"}
                wi.write_csv(root / label / f"r{v}_{run}.csv",
                             wi.Recording(t=t, columns={"adc": x}, meta=meta))  # fmt: skip


@pytest.mark.parametrize("how", ["metadata", "per_rev"])
def test_cli_analyze_finds_the_modulated_terrain(tmp_path, capsys, how):
    root = tmp_path / "ds"
    _dataset(root, np.random.default_rng(4))
    args = ["analyze", str(root), "--json", "--segment", "2", "--plot", str(tmp_path / "a.png")]
    if how == "per_rev":  # the same f_b from the speed and the wheel
        for p in root.rglob("*.csv"):
            p.write_text("".join(ln for ln in p.read_text().splitlines(keepends=True)
                                 if "perturbation_hz" not in ln))  # fmt: skip
        args += ["--per-rev", "48"]
    assert main(args) == 0
    res = json.loads(capsys.readouterr().out)
    for v in ("0.1", "0.3"):
        mod, plain = res["groups"]["mod"][v], res["groups"]["plain"][v]
        assert mod["dominant_at_perturbation"] and plain["dominant_at_perturbation"]
        assert mod["sandwiched"] and abs(mod["sidebands"]["delta_hz"] - 3.0) < 0.3
        assert not plain["sandwiched"]
        for g in (mod, plain):  # the test used, the carrier's own p-value, the power
            sb = g["sidebands"]
            assert sb["test"] == wi.classify.TEST_NAME and sb["carrier_p_value"] < 1e-3
            assert {"present", "p_value", "delta_hz", "power"} <= set(sb)
        assert mod["sidebands"]["power"] > 0.9 and mod["sidebands"]["p_value"] < 1e-3
        want = "metadata" if how == "metadata" else "speed and wheel geometry"
        assert mod["perturbation_source"] == want
    assert res["claim"]["sandwiched"] == 0.5
    assert res["claim"]["verdict"].startswith("the claim does not hold")
    assert (tmp_path / "a.png").stat().st_size > 5000


def test_cli_analyze_refuses_bad_settings(tmp_path, capsys):
    root = tmp_path / "ds"
    _dataset(root, np.random.default_rng(5))
    assert main(["analyze", str(root), "--per-rev", "-3"]) == 2
    assert "--per-rev -3: give a number from 0.001 to 10000" in capsys.readouterr().err
