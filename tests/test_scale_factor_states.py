"""The 21-state layout estimates the gyro scale factor that turns excite."""

import numpy as np

from mixnav.config import load_scenario
from mixnav.experiment.run import run_scenario, solution_table

from .test_config import DEMO


def test_21_state_filter_learns_the_yaw_gyro_scale_factor(tmp_path):
    text = DEMO.read_text().replace(
        'grade = "mems"',
        'grade = "mems"\nerrors = { gyro_scale = "5000 ppm", accel_scale = "3000 ppm" }')
    text = text.replace('name = "ekf"\ntype = "loose-ekf"\nstates = 15',
                        'name = "ekf15"\ntype = "loose-ekf"\nstates = 15\n\n'
                        '[[methods]]\nname = "ekf21"\ntype = "loose-ekf"\nstates = 21')
    p = tmp_path / "scale.toml"
    p.write_text(text)
    sc, src, _ = load_scenario(str(p))
    est, sig, true, yaw15, yaw21 = [], [], [], [], []
    for seed in range(4):
        run = run_scenario(sc, src, seed=seed)
        r21 = run.results["ekf21"]
        est.append(r21.sensor[-1, 8])       # sg_z estimate
        sig.append(r21.sigma[-1, 17])       # its 1-sigma (layout: sg at 15..17)
        true.append(run.sim.imu_draw.gyro_scale[2])
        for name, acc in (("ekf15", yaw15), ("ekf21", yaw21)):
            t = solution_table(run.results[name], run.sim.truth, run.sim.outages)
            acc.append(np.sqrt(np.mean(t["err_yaw_deg"] ** 2)))
    est, sig, true = map(np.asarray, (est, sig, true))
    # The turns (+-180 deg) make the z-gyro scale observable: the estimate is
    # within 3 sigma of the drawn value, and sigma has shrunk well below the
    # prior 5000 ppm.
    assert np.all(np.abs(est - true) < 3 * sig), (est, true, sig)
    assert np.all(sig < 0.3 * 5e-3)
    # Modelling the scale factor does not make the heading worse (4 seeds).
    assert np.mean(yaw21) <= 1.05 * np.mean(yaw15)


def test_23_state_tight_filter_learns_the_yaw_gyro_scale_factor():
    """The 23-state layout (scale factors and the receiver clock) in tight
    coupling, on P2-s2 (0.2 % / 0.3 % scale factors): the z-gyro scale factor
    estimate is within 3 sigma of the drawn value and sigma is below half its
    prior; the clock states sit after the scale factors (layout indices)."""
    from mixnav.ins.error_model import get_layout
    lay = get_layout(23)
    assert (lay.sg, lay.sa, lay.clk) == (15, 18, 21) and lay.labels()[21:] == ["clock_bias", "clock_drift"]
    sc, src, text = load_scenario("P2-s2")
    sc = sc.model_copy(update={"methods": [m for m in sc.methods if m.name == "gmekf-sf"]})
    for seed in range(2):
        run = run_scenario(sc, src, seed=seed)
        r = run.results["gmekf-sf"]
        est, sig = r.sensor[-1, 8], r.sigma[-1, 17]
        assert abs(est - run.sim.imu_draw.gyro_scale[2]) < 3 * sig, seed
        assert sig < 0.5 * 2e-3, seed
