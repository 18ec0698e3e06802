"""Cost of the UKF's propagation step before and after the ensemble seam (issue 33).

    PYTHONPATH=<tree>/src python benchmarks/bench_ensemble_seam.py <label>

Times ``UnscentedEstimator.predict`` alone (21 states, 43 sigma points, one 1 s step of
100 IMU increments merged into 4 sub-intervals): before the seam one compiled call
(``ukf_predict``), after it three (``ukf_sigma``, the motion model's
``propagate_members``, ``ukf_moments``). Seven batches of 300 calls; the minimum batch
mean is the number to compare (the machine is shared), run alternately on the two trees.
"""

import sys
import time

import numpy as np

from mixnav.ins.error_model import get_layout
from mixnav.ins.imu_model import ImuErrorModel
from mixnav.ins.strapdown import StrapdownMotion
from mixnav.engine.protocols import StepInputs, Transition
from mixnav.filters.ukf import UnscentedEstimator
lay = get_layout(21)
motion = StrapdownMotion(lay, ImuErrorModel())
motion.warm_up()
est = UnscentedEstimator()
est.warm_up()
n = lay.n
P0 = np.eye(n) * 1e-4
est.init(motion, P0, 0, np.random.default_rng(0))
K = 100
dth = np.zeros((K, 3)); dv = np.zeros((K, 3)); dv[:, 2] = -0.098; dt = np.full(K, 0.01)
nav = np.array([1.0, 0, 0, 0, 0, 0, 0, 0.7, 0.2, 100.0])
inp = StepInputs(nav.copy(), np.zeros(6), np.zeros(2), np.zeros(12), dth, dv, dt, nav)
Qd = np.eye(n) * 1e-10
step = Transition(np.zeros((n, n)), np.eye(n), Qd, 1.0, True, inp)
best = []
for r in range(7):
    t0 = time.perf_counter()
    for i in range(300):
        est.P[:] = P0; est.x[:] = 0.0
        est.predict(step)
    best.append((time.perf_counter() - t0) / 300 * 1e6)
print(sys.argv[1] if len(sys.argv) > 1 else "this tree", "predict us: min %.1f median %.1f" % (min(best), np.median(best)))
