"""The parts of an INS dataset run that every GNSS input shares (recorded fixes,
:mod:`mixnav.experiment.process`; RINEX observations, :mod:`mixnav.experiment.rinex_ins`):
the output record, the IMU and reference readers, the installation, the alignment and the
data checks.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..alignment import align_from_gnss_velocity, align_level_then_gnss, coarse_align
from ..attitude import euler_to_dcm
from ..config.dataset_schema import Dataset
from ..data import GnssFixes, ImuData, OdometerData, Trajectory
from ..errors import ArgumentError, ConfigError, DataError
from ..filters.ekf import FilterResult, InitialState
from ..ins.mechanization import nav_vector
from ..io.readers import read_table
from ..sim.gnss import in_windows
from ..geodesy.frames import displace


@dataclass
class ProcessOutput:
    dataset: Dataset
    source: str
    data_dir: Path
    time_origin: float
    imu: ImuData
    fixes: GnssFixes           # what the filters were given (withheld windows removed)
    all_fixes: GnssFixes       # every fix read
    reference: Trajectory | None
    lever: np.ndarray
    results: dict[str, FilterResult]
    init: InitialState
    read_time_s: float
    filter_time_s: float
    aiding: dict = field(default_factory=dict)   # AidingInputs.summary(): still intervals, thresholds
    installation: dict = field(default_factory=dict)  # aiding.installation_check: level, rest, estimates
    odometer: OdometerData | None = None  # the [aiding.odometer] file's samples, when one is read
    gnss_bias: tuple | None = None  # (times, (M, 3) NED m): the systematic part of the injected corruption
    checks: dict = field(default_factory=dict)  # data_checks: GNSS gaps, gyro-vs-track turning
    observations: object = None  # GnssObservations the tight methods read ([raw_gnss] datasets)


def read_imu(ds: Dataset, folder: Path) -> ImuData:
    """The ``[imu]`` file, by the reader registered for its format."""
    return read_table("imu", ds.imu, folder, "imu")


def read_reference(ds: Dataset, folder: Path) -> Trajectory | None:
    """The ``[reference]`` file (None without one), by the reader registered for its format."""
    c = ds.reference
    if c is None:
        return None
    if c.velocity_delay and c.format != "rtklib-pos":
        raise ConfigError(f"velocity_delay is supported for the rtklib-pos format only, not '{c.format}'",
                          key="reference.velocity_delay")
    return read_table("reference", c, folder, "reference")


def _shift(obj, t0):
    return replace(obj, time=obj.time - t0)


def install(imu: ImuData, ds: Dataset) -> ImuData:
    """IMU axes to body axes, and the IMU time offset and clock drift
    (``installation.imu_clock_drift``: the stamps stretched about the first increment's start)."""
    inst = ds.installation
    c_bi = euler_to_dcm(np.asarray(inst.imu_misalignment)) @ euler_to_dcm(np.asarray(inst.imu_rotation))
    time, dt = imu.time + inst.imu_time_offset, imu.dt
    if inst.imu_clock_drift:
        t0 = imu.time[0] - imu.dt[0]
        time = time + inst.imu_clock_drift * (imu.time - t0)
        dt = imu.dt * (1.0 + inst.imu_clock_drift)
    return ImuData(time=time, dt=dt, dtheta=imu.dtheta @ c_bi.T,
                   dvel=imu.dvel @ c_bi.T, source=imu.source, gaps=imu.gaps, spikes=imu.spikes,
                   partial_lines=imu.partial_lines)


def initial_state(ds: Dataset, imu: ImuData, fixes: GnssFixes, lever: np.ndarray) -> InitialState:
    al = ds.alignment
    sig = dict(sigma_att=np.asarray(al.attitude_sigma), sigma_vel=np.asarray(al.velocity_sigma),
               sigma_pos=np.asarray(al.position_sigma))
    if al.method == "level-then-gnss":
        mounting = None if ds.aiding is None else ds.aiding.vehicle_mounting
        forward = None if mounting is None else euler_to_dcm(mounting)[0]   # C_vb^T e_x: the row
        keys = {"rest_duration": "alignment.static_duration", "min_speed": "alignment.min_speed",
                "forward_b": "aiding.vehicle_mounting"}
        try:
            a = align_level_then_gnss(imu, fixes, lever, al.static_duration, al.min_speed, forward_b=forward)
        except ArgumentError as exc:
            raise ConfigError(exc.message, key=keys.get(exc.argument, "alignment")) from None
        sensor0 = np.zeros(12)
        sensor0[0:3] = a.gyro_bias
        return InitialState(time=a.time, nav=nav_vector(a.q_nb, a.v_n, a.lla), sensor0=sensor0, **sig)
    t_static = imu.start_time + al.static_duration
    still = imu.time <= t_static
    sensor0 = None
    if al.gyro_bias_from_static or al.method == "static":
        if still.sum() < 10:
            raise ConfigError("static window holds fewer than 10 IMU samples", key="alignment.static_duration")
        static = ImuData(imu.time[still], imu.dt[still], imu.dtheta[still], imu.dvel[still], imu.source)
    if al.method == "static":
        lat = fixes.lla[0, 0]
        a = coarse_align(static, lat, fixes.lla[0, 2])
        k = int(np.searchsorted(fixes.time, t_static))
        if k >= len(fixes):
            raise DataError("no GNSS fix after the static alignment window", file=fixes.source)
        lla = displace(fixes.lla[k], -(euler_to_dcm(a.rpy) @ lever))
        return InitialState(time=float(t_static), nav=nav_vector(a.q_nb, np.zeros(3), lla), **sig)
    if al.gyro_bias_from_static:
        # mean rate at rest; the unknown horizontal Earth rate (<= 15 deg/h)
        # stays in it, far below a MEMS gyro's bias
        sensor0 = np.zeros(12)
        sensor0[0:3] = static.dtheta.sum(0) / static.dt.sum()
    m = align_from_gnss_velocity(fixes, lever, al.min_speed, after=imu.start_time)
    return InitialState(time=m.time, nav=nav_vector(m.q_nb, m.v_n, m.lla), sensor0=sensor0, **sig)


def data_checks(ds: Dataset, source: str, imu: ImuData, fixes: GnssFixes) -> dict:
    """Plausibility of the data read, on the processing time axis (docs/validation.md).

    - some GNSS fix must fall within the IMU's time span (a different time base is an error);
      the fixes outside it are counted (``gnss_fixes_outside_imu``);
    - ``gnss.withhold`` windows must overlap the fixes (ConfigError naming the window);
    - GNSS holes longer than ``gnss.max_gap`` outside the withheld windows are listed
      (``gnss_gaps_s``, with a warning) or, with ``gnss.gap_action = "fail"``, an error;
    - the gyros' turning must agree with the GNSS track's (:func:`mixnav.io.imu_checks.check_turns`).
    """
    import warnings
    from ..io.imu_checks import DataWarning, check_turns
    out: dict = {}
    g, gk = gnss_section(ds)
    if len(fixes) == 0:
        raise DataError("no GNSS fix of the chosen qualities", file=fixes.source)
    t0, t1 = float(fixes.time[0]), float(fixes.time[-1])
    inside = (fixes.time >= imu.start_time) & (fixes.time <= imu.time[-1])
    if not inside.any():
        raise DataError(f"no GNSS fix within the IMU's time span: IMU {imu.start_time:.3f}..{imu.time[-1]:.3f} s, "
                        f"GNSS {t0:.3f}..{t1:.3f} s (after the first IMU sample): different time bases "
                        "(GPS time of week, Unix time, time since start)?", file=fixes.source)
    out["gnss_fixes_outside_imu"] = int((~inside).sum())
    for i, (a, b) in enumerate(g.withhold):
        if a >= t1 or b <= t0:
            raise ConfigError(f"window [{a:g}, {b:g}] s lies outside the GNSS data ({t0:.1f}..{t1:.1f} s after the "
                              "first IMU sample): nothing would be withheld", file=source, key=f"gnss.withhold[{i}]")
    d = np.diff(fixes.time)
    mid = 0.5 * (fixes.time[1:] + fixes.time[:-1])
    withheld = in_windows(mid, tuple(tuple(w) for w in g.withhold))
    holes = np.flatnonzero((d > g.max_gap) & ~withheld)
    out["gnss_gaps_s"] = [[float(fixes.time[k]), float(fixes.time[k + 1])] for k in holes]
    if holes.size:
        k = int(holes[np.argmax(d[holes])])
        msg = (f"{holes.size} hole(s) longer than {gk}.max_gap = {g.max_gap:g} s between GNSS fixes; the longest "
               f"{d[k]:.1f} s from t = {fixes.time[k]:.1f} s (listed in metrics.json: gnss_gaps_s)")
        if g.gap_action == "fail":
            raise DataError(msg, file=fixes.source)
        warnings.warn(f"{fixes.source}: {msg}", DataWarning, stacklevel=2)
    turns = check_turns(imu, fixes.time, fixes.lla, fixes.vel_n, f"the unit of the {ds.imu.format} format")
    if turns is not None:
        out["gyro_turn_check"] = turns
    return out


def gnss_section(ds: Dataset):
    """The dataset's GNSS section and its key: ``([gnss], "gnss")`` (fixes) or
    ``([raw_gnss], "raw_gnss")`` (RINEX observations); both have ``withhold``, ``max_gap``
    and ``gap_action``."""
    return (ds.gnss, "gnss") if ds.gnss is not None else (ds.raw_gnss, "raw_gnss")


def with_withheld(ds: Dataset, windows) -> Dataset:
    """The dataset with its GNSS withheld in ``windows`` ``[(start, end), ...]`` [s] instead of
    its own ``withhold`` windows (the outage sweep: :mod:`mixnav.experiment.sweep`)."""
    section, key = gnss_section(ds)
    held = [(float(a), float(b)) for a, b in windows]
    return ds.model_copy(update={key: section.model_copy(update={"withhold": held})})


def _start_for(init: InitialState, meas) -> InitialState:
    """``init`` without the auxiliary start values (the inter-system offsets of a multi-system
    tight start) of blocks the method's layout does not have (a loose method beside it)."""
    if not init.aux0 or not meas:
        return init
    lay = getattr(meas[0], "layout", None)
    if lay is None:
        return init
    kept = {k: v for k, v in init.aux0.items() if lay.has(k)}
    return init if len(kept) == len(init.aux0) else replace(init, aux0=kept or None)


def run_ins_methods(ds: Dataset, imu: ImuData, fixes: GnssFixes, init: InitialState, reference,
                    lever: np.ndarray, source: str, make_aiding, **build) -> tuple[dict, object, float]:
    """Every ``[[methods]]`` entry on the IMU from ``init``: ``(results, aiding,
    filter_time_s)``. Solutions are output at the reference's times when there is a
    reference (a DataError if it does not overlap the run); ``make_aiding()`` builds the
    run's AidingInputs (inside the timed part, as the filters use it); ``build``: extra
    keywords of :func:`mixnav.experiment.methods.build` (the tight observations, the clock
    model)."""
    import time as _time
    from ..config.loader import imu_model
    from . import methods
    out_times = None
    if reference is not None:
        out_times = reference.time[(reference.time > init.time) & (reference.time <= imu.time[-1])]
        if out_times.size == 0:
            raise DataError("the reference does not overlap the processed time span", file=source)
    t_filt = _time.perf_counter()
    model = imu_model(ds.imu.grade, ds.imu.errors, source, "imu.errors", "imu.grade")
    aiding = make_aiding()
    names = [x.name for x in ds.methods]
    results: dict = {}
    for i, m in enumerate(ds.methods):
        filt, meas = methods.build(m, model, fixes, lever, source, i, aiding=aiding, **build)
        results.update(methods.run_method(m, filt, imu, _start_for(init, meas), meas, source, i, names,
                                          output_times=out_times))
    return results, aiding, _time.perf_counter() - t_filt

