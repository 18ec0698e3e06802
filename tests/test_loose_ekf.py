"""The loose EKF on loose-demo: seeded consistency (NEES) and outage drift."""

import numpy as np
import pytest
from scipy.stats import chi2

from mixnav.config import load_scenario
from mixnav.experiment.run import run_scenario, solution_table
from mixnav.sim.scenario import truth_and_ideal_imu

N_RUNS = 20


@pytest.fixture(scope="module")
def demo_runs():
    sc, src, _ = load_scenario("loose-demo")
    ideal = truth_and_ideal_imu(sc, src)
    tables = []
    for seed in range(N_RUNS):
        run = run_scenario(sc, src, seed=seed, ideal=ideal)
        res = run.results["ekf"]
        assert sum(res.recoveries.values()) == 0
        tables.append(solution_table(res, run.sim.truth, run.sim.outages))
    return sc, tables


def test_nees_of_position_and_velocity_is_chi_square(demo_runs):
    sc, tables = demo_runs
    nees = np.array([t["nees_pv"].to_numpy() for t in tables])  # (runs, epochs)
    anees = nees.mean(0)
    dof = 6
    # Averaged over 20 runs, a consistent filter's NEES at each epoch is
    # chi2(20 * 6) / 20: its two-sided 95 % band is [4.6, 7.6].
    lo, hi = chi2.ppf([0.025, 0.975], N_RUNS * dof) / N_RUNS
    inside = np.mean((anees >= lo) & (anees <= hi))
    # Successive epochs are strongly correlated (the errors are smooth), so
    # the share inside the band scatters from run set to run set far more
    # than 5 %; 80 % still fails a filter whose variances are off by 30 %,
    # which would put the whole curve outside the band.
    assert inside >= 0.80, (inside, anees.mean())
    # And the mean over the drive is near the dof: 6 +- 15 % (same reason).
    assert abs(anees.mean() / dof - 1.0) < 0.15, anees.mean()


def test_outage_drift_is_bounded_by_the_filter(demo_runs):
    sc, tables = demo_runs
    (a, b), = [tuple(o) for o in sc.gnss.outages]
    herr = np.array([np.hypot(t["err_n_m"], t["err_e_m"])[(t["time_s"] > a) & (t["time_s"] <= b)].max()
                     for t in tables])
    hsig = np.array([np.hypot(t["sig_n_m"], t["sig_e_m"])[(t["time_s"] > a) & (t["time_s"] <= b)].max()
                     for t in tables])
    # A 60 s MEMS outage drifts metres to tens of metres; the 3-sigma bound
    # of the filter must contain the drift in nearly every run.
    assert 1.0 < np.median(herr) < 100.0
    assert np.mean(herr <= 3 * hsig) >= 0.9
    # and GNSS back brings the error down to the fix noise level
    after = np.array([np.hypot(t["err_n_m"], t["err_e_m"])[t["time_s"] > b + 20].max() for t in tables])
    assert np.median(after) < 5.0
