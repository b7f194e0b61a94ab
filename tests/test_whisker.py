"""Whisker description, derived values, and records (TOML) with their refusals."""

import math
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import PAPER_C, PAPER_EI, PAPER_FREQS_HZ, PAPER_RHO_A

import whiskerid as wi

FITS = Path(__file__).resolve().parents[1] / "fits"


def test_paper_coil_equivalent_beam_values():
    coil = wi.paper_coil()
    assert coil.EI == pytest.approx(PAPER_EI, rel=2e-4)
    assert coil.coil_factor == pytest.approx(PAPER_C, rel=2e-4)
    assert coil.rho_a == pytest.approx(PAPER_RHO_A, rel=2e-4)
    # Independent arithmetic from the paper's definitions.
    p = 0.06 / 13
    assert coil.coil_factor == pytest.approx(math.hypot(2 * math.pi * 0.0045, p) / p, rel=1e-12)


def test_paper_natural_frequencies_within_0p1_percent():
    f = np.asarray(wi.paper_whisker().natural_frequencies_hz)
    np.testing.assert_allclose(f, PAPER_FREQS_HZ, rtol=1e-3)


def test_uniform_beam_sections():
    rect = wi.UniformBeam(
        length_m=0.3, youngs_modulus_pa=70e9, density_kg_m3=2700, width_m=0.05, thickness_m=0.002
    )
    assert rect.EI == pytest.approx(70e9 * 0.05 * 0.002**3 / 12)
    assert rect.rho_a == pytest.approx(2700 * 1e-4)
    circ = wi.UniformBeam(
        length_m=0.1,
        youngs_modulus_pa=200e9,
        density_kg_m3=7800,
        section="circular",
        diameter_m=0.001,
    )
    assert circ.EI == pytest.approx(200e9 * math.pi * 1e-12 / 64)
    # Analytic f_1 of a uniform cantilever: 1.8751^2/(2 pi l^2) sqrt(EI/rho A).
    w = wi.whisker_from_structure(circ, sensor_x_m=0.01)
    f1 = 1.875104**2 / (2 * math.pi * 0.01) * math.sqrt(circ.EI / circ.rho_a)
    assert float(w.natural_frequencies_hz[0]) == pytest.approx(f1, rel=1e-6)


def test_whisker_is_a_pytree_that_jits_and_vmaps():
    w = wi.paper_whisker()
    f1 = jax.jit(lambda w: w.natural_frequencies_hz[0])(w)
    assert float(f1) == pytest.approx(PAPER_FREQS_HZ[0], rel=1e-3)
    stacked = jax.vmap(lambda s: eqx.tree_at(lambda w: w.EI, w, w.EI * s))(jnp.array([1.0, 4.0]))
    f = jax.vmap(lambda w: w.natural_frequencies_hz[0])(stacked)
    assert float(f[1] / f[0]) == pytest.approx(2.0, rel=1e-12)  # f ∝ sqrt(EI)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("length_m", -0.06, "length_m"),
        ("zeta", jnp.array([1.0]), "zeta"),
        ("sensor_x_m", 0.07, "sensor_x_m"),
        ("EI", 0.0, "EI"),
    ],
)
def test_whisker_refuses_non_physical_values(field, value, message):
    kwargs = {
        "length_m": 0.06,
        "EI": 1e-3,
        "rho_a": 0.04,
        "zeta": jnp.array([0.04]),
        "sensor_x_m": 0.005,
    }
    kwargs[field] = value
    with pytest.raises(ValueError, match=message):
        wi.Whisker(**kwargs)


def test_whisker_refuses_wrong_shapes():
    with pytest.raises(ValueError, match="zeta"):
        wi.Whisker(length_m=0.06, EI=1e-3, rho_a=0.04, zeta=jnp.ones((2, 2)) * 0.01)


def test_shipped_paper_record_matches_code():
    rec = wi.load_record(FITS / "paper-whisker.toml")
    assert rec == wi.paper_record()


def test_record_round_trip_keeps_unknown_tables(tmp_path):
    rec = wi.paper_record().replace(
        extra={"fit": {"status": "ok", "zeta": {"value": 0.03}}},
        zeta=(0.04, 0.03, 0.02),
        n_modes=3,
        tip_mass_kg=0.001,
    )
    path = rec.save(tmp_path / "sub" / "w.toml")
    back = wi.load_record(path)
    assert back == rec
    np.testing.assert_allclose(back.whisker().zeta, [0.04, 0.03, 0.02])


def _paper_toml(**edits) -> str:
    text = wi.paper_record().to_toml()
    for old, new in edits.items():
        assert old in text, old
        text = text.replace(old, new)
    return text


@pytest.mark.parametrize(
    ("old", "new", "named"),
    [
        ("length_m = 0.06", "length_m = -0.06", "length_m"),
        ("zeta = 0.04", "zeta = 1.0", "zeta"),
        ("position_m = 0.005", "position_m = 0.08", "position_m"),
        ("n_coils = 13\n", "", "n_coils"),
        ('kind = "coil"', 'kind = "rope"', "kind"),
        ("fsr_v = 4.096", "fsr_v = 5.0", "full-scale"),
        ("data_rate_sps = 475", "data_rate_sps = 200", "no 200 SPS"),
    ],
)
def test_bad_records_are_refused_naming_the_field(tmp_path, old, new, named):
    path = tmp_path / "bad.toml"
    path.write_text(_paper_toml(**{old: new}))
    with pytest.raises(wi.RecordError, match=named) as err:
        wi.load_record(path)
    assert str(path) in str(err.value)


def test_missing_and_garbled_files(tmp_path):
    with pytest.raises(wi.RecordError, match="no such"):
        wi.load_record(tmp_path / "absent.toml")
    (tmp_path / "x.toml").write_text("this is = = not toml")
    with pytest.raises(wi.RecordError, match="TOML"):
        wi.load_record(tmp_path / "x.toml")


@pytest.mark.parametrize("n_modes", [1, 2, 4])
@pytest.mark.parametrize(
    "record",
    [
        wi.paper_record(),
        wi.paper_record().replace(tip_mass_kg=0.002, zeta=(0.04, 0.03), n_modes=2),
        wi.load_record(FITS / "cantilever-aluminium-30cm.toml"),
    ],
    ids=["paper", "tip-mass-two-zetas", "cantilever"],
)
def test_the_calibration_reads_the_whisker_the_model_makes(record, n_modes):
    """The calibration's host copy of the record's whisker (its set-up, report and checks)
    holds what :meth:`WhiskerRecord.whisker` gives, to rounding."""
    from whiskerid.fit._linear._host_whisker import nominal_whisker

    host, w = nominal_whisker(record, n_modes), record.whisker().with_modes(n_modes)
    for name in ("length_m", "EI", "rho_a", "zeta", "tip_mass_kg", "sensor_x_m", "mu", "beta",
                 "natural_frequencies_hz"):  # fmt: skip
        np.testing.assert_allclose(getattr(host, name), getattr(w, name), rtol=1e-13,
                                   err_msg=name)  # fmt: skip
