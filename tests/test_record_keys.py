"""Whisker records: a misspelt key is an error naming the nearest known key (it would
otherwise leave its default in place silently), and a list of ζ never overrides n_modes."""

import pytest

from whiskerid.cli import main
from whiskerid.model import RecordError, load_record, paper_record


def _paper(tmp_path, old: str, new: str):
    text = paper_record().to_toml()
    assert old in text, old
    path = tmp_path / "w.toml"
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("tip_mass_kg =", "tip_mas_kg =", "did you mean 'tip_mass_kg'"),
        ("hall_offset_v =", "hall_ofset_v =", "sensor.hall_ofset_v is not a known key; did"),
        ("zeta =", "zeta_2 =", "damping.zeta_2 is not a known key; did you mean 'zeta'"),
        ("[sensor]", "[sensr]", "[sensr] is not a known table; did you mean [sensor]"),
        ("n_coils =", "n_coil =", "did you mean 'n_coils'"),
    ],
)  # fmt: skip
def test_a_misspelt_key_names_the_nearest_known_one(tmp_path, old, new, message):
    with pytest.raises(RecordError) as err:
        load_record(_paper(tmp_path, old, new))
    assert message in str(err.value)


def test_the_cli_refuses_a_misspelt_record_in_one_line(tmp_path, capsys):
    path = _paper(tmp_path, "tip_mass_kg =", "tip_mas_kg =")
    assert main(["simulate", "--whisker", str(path), "--out", str(tmp_path / "s.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert "did you mean 'tip_mass_kg'" in err and "Traceback" not in err


def test_a_list_of_zeta_must_agree_with_n_modes(tmp_path):
    path = _paper(tmp_path, "zeta = 0.04", "zeta = [0.04, 0.03]")
    with pytest.raises(RecordError, match=r"lists 2 modes but damping\.n_modes = 5"):
        load_record(path)
    text = path.read_text().replace("n_modes = 5", "n_modes = 2")
    path.write_text(text)
    rec = load_record(path)
    assert rec.n_modes == 2 and rec.zeta == (0.04, 0.03)


def test_tables_of_later_stages_are_kept(tmp_path):
    path = _paper(tmp_path, "[sensor]", "[posterior]\nsteps = 3\n\n[sensor]")
    assert load_record(path).extra["posterior"] == {"steps": 3}


def test_a_nan_in_a_record_is_refused_by_name(tmp_path):
    """f1 = NaN in a calibrated record's [fit] table was copied into every record made
    from it (posterior.toml)."""
    path = _paper(tmp_path, "[sensor]", "[fit.params.f1_hz]\nvalue = nan\nstd = nan\n\n[sensor]")
    with pytest.raises(RecordError, match=r"fit\.params\.f1_hz\.value = nan is not a number"):
        load_record(path)
    path.write_text(path.read_text().replace("value = nan", "value = 12.0"))
    assert load_record(path).extra["fit"]["params"]["f1_hz"]["value"] == 12.0


def test_a_posterior_too_short_for_tau_writes_no_nan(tmp_path):
    """posterior --steps 1: τ and ESS cannot be estimated; the record leaves them out and
    the JSON says null (it wrote tau = nan)."""
    import numpy as np

    from whiskerid.posterior._summary import Posterior, _updated_record

    q = {"median": 1.0, "tau": float("nan"), "ess": float("nan")}
    post = Posterior(params={"f1_hz": q}, diagnostics={"converged": False, "message": "m",
                     "max_tau": float("nan"), "tau": {"f1_hz": float("nan")},
                     "acceptance": 0.5}, correlations={"names": ["f1_hz"],
                     "matrix": [[float("nan")]]}, samples=np.zeros((2, 1)), names=["f1_hz"],
                     chain=np.zeros((1, 2, 1)))  # fmt: skip
    rec = _updated_record(paper_record(), post)
    text = rec.to_toml()
    assert "= nan" not in text and "nan]" not in text and "median = 1.0" in text
    assert post.to_json()["params"]["f1_hz"]["tau"] is None
