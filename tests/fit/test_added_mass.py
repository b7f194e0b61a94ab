"""The added-mass method: EI and C from plucks with and without a known tip mass, checked on
plucks of an independent finite-element beam; the modulus tolerance of ``--pin material``;
the mass written on the command line and in a recording."""

import json

import numpy as np
import pytest
import scipy.linalg
from helpers import FEMBeam

from whiskerid.cli import main
from whiskerid.fit import AddedMass, CalibrationError, Observation, calibrate
from whiskerid.io import mass_from_meta, parse_mass
from whiskerid.model import paper_record

REC = paper_record()
W = REC.whisker()
EI, RHO_A, L = float(W.EI), float(W.rho_a), float(W.length_m)
C_TRUE = REC.structure.coil_factor
BEAM_KG = RHO_A * L


def fe_pluck(tip_kg, *, zeta, seed, rate=200.0, duration=1.5, snr_db=40.0, n_fe_modes=6):
    """A pluck (release from a static tip deflection) of a Hermite finite-element cantilever
    with a tip mass, modal damping, read at the paper's sensor (5 mm), white noise."""
    b = FEMBeam(length=L, EI=EI, rho_a=RHO_A, zeta=zeta, tip_mass=tip_kg, n_el=24)
    w2, phi = scipy.linalg.eigh(b.K, b.M, subset_by_index=[0, n_fe_modes - 1])
    om = np.sqrt(w2)
    q0 = phi.T @ b.M @ b.static_tip_shape(2e-3)
    rng = np.random.default_rng(seed)
    t = (np.arange(int(duration * rate)) + rng.uniform()) / rate
    wd = om * np.sqrt(1 - zeta**2)
    tt = t[:, None]
    q = (
        q0
        * np.exp(-zeta * om * tt)
        * (np.cos(wd * tt) + zeta / np.sqrt(1 - zeta**2) * np.sin(wd * tt))
    )
    y = q @ (b.interpolation(0.005) @ phi)
    y = y + rng.standard_normal(t.size) * np.std(y) * 10 ** (-snr_db / 20)
    return Observation(t, y, excitation="decay", observable="deflection", gain=1.0,
                       name=f"tip{tip_kg:.3g}-{seed}")  # fmt: skip


def _pair(mass_kg, seed):
    return [fe_pluck(0.0, zeta=0.02, seed=seed), fe_pluck(mass_kg, zeta=0.017, seed=seed + 1)]


@pytest.fixture(scope="module")
def pair():
    return _pair(0.25 * BEAM_KG, seed=11)


@pytest.fixture(scope="module")
def fitted(pair):
    masses = [None, AddedMass(0.25 * BEAM_KG, 0.002 * BEAM_KG)]
    return calibrate(REC, pair, added_mass=masses)


@pytest.mark.slow
def test_added_mass_recovers_c_and_ei_within_their_1_sigma(fitted):
    p = fitted.params
    assert fitted.status == "ok", fitted.warnings
    for name, truth in (("C", C_TRUE), ("EI", EI), ("rho_a", RHO_A)):
        pull = (p[name]["value"] - truth) / p[name]["std"]
        assert abs(pull) <= 3, (name, p[name], truth)
        assert p[name]["source"] == "fit (added mass)"
    # a real measurement: a few percent, not the geometry's value copied through
    assert 1e-3 < p["C"]["std"] / p["C"]["value"] < 0.05
    assert p["zeta"]["value"] == pytest.approx(0.02, rel=0.05)
    assert p["zeta_mass1"]["value"] == pytest.approx(0.017, rel=0.05)
    assert p["mu_mass1"]["value"] == pytest.approx(0.25, rel=0.05)
    # the record written reproduces the fit's whisker
    w = fitted.record.whisker()
    assert float(w.EI) == pytest.approx(p["EI"]["value"], rel=1e-9)
    assert float(w.rho_a) == pytest.approx(p["rho_a"]["value"], rel=1e-9)
    assert fitted.record.extra["fit"]["pin"] == "added mass"


@pytest.mark.slow
def test_the_masses_uncertainty_enters_the_1_sigma(pair, fitted):
    loose = calibrate(REC, pair, added_mass=[None, AddedMass(0.25 * BEAM_KG, 0.05 * BEAM_KG)])
    tight, wide = fitted.params["C"], loose.params["C"]
    assert wide["std"] > 3 * tight["std"]
    # a mass known to 20 % cannot give C to better than 20 %
    assert wide["std"] / wide["value"] >= 0.19


@pytest.mark.slow
def test_a_mass_too_small_for_the_data_is_flagged():
    # 1e-5 of the whisker's mass shifts f1 by about 2e-5 relative: at this noise the shift
    # is measured to about its own size, so C is not separated from EI
    obs = _pair(1e-5 * BEAM_KG, seed=21)
    cal = calibrate(REC, obs, added_mass=[None, AddedMass(1e-5 * BEAM_KG, 0.0)])
    assert cal.status == "check"
    assert "added-mass-small" in cal.checks
    assert "too small" in cal.checks["added-mass-small"]
    assert cal.params["C"]["std"] / cal.params["C"]["value"] > 0.1


def test_one_configuration_and_a_static_test_are_refused(pair):
    with pytest.raises(CalibrationError, match="two different tip masses"):
        calibrate(REC, pair, added_mass=[AddedMass(1e-4), AddedMass(1e-4)])
    with pytest.raises(CalibrationError, match="one each"):
        calibrate(REC, pair, added_mass=[None])


@pytest.mark.parametrize(
    ("text", "kg", "std"),
    [("0.52g±0.01g", 5.2e-4, 1e-5), ("520mg+-10mg", 5.2e-4, 1e-5), ("0.52g", 5.2e-4, 5e-6),
     ("5.2e-4kg", 5.2e-4, 5e-6), ("0.52 g +/- 0.02", 5.2e-4, 2e-5)],
)  # fmt: skip
def test_parse_mass(text, kg, std):
    assert parse_mass(text) == pytest.approx((kg, std))


@pytest.mark.parametrize("text", ["", "g", "-1g", "0g", "1g±0.6g", "1 stone"])
def test_parse_mass_refuses_what_is_not_a_mass(text):
    with pytest.raises(ValueError, match="mass"):
        parse_mass(text)


def test_mass_from_metadata():
    assert mass_from_meta({}) is None
    assert mass_from_meta({"added_mass_kg": "0"}) is None
    assert mass_from_meta({"added_mass_kg": "0.00052"}) == pytest.approx((5.2e-4, 5e-6))
    got = mass_from_meta({"added_mass_kg": "0.00052", "added_mass_std_kg": "1e-5"})
    assert got == pytest.approx((5.2e-4, 1e-5))


@pytest.mark.slow
def test_pin_material_carries_the_modulus_tolerance(pair):
    exact = calibrate(REC, pair[:1], pin="material", modulus_tolerance=0.0)
    loose = calibrate(REC, pair[:1], pin="material")
    rel0 = exact.params["C"]["std"] / exact.params["C"]["value"]
    rel = loose.params["C"]["std"] / loose.params["C"]["value"]
    assert rel0 < 1e-3
    assert rel == pytest.approx(np.hypot(rel0, 0.2), rel=1e-6)
    assert loose.fixed["modulus_tolerance"] == 0.2
    assert "rests on the assumed modulus" in loose.note
    with pytest.raises(CalibrationError, match="modulus tolerance"):
        calibrate(REC, pair[:1], pin="material", modulus_tolerance=1.5)


def _csv(path, obs, meta=""):
    rows = "\n".join(f"{float(a)!r},{float(b)!r}" for a, b in zip(obs.t, obs.y, strict=True))
    path.write_text(f"{meta}# excitation: decay\n# units: m\nt,deflection\n{rows}\n")
    return path


def _cli_base(tmp_path, pair, request, monkeypatch):
    monkeypatch.chdir(request.config.rootpath)
    plain, loaded = _csv(tmp_path / "plain.csv", pair[0]), _csv(tmp_path / "loaded.csv", pair[1])
    base = ["calibrate", str(plain), str(loaded), "--whisker", "fits/paper-whisker.toml",
            "--t-start", "0"]  # fmt: skip
    return base, loaded


def test_cli_added_mass_refusals(tmp_path, pair, capsys, monkeypatch, request):
    base, loaded = _cli_base(tmp_path, pair, request, monkeypatch)
    for extra, why in (
        (["--added-mass", "other.csv=0.5g"], "not one of the recordings"),
        (["--added-mass", f"{loaded}=heavy"], "not a mass"),
        (["--added-mass", f"{loaded}"], "write FILE=MASS"),
        (["--added-mass", f"{loaded}=0.5g", "--pin", "material"], "leave --pin out"),
        (["--modulus-tolerance", "-1"], "--modulus-tolerance"),
    ):
        assert main([*base, "--out", str(tmp_path / "x.toml"), *extra]) == 2
        assert why in capsys.readouterr().err


@pytest.mark.slow
def test_cli_added_mass_fit(tmp_path, pair, capsys, monkeypatch, request):
    base, loaded = _cli_base(tmp_path, pair, request, monkeypatch)
    mass = f"{loaded.name}={0.25 * BEAM_KG * 1e3:.6f}g±{0.002 * BEAM_KG * 1e3:.4f}g"
    out = tmp_path / "cal.toml"
    assert main([*base, "--out", str(out), "--added-mass", mass, "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["sources"]["C"] == "fit (added mass)"
    assert abs(js["params"]["C"]["value"] - C_TRUE) <= 3 * js["params"]["C"]["std"]


def test_record_writes_the_added_mass_into_the_recording(tmp_path, capsys):
    from whiskerid.io import Recording, read_recording, write_csv

    t = np.arange(0, 2.0, 1e-4)
    src = write_csv(tmp_path / "src.csv", Recording(t=t, columns={"A0": 1.6 + 0 * t},
                                                   meta={"units": "V"}))  # fmt: skip
    out = tmp_path / "loaded.csv"
    argv = ["record", str(out), "--emulate", str(src), "--fast", "--duration", "0.5",
            "--added-mass", "520mg±10mg"]  # fmt: skip
    assert main(argv) == 0
    assert mass_from_meta(read_recording(out).meta) == pytest.approx((5.2e-4, 1e-5))
    bad = ["record", str(tmp_path / "b.csv"), *argv[2:-1], "lots"]
    assert main(bad) == 2
    assert "--added-mass" in capsys.readouterr().err


@pytest.mark.slow
def test_the_posterior_samples_the_added_mass_model(pair):
    from whiskerid.posterior import sample_posterior

    masses = [None, AddedMass(0.25 * BEAM_KG, 0.002 * BEAM_KG)]
    cal = calibrate(REC, pair, added_mass=masses)
    post = sample_posterior(REC, pair, walkers=24, steps=1500, seed=1, added_mass=masses,
                            n_modes=2)  # fmt: skip
    for name in ("C", "EI", "zeta_mass1"):
        q, c = post.params[name], cal.params[name]
        half = 0.5 * (q["q84"] - q["q16"])
        assert abs(q["median"] - c["value"]) < 0.5 * c["std"], name
        assert 0.7 < half / c["std"] < 1.4, (name, half, c["std"])
    c = post.params["C"]
    assert c["q2.5"] < C_TRUE < c["q97.5"]


@pytest.mark.slow
def test_two_masses_fit_jointly_and_improve_on_one(pair, fitted):
    heavy = fe_pluck(0.5 * BEAM_KG, zeta=0.015, seed=31)
    masses = [
        None,
        AddedMass(0.25 * BEAM_KG, 0.002 * BEAM_KG),
        AddedMass(0.5 * BEAM_KG, 0.004 * BEAM_KG),
    ]
    cal = calibrate(REC, [*pair, heavy], added_mass=masses)
    p = cal.params
    assert cal.status == "ok", cal.warnings
    assert abs(p["C"]["value"] - C_TRUE) <= 3 * p["C"]["std"]
    assert p["C"]["std"] < 0.9 * fitted.params["C"]["std"]
    assert p["zeta_mass2"]["value"] == pytest.approx(0.015, rel=0.05)
    assert p["mu_mass2"]["value"] == pytest.approx(0.5, rel=0.05)
