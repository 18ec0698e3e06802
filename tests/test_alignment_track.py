"""The track alignment (mixnav.alignment.track) on synthetic pseudoranges: what it reports
is measured on its fit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mixnav.alignment.track import align_track
from mixnav.geodesy.frames import lla_to_ecef, ned_to_lla
from mixnav.gnss.geometry import C_LIGHT, earth_rotation_correction
from mixnav.gnss.pseudoranges import PseudorangeEpochs
from mixnav.motion.dead_reckoning import odometry_increments

LLA0 = np.array([math.radians(52.5), math.radians(13.37), 60.0])


def _scene(noise_sd: float, seed: int = 1, heading=math.radians(40.0), speed=8.0, duration=25.0):
    """A car driving straight at ``speed`` along ``heading``, 5 Hz pseudoranges of 9 GPS
    satellites (all line of sight) with white noise ``noise_sd`` [m], the file's variance
    25 m^2, a receiver clock of 100 m drifting 0.5 m/s; odometry at 10 Hz."""
    rng = np.random.default_rng(seed)
    t_odo = np.arange(0.0, duration + 1e-9, 0.1)
    inc = odometry_increments(t_odo, np.full(t_odo.size, speed), np.zeros(t_odo.size))
    az = np.radians(np.arange(9) * 40.0 + 7.0)
    el = np.radians([15, 25, 35, 45, 55, 65, 75, 30, 50])
    r0 = lla_to_ecef(LLA0)
    from mixnav.geodesy.frames import dcm_ecef_to_ned
    C_en = dcm_ecef_to_ned(LLA0[0], LLA0[1]).T
    los_ned = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)], axis=1)
    sats = r0 + 2.2e7 * los_ned @ C_en.T
    rows = {k: [] for k in ("t", "rho", "var", "sat", "id")}
    for t in np.arange(0.2, duration + 1e-9, 0.2):
        p = ned_to_lla(np.array([[speed * t * math.cos(heading), speed * t * math.sin(heading), 0.0]]), LLA0)[0]
        r = lla_to_ecef(p)
        tau = np.linalg.norm(sats - r, axis=1) / C_LIGHT
        rng_m = np.linalg.norm(earth_rotation_correction(sats, tau) - r, axis=1)
        rho = rng_m + 100.0 + 0.5 * t + noise_sd * rng.standard_normal(len(sats))
        for j in range(len(sats)):
            rows["t"].append(t), rows["rho"].append(rho[j]), rows["var"].append(25.0)
            rows["sat"].append(sats[j]), rows["id"].append(j + 1)
    n = len(rows["t"])
    ep = PseudorangeEpochs.from_rows(rows["t"], rows["rho"], rows["var"], np.array(rows["sat"]), rows["id"],
                                     np.ones(n, dtype=int), cn0=np.full(n, 45.0))
    return ep, inc


@pytest.mark.parametrize("noise_sd", [0.5, 3.0])
def test_fit_rms_is_measured_on_the_fit(noise_sd):
    """``fit_rms_m`` is the RMS of the fit's LOS residuals (it was a constant 5 m reported
    as measured), and it is the returned position sigma; ``los_scale`` their mean square on
    the given variances."""
    ep, inc = _scene(noise_sd)
    init, rep = align_track(ep, inc, 20.0, systems=(1,))
    assert rep["fit_rms_m"] == pytest.approx(noise_sd, rel=0.2), rep
    assert rep["los_scale"] == pytest.approx(noise_sd ** 2 / 25.0, rel=0.4), rep
    np.testing.assert_allclose(init.sigma_pos, [rep["fit_rms_m"], rep["fit_rms_m"], 2 * rep["fit_rms_m"]])
    assert abs(((rep["heading_deg"] - 40.0) + 180.0) % 360.0 - 180.0) < 2.0
