"""Noise processes reach the simulated data from scenario and dataset files."""

import numpy as np
import pytest
from scipy.stats import kurtosis

from mixnav.config import load_dataset, load_scenario
from mixnav.errors import ConfigError
from mixnav.geodesy.frames import ned_displacement
from mixnav.measurements.loose import antenna_lla
from mixnav.sim.scenario import simulate, truth_and_ideal_imu

from .test_config import DEMO


def _scenario(tmp_path, old, new):
    text = DEMO.read_text()
    assert old in text
    p = tmp_path / "noisy.toml"
    p.write_text(text.replace(old, new, 1))
    return load_scenario(str(p))


def _fix_errors(run, lever):
    k = np.searchsorted(run.truth.time, run.fixes.time)
    ant = np.array([antenna_lla(np.concatenate([run.truth.q_nb[i], run.truth.v_n[i], run.truth.lla[i]]), lever)
                    for i in k])
    return ned_displacement(run.fixes.lla, ant)


def test_mixture_and_gross_errors_on_the_fixes(tmp_path):
    sc, src, _ = _scenario(tmp_path, 'outages = [["300 s", "360 s"]]', '''outages = []
position_noise = { type = "sum", parts = [
  { type = "mixture", weights = [0.1, 0.9], sigmas = ["0.3 m", "0.17320508 m"] },
  { type = "gross", size = "2.5 m", every = 20, sign = "+" } ] }''')
    run = simulate(sc, 0, src)
    e = _fix_errors(run, np.asarray(sc.gnss.lever_arm))
    gross = np.zeros(len(e), dtype=bool)
    gross[::20] = True
    # gross errors exactly every 20th fix, of +2.5 m (the mixture adds < 1.5 m)
    assert np.all(e[gross, 0] > 1.0) and np.all(np.abs(e[~gross, 0]) < 1.5)
    # mixture variance 0.1*0.09 + 0.9*0.03 = 0.036 m^2 (570 samples x 3 axes: 6 % sd)
    assert np.var(e[~gross]) == pytest.approx(0.036, rel=0.15)
    # heavy tails: excess kurtosis of this mixture is 3*(0.1*0.09^2+0.9*0.03^2)/0.036^2 - 3 = 1.5
    assert kurtosis(e[~gross].ravel()) > 0.5


def test_imu_white_noise_mixture_raises_the_variance(tmp_path):
    sc, src, _ = _scenario(tmp_path, 'grade = "mems"', '''grade = "mems"
errors = { gyro_bias = "0 deg/h", gyro_bias_instability = "0 deg/h", gyro_scale = "0 ppm" }
white_noise = { type = "mixture", weights = [0.1, 0.9], sigmas = [1.7320508, 1.0] }''')
    ideal = truth_and_ideal_imu(sc, src)
    run = simulate(sc, 1, src, ideal=ideal)
    noise = (run.imu.dtheta - ideal[1].dtheta) / np.sqrt(ideal[1].dt)[:, None] / run.imu_model.arw
    # unit-free mixture variance 0.1*3 + 0.9*1 = 1.2 (180 000 samples: 0.5 % sd)
    assert np.var(noise) == pytest.approx(1.2, rel=0.03)


def test_bad_noise_table_names_its_key(tmp_path):
    with pytest.raises(ConfigError, match="gnss.position_noise"):
        _scenario(tmp_path, 'outages = [["300 s", "360 s"]]',
                  'position_noise = { type = "mixture", weights = [0.5, 0.6], sigmas = ["1 m", "2 m"] }')


def test_recorded_fixes_can_be_corrupted(tmp_path):
    from .test_process import _write_kfgins
    from mixnav.experiment.process import process
    sc, src, _ = load_scenario("loose-demo")
    run = simulate(sc, 2, src)
    cfg = _write_kfgins(tmp_path, run, sc)
    text = cfg.read_text().replace('withhold = [["150 s", "180 s"], ["300 s", "360 s"]]',
                                   'corrupt_position = { type = "gross", size = "20 m", every = 50, sign = "+" }')
    cfg.write_text(text)
    ds, s, _ = load_dataset(str(cfg))
    from mixnav.io.imu_checks import DataWarning
    with pytest.warns(DataWarning, match="hole"):     # the simulated record's 60 s outage, reported
        po = process(ds, s)
    d = ned_displacement(po.all_fixes.lla, run.fixes.lla)
    hit = np.zeros(len(d), dtype=bool)
    hit[::50] = True
    # the KF-GINS file holds degrees to 1e-10 (1e-5 m): compare to 1e-4 m
    np.testing.assert_allclose(d[hit], 20.0, atol=1e-4)
    np.testing.assert_allclose(d[~hit], 0.0, atol=1e-4)


def test_noise_processes_reach_the_raw_observables(tmp_path):
    # P1-sim1's noise on the pseudoranges (mixture + 2.5 m every 20 epochs) and an AR(1)
    # on the Doppler: the residuals against the noiseless observables show them
    from mixnav.config.loader import resolve
    text, _ = resolve("tight-demo")
    old = 'range_rate_sigma = "0.1 m/s"'
    new = old + '''
pseudorange_noise = { type = "sum", parts = [
  { type = "mixture", weights = [0.1, 0.9], sigmas = ["0.3 m", "0.17320508 m"] },
  { type = "gross", size = "2.5 m", every = 20, sign = "+" } ] }
range_rate_noise = { type = "ar1", coefficient = 0.9, sigma = "0.05 m/s" }'''
    p = tmp_path / "noisy.toml"
    p.write_text(text.replace(old, new).replace("keep = 3 }", "keep = 0 }"))
    sc, src, _ = load_scenario(str(p))
    noisy = simulate(sc, 0, src).observations
    # the same run without noise: same seed and streams, Gaussian sigmas made negligible
    q = tmp_path / "quiet.toml"
    q.write_text(p.read_text().replace(new, 'range_rate_sigma = "1e-9 m/s"').replace(
        'pseudorange_sigma = "3 m"', 'pseudorange_sigma = "1e-9 m"'))
    qsc, qsrc, _ = load_scenario(str(q))
    quiet = simulate(qsc, 0, qsrc).observations
    assert np.array_equal(noisy.valid, quiet.valid) and np.array_equal(noisy.prn, quiet.prn)
    e_pr = (noisy.pseudorange - quiet.pseudorange)
    # the clock walk is drawn from the same stream before the noise: identical in both
    np.testing.assert_array_equal(noisy.clock, quiet.clock)
    rows = np.arange(len(noisy.time))
    gross = (rows % 20) == 0
    v = noisy.valid
    assert (e_pr[gross][v[gross]] > 1.0).all() and (np.abs(e_pr[~gross][v[~gross]]) < 1.5).all()
    # mixture variance 0.1 * 0.09 + 0.9 * 0.03 = 0.036 m^2 (+-10 %: ~4000 samples)
    assert np.var(e_pr[~gross][v[~gross]]) == pytest.approx(0.036, rel=0.1)
    # AR(1) along time in one satellite slot: lag-1 autocorrelation 0.9
    e_rr = noisy.range_rate - quiet.range_rate
    col = e_rr[:, 0]
    col = col[np.isfinite(col)]
    r1 = np.corrcoef(col[:-1], col[1:])[0, 1]
    assert r1 == pytest.approx(0.9, abs=0.05)


@pytest.mark.parametrize("hold,words", [
    ('"0 s"', "positive"), ('"-1 s"', "positive"), ('"1"', "unit"),
    ('"0.015 s"', "whole number of IMU intervals"), ('"601 s"', "longer than the run"),
])
def test_bad_white_noise_hold_names_its_key(tmp_path, hold, words):
    with pytest.raises(ConfigError) as exc:
        _scenario(tmp_path, 'grade = "mems"', f'grade = "mems"\nwhite_noise_hold = {hold}')
    msg = str(exc.value)
    assert "imu.white_noise_hold" in msg and "noisy.toml" in msg and words in msg, msg


def test_training_process_samples_follow_the_hold(tmp_path, monkeypatch):
    # with a hold the "process" training series is the process drawn at epochs one hold
    # interval apart (the simulation's reading), 6 channels interleaved; an AR(1) keeps its
    # coefficient per channel (6 x 1000 values: se 0.006 on the mean of the 6 fits, 0.03 is 5)
    import mixnav.noise.processes as proc
    from mixnav.noise.ar import fit_ar1
    from mixnav.sim.training import training_residuals
    ar = 'white_noise = { type = "ar1", coefficient = 0.8, innovation = { type = "mixture", ' \
         'weights = [0.1, 0.9], sigmas = [0.25, 1.0] } }'
    seen = []
    orig = proc.AR1.sample
    monkeypatch.setattr(proc.AR1, "sample",
                        lambda self, t, c, g: seen.append(np.asarray(t)) or orig(self, t, c, g))
    for hold, step in (('\nwhite_noise_hold = "1 s"', 1.0), ("", 0.01)):
        sc, src, _ = _scenario(tmp_path, 'grade = "mems"', f'grade = "mems"\n{ar}{hold}')
        x = training_residuals(sc, 5, [], 6000, True, src)["process"]
        np.testing.assert_allclose(np.diff(seen[-1]), step)
        assert fit_ar1(x.reshape(-1, 6)).psi.mean() == pytest.approx(0.8, abs=0.03)
