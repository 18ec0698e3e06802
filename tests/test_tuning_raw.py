"""mixnav tune on raw-GNSS datasets (issue 35): the starts, the criterion of the written file,
never reading the reference, what a static receiver's likelihood prefers, --fix, bad input."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
import tomlkit

from mixnav.errors import ArgumentError
from mixnav.experiment.tuning import tune
from mixnav.experiment.tuning.criterion import without_reference
from mixnav.experiment.tuning.raw_gnss import MIN_SCORED, SETTLE, STARTS_EVERY, RawEvaluator, starts_for

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "src" / "mixnav" / "config" / "datasets"
DATA = ROOT.parent / "shared" / "data" / "android-static"
need_data = pytest.mark.skipif(not DATA.is_dir(), reason="needs ../shared/data/android-static")


def _untuned(tmp_path, name="phone.toml", edit=None) -> Path:
    """android-static-filters without its motion noise (the schema's car defaults), the data
    folder absolute; ``edit(doc)`` changes it further."""
    doc = tomlkit.parse((SHIPPED / "android-static-filters.toml").read_text())
    for k in ("accel_sigma", "vertical_accel_sigma", "clock_q_bias", "clock_q_drift"):
        doc["motion"].pop(k)
    doc["dataset"]["data_dir"] = str(DATA)
    if edit is not None:
        edit(doc)
    path = tmp_path / name
    path.write_text(tomlkit.dumps(doc))
    return path


def test_starts_leave_the_scored_span():
    """0, every STARTS_EVERY s, each with SETTLE + MIN_SCORED s after it (223 s: 0 ... 120 s)."""
    assert starts_for(223.0) == [0.0, 30.0, 60.0, 90.0, 120.0]
    assert starts_for(SETTLE + MIN_SCORED) == [0.0]
    assert starts_for(SETTLE + MIN_SCORED - 1.0) == []
    assert all(b - a == STARTS_EVERY for a, b in zip(starts_for(1e4), starts_for(1e4)[1:]))
    assert len(starts_for(1e4)) == 6


@need_data
def test_the_tuned_file_is_the_one_scored_and_a_static_receiver_wants_little_acceleration(tmp_path):
    """The written tuned.toml, scored afresh, gives the criterion the search reported (the
    values written with their units and comments are the ones evaluated), no worse than the
    file as given, on the same rows; and the phone held still prefers a white acceleration
    well below the schema's car default of 1 m/s^2/sqrt(Hz) (the likelihood of a static
    receiver's pseudoranges rises as the model stops letting it wander)."""
    res = tune(_untuned(tmp_path), tmp_path / "out", budget=10, workers=1, method="ekf")
    text = (tmp_path / "out" / "tuned.toml").read_text()
    tuned = tomllib.loads(text)
    ev = RawEvaluator(without_reference(text), str(tmp_path / "out" / "tuned.toml"), None, "ekf",
                      starts_for(223.0), SETTLE)
    again = ev.evaluate(without_reference(text)).as_dict()
    assert again["criterion"] == pytest.approx(res.tuned["criterion"], rel=1e-12)
    assert res.tuned["criterion"] <= res.given["criterion"]
    assert again["rows_scored"] == res.given["rows_scored"] > 1000
    accel = float(tuned["motion"]["accel_sigma"].split()[0])
    assert accel <= 0.1
    assert "mixnav tune: innovation log-likelihood over 5 starts" in text


@need_data
def test_tune_never_reads_the_reference(tmp_path):
    """A wrong surveyed point changes nothing but itself in tuned.toml."""
    def far(doc):
        doc["reference_point"]["latitude"] = "10 deg"
    a = tune(_untuned(tmp_path, "a.toml"), tmp_path / "a", budget=4, workers=1, method="ekf")
    b = tune(_untuned(tmp_path, "b.toml", far), tmp_path / "b", budget=4, workers=1, method="ekf")
    assert a.tuned_text != b.tuned_text
    assert without_reference(a.tuned_text) == without_reference(b.tuned_text)


@need_data
def test_a_fixed_key_keeps_its_value_and_the_epoch_mixtures_start_is_searched(tmp_path):
    res = tune(_untuned(tmp_path), tmp_path / "out", budget=6, workers=1, fix=["motion.accel_sigma"])
    assert res.not_tuned["motion.accel_sigma"] == "fixed by the user (--fix)"
    tuned = tomllib.loads(res.tuned_text)
    assert "accel_sigma" not in tuned["motion"]                  # still the schema default
    assert "motion.vertical_accel_sigma" in res.chosen
    names = [p["changed"] for p in res.evaluations]
    assert any(n.startswith("motion.vertical_accel_sigma") for n in names)
    # the tuned method is the epoch mixture: the file's other filters are said to be untuned
    assert res.not_tuned["the other filters"].startswith("ekf, robust, mixture, vb-akf: scored by no criterion")


@need_data
@pytest.mark.parametrize("kwargs, argument, says", [
    ({"fix": ["imu.errors.arw"]}, "fix", "tunable: motion.accel_sigma"),
    ({"method": "spp"}, "method", "epoch-by-epoch solution"),
    ({"method": "nothere"}, "method", "no method 'nothere'"),
    ({"criterion": "withheld-satellites"}, "criterion", "raw-GNSS one by the innovation likelihood only"),
    ({"budget": 0}, "budget", ">= 1"),
])
def test_bad_input_names_the_argument(tmp_path, kwargs, argument, says):
    with pytest.raises(ArgumentError) as e:
        tune(_untuned(tmp_path), tmp_path / "out", workers=1, **{"budget": 4, **kwargs})
    assert e.value.argument == argument
    assert says in str(e.value)


@need_data
def test_the_cached_spp_stage_scores_as_the_whole_pipeline(tmp_path):
    """The evaluator computes the SPP stage (the SPP, the filters' corrected pseudoranges) once
    and runs the filter alone per candidate: every candidate's score equals, bitwise, the one of
    the whole pipeline run afresh for it (``cached=False``), a candidate of other motion noise
    and mixture start as the file as given; one changing ``[raw_gnss]`` (the pseudorange sigmas:
    other corrected rows' variances) gets a stage of its own, and its score differs."""
    from mixnav.experiment.tuning.criterion import without_reference
    from mixnav.experiment.tuning.raw_gnss import stage_key
    text = without_reference(_untuned(tmp_path).read_text())
    doc = tomlkit.parse(text)
    doc["motion"]["accel_sigma"] = "0.05 m/s^2/sqrt(Hz)"
    doc["methods"][[m["name"] for m in doc["methods"]].index("epoch-mixture")]["options"] = {"los_weight": 0.7}
    other = tomlkit.dumps(doc)
    doc["raw_gnss"]["sigma_a"] = "6 m"
    sigmas = tomlkit.dumps(doc)
    args = (str(tmp_path / "phone.toml"), None, "epoch-mixture", [0.0, 30.0], SETTLE)
    cached, whole = RawEvaluator(text, *args), RawEvaluator(text, *args, cached=False)
    scores = [cached.evaluate(t).as_dict() for t in (text, other, sigmas)]
    assert scores == [whole.evaluate(t).as_dict() for t in (text, other, sigmas)]
    assert len({s["criterion"] for s in scores}) == 3 and all(s["error"] is None for s in scores)
    keys = {stage_key(cached.dataset(t)) for t in (text, other, sigmas)}
    assert len(keys) == 2 and len(cached._stages) == 2
