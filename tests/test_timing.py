"""Splitting IMU increments at measurement times."""

import numpy as np

from mixnav.data import ImuData
from mixnav.engine.timing import split_at_times


def _imu(n=50, dt=0.01, rng=None):
    rng = rng or np.random.default_rng(0)
    return ImuData(time=dt * np.arange(1, n + 1), dt=np.full(n, dt),
                   dtheta=rng.normal(size=(n, 3)), dvel=rng.normal(size=(n, 3)))


def test_split_preserves_sums_and_lands_on_event_times():
    imu = _imu()
    events = np.array([0.0137, 0.0200, 0.0212, 0.0219, 0.25, 0.5])
    out, ends = split_at_times(imu, events)
    np.testing.assert_allclose(out.time[ends], events, atol=1e-12)
    for name in ("dtheta", "dvel", "dt"):
        np.testing.assert_allclose(getattr(out, name).sum(0), getattr(imu, name).sum(0), atol=1e-12)
    # 0.02, 0.25 and 0.5 are on samples; 0.0137 cuts one increment in two,
    # 0.0212 and 0.0219 cut another in three
    assert len(out) == len(imu) + 3
    np.testing.assert_allclose(out.time - out.dt, np.concatenate([[0.0], out.time[:-1]]), atol=1e-12)
    # a split part has the rate of the increment it came from
    k = int(np.searchsorted(imu.time, 0.0137))
    j = int(ends[0])
    np.testing.assert_allclose(out.dtheta[j] / out.dt[j], imu.dtheta[k] / imu.dt[k], rtol=1e-12)


def test_no_events_on_samples_means_no_copy():
    imu = _imu()
    out, ends = split_at_times(imu, imu.time[[4, 9]])
    assert out is imu
    np.testing.assert_array_equal(ends, [4, 9])


def test_split_at_times_equals_a_loop_over_the_events():
    """The vectorised split against a plain per-increment loop (each increment cut at its events'
    fractions, in order): bitwise the same times, lengths, increments and event indices."""
    rng = np.random.default_rng(11)
    n = 3000
    dt = 0.01 + rng.uniform(-2e-4, 2e-4, n)
    t = 50.0 + np.cumsum(dt)
    imu = ImuData(time=t, dt=dt, dtheta=rng.normal(size=(n, 3)), dvel=rng.normal(size=(n, 3)))
    ev = np.unique(np.concatenate([rng.uniform(t[0], t[-1], 900), t[rng.integers(0, n, 50)],
                                   t[5] - dt[5] * np.array([0.2, 0.5, 0.7])]))   # three cuts in one increment
    got, idx = split_at_times(imu, ev)
    times, dts, dth, dvs = [], [], [], []
    for i in range(n):
        t0 = t[i] - dt[i]
        inside = ev[(ev > t0 + 1e-6) & (ev < t[i] - 1e-6)]
        edges = [0.0] + sorted(((e - t0) / dt[i]) for e in inside) + [1.0]
        for a, b in zip(edges[:-1], edges[1:]):
            times.append(t0 + b * dt[i] if b < 1.0 else t[i])
            dts.append((b - a) * dt[i])
            dth.append((b - a) * imu.dtheta[i])
            dvs.append((b - a) * imu.dvel[i])
    np.testing.assert_array_equal(got.time, times)
    np.testing.assert_array_equal(got.dt, dts)
    np.testing.assert_array_equal(got.dtheta, np.array(dth))
    np.testing.assert_array_equal(got.dvel, np.array(dvs))
    np.testing.assert_array_equal(got.time[idx], np.array(times)[np.searchsorted(times, ev - 1e-6)])
