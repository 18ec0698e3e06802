"""Cost of one tight-EKF GNSS epoch, side by side with filterpy, in one run.

    python benchmarks/bench_tight.py         # writes benchmarks/results/tight_bench.{json,md}

Per GNSS epoch with 8 and 12 satellites (pseudorange + Doppler, so 16 and 24
measurements; 17 states), after a warm-up, best of repeats:

- ``mixnav``: the compiled measurement model (:class:`TightGnss.measure`:
  antenna, lines of sight, z, H, R) plus the compiled gate + Joseph update +
  feedback (``ekf_correct``), i.e. what the engine runs at a GNSS epoch;
- ``filterpy_full``: filterpy's ``ExtendedKalmanFilter.update`` given the same
  h(x) and H, both evaluated by the numpy model (:meth:`TightGnss.predict`,
  :meth:`TightGnss.measure_numpy`) inside the call, as a user of filterpy
  would write it;
- ``filterpy_update_only``: the same update with h(x) and H precomputed
  outside the timed call (filterpy's Kalman algebra alone).

Also the engine's own mean update time on the shipped demos (measurement
model, augmentation for the clone, correction and feedback) as
``FilterResult.timing['update_time_mean_us']``.
"""

from __future__ import annotations

import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

from _timing import best_time
from mixnav import __version__
from mixnav.config import load_scenario
from mixnav.experiment.run import run_scenario
from mixnav.filters._ekf_kernels import ekf_correct
from mixnav.filters.ekf import _warm_up
from mixnav.geodesy.frames import lla_to_ecef
from mixnav.gnss.constellation import NominalConstellation
from mixnav.gnss.geometry import elevation_azimuth
from mixnav.gnss.observables import GnssObservations
from mixnav.ins.error_model import get_layout
from mixnav.measurements.tight import TightGnss

RESULTS = Path(__file__).resolve().parent / "results"
LEVER = np.array([0.5, 0.2, -1.0])


def one_epoch(n_sat: int, nav: np.ndarray, rng) -> GnssObservations:
    """One epoch with the ``n_sat`` highest satellites of the 30-satellite constellation."""
    r = lla_to_ecef(nav[7:10])
    s = NominalConstellation.gps(5).states(1000.0)
    el, _ = elevation_azimuth(r, s.pos_ecef)
    top = np.argsort(-el)[:n_sat]
    assert el[top].min() > 0, "not enough satellites above the horizon"
    p, v = s.pos_ecef[top][None], s.vel_ecef[top][None]
    d = p[0] - r
    rho = np.linalg.norm(d, axis=1)
    u = d / rho[:, None]
    pr = (rho + 5.0 + rng.standard_normal(n_sat) * 3.0)[None]
    rr = (np.einsum("ij,ij->i", u, v[0]) + 0.2 + rng.standard_normal(n_sat) * 0.1)[None]
    return GnssObservations(time=np.array([1.0]), valid=np.ones((1, n_sat), bool),
                            prn=s.prn[top][None], sat_pos=p, sat_vel=v, pseudorange=pr,
                            range_rate=rr, carrier=pr.copy(), elevation=el[top][None],
                            sigma_pr=3.0, sigma_rr=0.1, sigma_cp=0.003, clock=np.zeros((1, 2)))


def bench_epoch(n_sat: int) -> dict:
    from filterpy.kalman import ExtendedKalmanFilter
    lay = get_layout(17)
    la = lay.as_array()
    _warm_up(lay)
    rng = np.random.default_rng(0)
    nav = np.array([np.cos(0.25), 0.0, 0.0, np.sin(0.25), 10.0, 5.0, 0.1,
                    np.radians(34.4), np.radians(113.5), 100.0])
    obs = one_epoch(n_sat, nav, rng)
    meas = TightGnss(obs, LEVER, lay)
    w_b = np.array([0.01, -0.02, 0.15])
    clock = np.array([0.0, 0.0])
    P0 = np.diag(np.r_[np.full(3, 1e-2), np.full(3, 0.1), np.full(3, 2.0), np.full(3, 1e-4),
                       np.full(3, 1e-2), 10.0, 1.0] ** 2)
    m = 2 * n_sat

    def ours():
        z, H, r = meas.measure(0, nav, w_b, clock)
        return ekf_correct(P0, z, H, r, 1e4, nav.copy(), np.zeros(12), np.zeros(2), la)

    t_ours = best_time(ours, 7, number=2000, warmup=True)
    y = obs.pseudorange[0], obs.range_rate[0]
    z_meas = np.concatenate(y).reshape(m, 1)

    def hx(x):
        pr, rr, *_ = meas.predict(0, nav, w_b, clock)
        return np.concatenate([pr, rr]).reshape(m, 1)

    def jac(x):
        return meas.measure_numpy(0, nav, w_b, clock)[1]

    ekf = ExtendedKalmanFilter(dim_x=17, dim_z=m)
    ekf.R = np.diag(meas.measure_numpy(0, nav, w_b, clock)[2])

    def filterpy_full():
        ekf.x = np.zeros((17, 1))
        ekf.P = P0.copy()
        ekf.update(z_meas, jac, hx)

    t_full = best_time(filterpy_full, 7, number=500, warmup=True)
    H = jac(None)
    h0 = hx(None)

    def filterpy_update_only():
        ekf.x = np.zeros((17, 1))
        ekf.P = P0.copy()
        ekf.update(z_meas, lambda x: H, lambda x: h0)

    t_upd = best_time(filterpy_update_only, 7, number=1000, warmup=True)
    # same numbers: the posterior covariance of both (the feedback does not change P)
    P_ours = ours()[0]
    ekf.x = np.zeros((17, 1))
    ekf.P = P0.copy()
    ekf.update(z_meas, jac, hx)
    agree = float(np.abs(P_ours - ekf.P).max() / np.abs(P0).max())
    return {"satellites": n_sat, "measurements": m, "states": 17,
            "mixnav_us_per_epoch": t_ours * 1e6,
            "filterpy_full_us_per_epoch": t_full * 1e6,
            "filterpy_update_only_us_per_epoch": t_upd * 1e6,
            "ratio_filterpy_full_over_mixnav": t_full / t_ours,
            "ratio_filterpy_update_only_over_mixnav": t_upd / t_ours,
            "max_rel_difference_of_P_post": agree}


def bench_engine() -> dict:
    out = {}
    for name in ("tight-demo", "tdcp-demo"):
        sc, src, _ = load_scenario(name)
        run = run_scenario(sc, src, seed=1)  # the first run compiles (cached kernels load)
        run = run_scenario(sc, src, seed=1)
        for m, res in run.results.items():
            out[f"{name}/{m}"] = {"update_time_mean_us": res.timing["update_time_mean_us"],
                                  "epoch_time_mean_us": res.timing["epoch_time_mean_us"]}
    return out


def main():
    res = {"machine": {"python": sys.version.split()[0], "platform": platform.platform(),
                       "mixnav": __version__, "date": time.strftime("%Y-%m-%d %H:%M")},
           "epoch_8": bench_epoch(8), "epoch_12": bench_epoch(12), "engine": bench_engine()}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "tight_bench.json").write_text(json.dumps(res, indent=2) + "\n")
    lines = ["# Tight EKF epoch cost (benchmarks/bench_tight.py)", "",
             f"Recorded {res['machine']['date']}, Python {res['machine']['python']}, mixnav "
             f"{res['machine']['mixnav']}; one process, side by side, best of 7 repeats.", "",
             "| quantity | 8 satellites | 12 satellites |", "| --- | --- | --- |"]
    for k in res["epoch_8"]:
        lines.append(f"| {k} | {res['epoch_8'][k]:.4g} | {res['epoch_12'][k]:.4g} |")
    lines += ["", "Engine, mean per GNSS epoch on the shipped demos (seed 1):", "",
              "| scenario/method | update (model + correction + feedback) [us] | whole epoch incl. INS [us] |",
              "| --- | --- | --- |"]
    for k, v in res["engine"].items():
        lines.append(f"| {k} | {v['update_time_mean_us']:.1f} | {v['epoch_time_mean_us']:.1f} |")
    (RESULTS / "tight_bench.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
