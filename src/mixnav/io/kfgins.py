"""Readers of the KF-GINS text formats (Wuhan University i2Nav's KF-GINS).

* IMU: ``time dtheta_x dtheta_y dtheta_z dvel_x dvel_y dvel_z`` per line:
  GPS seconds of week, angle increments [rad] and velocity increments [m/s]
  in the forward-right-down body frame. The first line only opens the first
  interval (its increments belong to an interval that started before it).
* GNSS: ``time lat lon h sd_n sd_e sd_d`` [s, deg, deg, m, m, m, m], optionally
  followed by ``vn ve vd sd_vn sd_ve sd_vd``.
* Reference ``.nav``: ``week time lat lon h vn ve vd roll pitch yaw``
  [-, s, deg, deg, m, m/s x 3, deg x 3].
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..attitude import euler_to_quat
from ..data import GnssFixes, ImuData, Trajectory
from ..errors import DataError
from .imu_checks import check_plausible
from .registry import ReadOptions, register_reader
from .tables import check_fix_values, check_times, read_numeric


def read_kfgins_imu(path, max_gap: float | None = None, gap_action: str = "warn",
                    spike_action: str = "fail") -> ImuData:
    tab = read_numeric(path, 7, what="KF-GINS IMU")
    v = tab.values
    gaps = check_times(v[:, 0], tab.lines, tab.path, max_gap=max_gap, gap_action=gap_action, what="IMU").gaps
    if len(v) < 2:
        raise DataError("need at least two IMU lines", file=tab.path)
    imu = ImuData(time=v[1:, 0], dt=np.diff(v[:, 0]), dtheta=v[1:, 1:4], dvel=v[1:, 4:7], source=tab.path,
                  gaps=gaps)
    return check_plausible(imu, "rad", "m/s", tab.lines[1:], spike_action)


def read_kfgins_gnss(path, max_gap: float | None = None, gap_action: str = "warn") -> GnssFixes:
    tab = read_numeric(path, (7, 13), what="KF-GINS GNSS")
    v = tab.values
    check_times(v[:, 0], tab.lines, tab.path, max_gap=max_gap, gap_action=gap_action, what="GNSS")
    _check_sigma(v[:, 4:7], tab)
    lla = np.column_stack([np.radians(v[:, 1]), np.radians(v[:, 2]), v[:, 3]])
    check_fix_values(lla, v[:, 4:7], tab.lines, tab.path, v[:, 7:10] if v.shape[1] == 13 else None)
    if v.shape[1] == 13:
        _check_sigma(v[:, 10:13], tab)
        return GnssFixes(time=v[:, 0], lla=lla, pos_sigma=v[:, 4:7], vel_n=v[:, 7:10], vel_sigma=v[:, 10:13],
                         source=tab.path)
    return GnssFixes(time=v[:, 0], lla=lla, pos_sigma=v[:, 4:7], source=tab.path)


def read_kfgins_nav(path) -> Trajectory:
    tab = read_numeric(path, 11, what="KF-GINS reference")
    v = tab.values
    check_times(v[:, 1], tab.lines, tab.path, what="reference")
    return Trajectory(time=v[:, 1], lla=np.column_stack([np.radians(v[:, 2]), np.radians(v[:, 3]), v[:, 4]]),
                      v_n=v[:, 5:8], q_nb=euler_to_quat(np.radians(v[:, 8:11])))


def _check_sigma(sd, tab):
    bad = np.nonzero(~(sd > 0).all(1))[0]
    if bad.size:
        raise DataError("standard deviations must be positive", file=tab.path, line=int(tab.lines[bad[0]]))


@register_reader("imu", "kf-gins")
def _read_imu(path: Path, options: ReadOptions) -> ImuData:
    """The registered IMU reader (``options``: ``max_gap``, ``gap_action``, ``spike_action``)."""
    return read_kfgins_imu(path, **options.imu_checks())


@register_reader("gnss-fixes", "kf-gins")
def _read_gnss(path: Path, options: ReadOptions) -> GnssFixes:
    """The registered GNSS reader (no options)."""
    return read_kfgins_gnss(path)


@register_reader("reference", "kf-gins-nav")
def _read_reference(path: Path, options: ReadOptions) -> Trajectory:
    """The registered reference reader (no options)."""
    return read_kfgins_nav(path)
