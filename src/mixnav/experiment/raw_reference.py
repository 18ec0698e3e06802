"""The reference of a raw-GNSS dataset (``kind = "gnss-raw"``) at its epochs: a surveyed
static point (``[reference_point]``) or the trajectory of a moving receiver
(``[reference]``, :class:`mixnav.config.raw_gnss_schema.RawReference`).

Time axis: the SPP solution table's, seconds since the first observation epoch, built
from GPS week and seconds of week (the week difference first, so that no float holds GPS
seconds since 1980). Each reference format's time stamps are brought onto it:

- ``gps-week-csv``: GPS week and time of week per line (:mod:`mixnav.io.gps_week_csv`);
- ``rtklib-pos``: GPST (calendar or week/tow), read as GPS seconds in the Unix scale
  (:mod:`mixnav.io.rtklib`);
- ``smartloc``: seconds since the start of the log, as a smartLoc log's pseudoranges
  (``[raw_gnss] format = "smartloc"``, solved with week 0 and the log's seconds);
- ``csv``, ``kf-gins-nav``: bare seconds, GPS seconds of the week of the first epoch
  (``time = "gps-week-seconds"``, the default) or since 1980 (``"gps-seconds"``): the
  convention of the INS datasets with RINEX (``[raw_gnss] imu_time``).

The reference at an epoch is interpolated linearly in latitude, longitude and height
between the two samples around it (:func:`mixnav.experiment.outputs.truth_at`, as the INS
datasets' scoring); an epoch within 1 us of a sample takes that sample exactly. An epoch
before the first or after the last sample, or between two samples further apart than
``max_gap``, is not scored: its error columns are NaN, its status is unchanged (a solved
epoch stays solved: availability counts it), and it is counted in ``reference_epochs``
(metrics.json). No epoch inside the span and outside the gaps is a ConfigError naming the
reference file and ``reference.file``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..data import Trajectory
from ..errors import ConfigError
from ..geodesy.frames import dcm_ecef_to_ned, lla_to_ecef
from ..io.readers import read_table
from .outputs import truth_at

SECONDS_PER_WEEK = 604800.0
GPS_EPOCH_UNIX = 315964800.0     # 1980-01-06 00:00:00 in Unix seconds (RTKLIB's time scale)
#: an epoch this close to a reference sample takes the sample (RINEX epochs carry 0.1 us)
SNAP_S = 1e-6


@dataclass
class EpochReference:
    """The moving reference at the epochs.

    Attributes
    ----------
    lla : ndarray (k, 3)
        Latitude, longitude [rad], height [m] at each epoch; NaN where not scored.
    scored : ndarray (k,) of bool
        Inside the reference's span and outside its gaps.
    counts : dict
        ``scored``, ``before_reference``, ``after_reference``, ``in_reference_gaps``
        (epochs, solved or not), ``reference_gaps`` (intervals longer than ``max_gap``
        that hold an epoch).
    trajectory : Trajectory
        The reference read, its time on the epochs' axis [s since the first epoch].
    file : str
        The reference file (for messages and metrics.json).
    """

    lla: np.ndarray
    scored: np.ndarray
    counts: dict
    trajectory: Trajectory
    file: str


def epoch_axis(week, tow) -> np.ndarray:
    """Seconds since the first epoch ((k,)), the week difference first."""
    week = np.asarray(week, np.int64)
    tow = np.asarray(tow, float)
    return (week - week[0]) * SECONDS_PER_WEEK + (tow - tow[0])


def reference_times(traj: Trajectory, fmt: str, time: str, week0: int, tow0: float) -> np.ndarray:
    """The reference's time stamps on the epochs' axis (module docstring)."""
    if fmt == "gps-week-csv":
        return (np.asarray(traj.extra["gps_week"], np.int64) - week0) * SECONDS_PER_WEEK + (
            np.asarray(traj.extra["gps_tow_s"], float) - tow0)
    if fmt == "smartloc":     # the log's own seconds, as the smartLoc pseudoranges' (week 0)
        return np.asarray(traj.time, float) - tow0
    if fmt == "rtklib-pos":
        return (np.asarray(traj.time, float) - GPS_EPOCH_UNIX - week0 * SECONDS_PER_WEEK) - tow0
    if time == "gps-seconds":
        return (np.asarray(traj.time, float) - week0 * SECONDS_PER_WEEK) - tow0
    return np.asarray(traj.time, float) - tow0


def _gps(week0: int, tow0: float, t: float) -> str:
    """A time on the epochs' axis as GPS week and seconds of week, for messages."""
    s = tow0 + t
    w = week0 + int(np.floor(s / SECONDS_PER_WEEK))
    return f"GPS week {w} {s - (w - week0) * SECONDS_PER_WEEK:.3f} s"


def reference_at_epochs(c, folder: Path, source: str, week, tow) -> EpochReference:
    """Read ``[reference]`` (table ``c``) and put it at the epochs (GPS ``week``, ``tow``:
    (k,)); module docstring."""
    path = folder / c.file
    traj = read_table("reference", c, folder, "reference", source)
    week0, tow0 = int(np.asarray(week)[0]), float(np.asarray(tow)[0])
    t_ref = reference_times(traj, c.format, c.time, week0, tow0)
    t_ep = epoch_axis(week, tow)
    span = f"{_gps(week0, tow0, t_ref[0])} .. {_gps(week0, tow0, t_ref[-1])}"
    obs_span = f"{_gps(week0, tow0, t_ep[0])} .. {_gps(week0, tow0, t_ep[-1])}"
    how = "" if c.format in ("gps-week-csv", "rtklib-pos", "smartloc") else (
        f" (its time column read as reference.time = \"{c.time}\")")
    if t_ref[-1] < t_ep[0] - SNAP_S or t_ref[0] > t_ep[-1] + SNAP_S:
        raise ConfigError(f"the reference {path} ({span}){how} and the observations ({obs_span}) do not overlap: "
                          "is it the reference of this recording, and on GPS time?", file=source, key="reference.file")
    # snap epochs onto samples within SNAP_S: they then take the sample exactly
    j = np.clip(np.searchsorted(t_ref, t_ep), 0, len(t_ref) - 1)
    near = np.where(np.abs(t_ref[j] - t_ep) <= np.abs(t_ref[np.maximum(j - 1, 0)] - t_ep), j, np.maximum(j - 1, 0))
    on_sample = np.abs(t_ref[near] - t_ep) <= SNAP_S
    t = np.where(on_sample, t_ref[near], t_ep)
    before, after = t < t_ref[0], t > t_ref[-1]
    k = np.clip(np.searchsorted(t_ref, t), 1, len(t_ref) - 1)
    interval = t_ref[k] - t_ref[k - 1]
    in_gap = ~on_sample & ~before & ~after & (interval > float(c.max_gap))
    scored = ~before & ~after & ~in_gap
    counts = {"scored": int(scored.sum()), "before_reference": int(before.sum()),
              "after_reference": int(after.sum()), "in_reference_gaps": int(in_gap.sum()),
              "reference_gaps": int(np.unique(k[in_gap]).size)}
    if not scored.any():
        raise ConfigError(f"no epoch of the observations ({obs_span}) falls inside the reference {path} ({span}){how} "
                          f"outside its gaps (samples further apart than reference.max_gap = {float(c.max_gap):g} s): "
                          f"nothing to score ({counts})", file=source, key="reference.file")
    lla = np.full((len(t), 3), np.nan)
    lla[on_sample] = traj.lla[near[on_sample]]              # the sample itself, bit for bit
    between = scored & ~on_sample
    if between.any():
        lla[between] = truth_at(Trajectory(time=t_ref, lla=traj.lla, v_n=None, q_nb=None), t[between]).lla
    return EpochReference(lla, scored, counts, Trajectory(time=t_ref, lla=traj.lla, v_n=None, q_nb=None), str(path))


def errors_ned(pos_ecef: np.ndarray, ref_lla: np.ndarray) -> np.ndarray:
    """Estimate minus reference, in NED at each epoch's reference point ((k, 3) m; NaN where
    either is NaN): the static point's convention, epoch by epoch."""
    C_ne = dcm_ecef_to_ned(ref_lla[:, 0], ref_lla[:, 1])
    return np.einsum("kij,kj->ki", C_ne, pos_ecef - lla_to_ecef(ref_lla))
