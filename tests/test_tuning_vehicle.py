"""mixnav tune on odometry + pseudorange datasets (issue 35): the withheld-satellite criterion
against its closed form, the folds, the epoch mixture's per-update log densities, and the tool
on smartLoc: never reading the reference, --fix, bad input."""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from mixnav.errors import ArgumentError
from mixnav.experiment.tuning import tune
from mixnav.experiment.tuning.vehicle import (MAX_STARTS, MIN_SCORED, SCORE_AFTER, STARTS_EVERY, satellite_folds,
                                              starts_for, withheld_deviation)
from mixnav.geodesy.frames import lla_to_ecef
from mixnav.gnss.geometry import C_LIGHT, earth_rotation_correction
from mixnav.gnss.pseudoranges import PseudorangeEpochs

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "src" / "mixnav" / "config" / "datasets"
DATA = ROOT.parent / "shared" / "data" / "smartloc-berlin"
need_data = pytest.mark.skipif(not DATA.is_dir(), reason="needs ../shared/data/smartloc-berlin")


def _sky(n, rng):
    """``n`` satellites at GPS radius above a receiver at 52.5 N, 13.4 E."""
    pos = lla_to_ecef(np.array([np.radians(52.5), np.radians(13.4), 40.0]))
    up = pos / np.linalg.norm(pos)
    d = rng.normal(size=(n, 3))
    d += 1.5 * up * np.abs(d @ up)[:, None] / 1.0
    d /= np.linalg.norm(d, axis=1)[:, None]
    d[(d @ up) < 0.2] += up
    d /= np.linalg.norm(d, axis=1)[:, None]
    return pos, pos + 2.02e7 * d


def _range(sat, pos):
    rng = np.linalg.norm(sat - pos, axis=1)
    return np.linalg.norm(earth_rotation_correction(sat, rng / C_LIGHT) - pos, axis=1)


def test_withheld_deviation_is_zero_at_the_true_position_and_sees_a_position_error():
    """Exact pseudoranges plus a clock common to the epoch: at the true position every epoch's
    deviation is zero whatever the clock; moved by dp, it is the median of |u_j.dp - median|
    over the satellites (u_j the unit line of sight; the range's first-order change)."""
    rng = np.random.default_rng(1)
    pos, sat = _sky(7, rng)
    lla = np.array([np.radians(52.5), np.radians(13.4), 40.0])
    times = np.array([10.0, 11.0])
    t = np.repeat(times, 7)
    sats = np.vstack([sat, sat])
    rho = np.concatenate([_range(sat, pos) + 3000.0, _range(sat, pos) - 125.0])   # two clocks
    res = SimpleNamespace(time=times, nav=np.tile(np.r_[np.zeros(7), lla], (2, 1)))
    dev = withheld_deviation(res, (t, rho, sats), after=0.0)
    np.testing.assert_allclose(dev, 0.0, atol=1e-6)
    # the filter 4 m off to the east and 2 m down
    from mixnav.geodesy.frames import ned_to_lla
    dp_ned = np.array([0.0, 4.0, 2.0])
    moved = ned_to_lla(dp_ned[None], lla)[0]
    res.nav[:, 7:10] = moved
    dev = withheld_deviation(res, (t, rho, sats), after=0.0)
    p2 = lla_to_ecef(moved)
    u = (sat - pos) / np.linalg.norm(sat - pos, axis=1)[:, None]
    proj = -(u @ (p2 - pos))                          # the range change, with the sign of rho - range
    expect = np.median(np.abs(proj - np.median(proj)))
    np.testing.assert_allclose(dev, expect, atol=2e-3)
    assert expect > 0.5
    # epochs after `after` only, and epochs with fewer than three satellites not scored
    assert len(withheld_deviation(res, (t, rho, sats), after=10.5)) == 1
    assert len(withheld_deviation(res, (t[:2], rho[:2], sats[:2]), after=0.0)) == 0


def test_the_two_folds_partition_every_epochs_satellites():
    rng = np.random.default_rng(2)
    n = 40
    t = np.sort(rng.integers(0, 6, n)).astype(float)
    ep = PseudorangeEpochs.from_rows(t, rng.normal(2e7, 10, n), np.full(n, 25.0), rng.normal(size=(n, 3)) * 2e7,
                                     rng.integers(1, 33, n), rng.choice([1, 4], n), cn0=rng.uniform(20, 50, n))
    (u0, h0), (u1, h1) = satellite_folds(ep)
    # each fold uses what the other withholds: together every row, once
    assert len(u0.pseudorange) == len(h1[1]) and len(u1.pseudorange) == len(h0[1])
    assert len(u0.pseudorange) + len(u1.pseudorange) == n
    np.testing.assert_array_equal(np.sort(np.concatenate([u0.pseudorange, u1.pseudorange])), np.sort(ep.pseudorange))
    parity0 = (u0.sat_id + u0.system) % 2
    assert (parity0 == 1).all() and ((u1.sat_id + u1.system) % 2 == 0).all()
    np.testing.assert_array_equal(np.sort(np.concatenate([h0[0], h1[0]])), np.repeat(ep.time, np.diff(ep.start)))


@pytest.mark.parametrize("criterion", ["likelihood", "withheld-satellites"])
def test_starts_leave_the_scored_span(criterion):
    assert starts_for(SCORE_AFTER + MIN_SCORED - 1, criterion) == []
    assert starts_for(SCORE_AFTER + MIN_SCORED, criterion) == [0.0]
    s = starts_for(10_000.0, criterion)
    assert len(s) == MAX_STARTS[criterion] and np.allclose(np.diff(s), STARTS_EVERY[criterion])
    assert all(x + SCORE_AFTER + MIN_SCORED <= 283.0 for x in starts_for(283.0, criterion))


@need_data
def test_the_epoch_mixtures_update_log_densities_sum_to_its_total():
    """FilterResult.outputs carries each update's log predictive density: their sum is the
    estimator's running total (the criterion scores a span of them)."""
    import warnings
    from mixnav.config.loader import load_dataset
    from mixnav.experiment.data_folder import find_data_dir
    from mixnav.experiment.vehicle_process import read_vehicle, run_vehicle
    ds, src, _ = load_dataset("smartloc-berlin")
    ds = ds.model_copy(update={"methods": [m.model_copy(update={"smooth": False}) for m in ds.methods
                                           if m.name == "epoch-mixture"]})
    folder = find_data_dir(ds, None, src)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        vo = run_vehicle(ds, src, folder, read_vehicle(ds, src, folder))
    res = vo.results["epoch-mixture"]
    out = res.outputs
    assert len(out["innovation_log_density"]) == len(out["innovation_log_density_time"]) > 1000
    np.testing.assert_allclose(out["innovation_log_density"].sum(), res.timing["innovation_log_likelihood"],
                               rtol=1e-12)
    assert (np.diff(out["innovation_log_density_time"]) > 0).all()


def _copy(tmp: Path, with_reference: bool) -> Path:
    """smartloc-berlin's file and data in ``tmp``, the reference file present or not."""
    data = tmp / "data"
    data.mkdir()
    shutil.copy(DATA / "Berlin_Potsdamer_Platz_Input.txt", data)
    if with_reference:
        shutil.copy(DATA / "Berlin_Potsdamer_Platz_GT.txt", data)
    text = (SHIPPED / "smartloc-berlin.toml").read_text().replace('data_dir = "../shared/data/smartloc-berlin"',
                                                                  'data_dir = "data"')
    (tmp / "car.toml").write_text(text)
    return tmp / "car.toml"


FAST = dict(budget=2, workers=1)


@need_data
def test_tune_never_reads_the_reference(tmp_path):
    """The same tuned.toml, byte for byte, with the reference file removed; the reference
    section is kept as written and the run count is starts x 2 folds per evaluation."""
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a, b = _copy(tmp_path / "a", True), _copy(tmp_path / "b", False)
    ra = tune(str(a), tmp_path / "a" / "out", fix=["alignment.cn0_edges"], **FAST)
    rb = tune(str(b), tmp_path / "b" / "out", fix=["alignment.cn0_edges"], **FAST)
    ta = (tmp_path / "a" / "out" / "tuned.toml").read_bytes()
    assert ta == (tmp_path / "b" / "out" / "tuned.toml").read_bytes()
    assert ra.runs == rb.runs == 2 * len(starts_for(283.0))
    assert 'file = "Berlin_Potsdamer_Platz_GT.txt"' in ta.decode()
    assert "innovation log-likelihood per pseudorange row" in (tmp_path / "a" / "out" / "report.md").read_text()
    # the window was searched (the first key): its value carries the tool's comment, the fixed edges do not
    tuned = tomllib.loads(ta.decode())
    assert tuned["alignment"]["cn0_edges"] == [29, 32, 35, 38, 42, 45, 48]
    assert "mixnav tune:" in ta.decode().split("window =", 1)[1].splitlines()[0]
    assert ra.not_tuned["alignment.cn0_edges"] == "fixed by the user (--fix)"


@need_data
def test_an_unknown_key_names_the_vehicle_keys(tmp_path):
    with pytest.raises(ArgumentError) as e:
        tune("smartloc-berlin", tmp_path / "out", budget=2, fix=["imu.errors.arw"])
    assert e.value.argument == "fix" and "alignment.window" in str(e.value)


@need_data
def test_the_withheld_satellite_criterion_runs_two_folds_per_start(tmp_path):
    """Scored as the functions above say: one evaluation is starts x 2 folds runs, and its
    criterion is the mean of the per-start deviations weighted by their epochs (here: checked
    to lie between the smallest and largest per-start mean, all of them metres-sized)."""
    r = tune("smartloc-berlin", tmp_path / "out", budget=1, workers=1, criterion="withheld-satellites")
    n = len(starts_for(283.0, "withheld-satellites"))
    assert r.runs == n * 2
    per = r.given["per_start"]
    assert len(per) == n and min(per) <= r.given["criterion"] <= max(per) and 1.0 < r.given["criterion"] < 50.0
    assert r.given["criterion_se"] > 0
    assert "half the satellites withheld" in (tmp_path / "out" / "report.md").read_text()


@need_data
def test_the_criterion_is_refused_for_an_imu_dataset(tmp_path):
    with pytest.raises(ArgumentError) as e:
        tune("drive-0708", tmp_path / "out", budget=2, criterion="likelihood")
    assert e.value.argument == "criterion"


_OCTILES = [29.0, 32.0, 35.0, 38.0, 42.0, 45.0, 48.0]


def test_set_edges_reaches_an_epoch_mixture_that_names_no_bands_of_its_own():
    """The epoch mixture takes no band edges from the alignment's hand-over (only the weights
    learned on its own bands), so the edges must be written into its options even when the
    file gave it none: otherwise the scan scores the alignment's bands under a filter without
    any. A method that is not an epoch mixture and names none is left alone."""
    import tomlkit
    from mixnav.experiment.tuning.vehicle import get_edges, set_edges
    doc = tomlkit.parse('[alignment]\nmode = "track"\n\n[[methods]]\nname = "ekf"\nestimator = "ekf"\n\n'
                        '[[methods]]\nname = "em"\nestimator = "epoch-mixture"\n')
    set_edges(doc, _OCTILES, "em")
    back = tomllib.loads(tomlkit.dumps(doc))
    assert back["alignment"]["cn0_edges"] == _OCTILES == get_edges(doc)
    assert back["methods"][1]["options"]["cn0_edges"] == _OCTILES
    assert "options" not in back["methods"][0]
    set_edges(doc, [], "em")                # and back to no bands
    assert tomllib.loads(tomlkit.dumps(doc))["methods"][1]["options"]["cn0_edges"] == []


@need_data
def test_edges_set_by_the_tuner_score_as_the_shipped_file_that_names_them():
    """The untuned file (no bands anywhere) given the shipped octiles and heading sigma by
    set_edges is the shipped configuration written another way: the criterion must be the same
    number (it was not, 4.33 against 3.94, while the edges reached the alignment only)."""
    import tomlkit
    from mixnav.experiment.tuning.criterion import without_reference
    from mixnav.experiment.tuning.vehicle import VehicleEvaluator, set_edges
    untuned = ROOT / "benchmarks" / "configs" / "smartloc-berlin-untuned.toml"
    shipped = without_reference((SHIPPED / "smartloc-berlin.toml").read_text())
    doc = tomlkit.parse(without_reference(untuned.read_text()))
    set_edges(doc, _OCTILES, "epoch-mixture")
    doc["alignment"]["heading_sigma"] = "6 deg"
    ev = VehicleEvaluator(tomlkit.dumps(doc), str(untuned), None, "epoch-mixture", [0.0, 90.0], SCORE_AFTER)
    a = ev.evaluate(tomlkit.dumps(doc)).as_dict()
    ev_s = VehicleEvaluator(shipped, str(SHIPPED / "smartloc-berlin.toml"), None, "epoch-mixture", [0.0, 90.0],
                            SCORE_AFTER)
    b = ev_s.evaluate(shipped).as_dict()
    assert a["error"] is None and a["rows_scored"] == b["rows_scored"] > 0
    assert a["criterion"] == pytest.approx(b["criterion"], rel=1e-12)


@need_data
def test_the_search_revisits_the_window_once_the_bands_are_chosen(tmp_path, monkeypatch):
    """A made-up criterion read from what the filter is given (the window, and the band edges
    of the epoch mixture's own options): bands help (-1) at any window, and the best window is
    40 s without bands but 20 s with them, the octiles best among the edges. From the untuned
    file (20 s, no bands) the window's first visit goes to 40 s; the search must take the
    octiles, then bring the window back to 20 s (the fine grid alone would stop at 37.5 s)."""
    from mixnav.config.loader import load_dataset_text
    from mixnav.experiment.tuning import vehicle as V
    untuned = ROOT / "benchmarks" / "configs" / "smartloc-berlin-untuned.toml"
    seen = []

    def fake(self, doc_text):
        ds, _, _ = load_dataset_text(doc_text, self.source)
        m = next(m for m in ds.methods if m.name == self.method)
        edges = list(m.options.get("cn0_edges", []))
        w = float(ds.alignment.window)
        best_w = 20.0 if edges else 40.0
        crit = (w - best_w) ** 2 / 1000.0 + (0.01 * abs(len(edges) - 7) if edges else 1.0)
        seen.append((w, len(edges)))
        return V.VehicleScore(crit, None, -crit, [crit], 1, rows=1)

    monkeypatch.setattr(V.VehicleEvaluator, "evaluate", fake)
    r = tune(str(untuned), tmp_path / "out", budget=200, workers=1, progress=False)
    tuned = tomllib.loads((tmp_path / "out" / "tuned.toml").read_text())
    method = next(m for m in tuned["methods"] if m["name"] == "epoch-mixture")
    assert method["options"]["cn0_edges"] == tuned["alignment"]["cn0_edges"] == _OCTILES
    assert (40.0, 0) in seen                                  # the first visit went there
    assert r.chosen["alignment.window"]["value"].startswith("20 s")
    assert r.tuned["criterion"] == pytest.approx(0.0, abs=1e-12)
