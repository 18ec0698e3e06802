"""``mixnav process``: run the methods of a dataset config on real recorded data.

Steps: read the IMU, GNSS and reference files (validated readers of
:mod:`mixnav.io`), apply the installation (IMU axes to body axes, IMU time
offset, lever arm), withhold GNSS in the configured windows, align the INS,
run every method, and score it against the reference where the reference is
valid (its chosen quality flags), reporting the withheld windows separately.

Times inside a run are seconds since the first IMU sample; the absolute time
of that origin (as the files give it) is ``time_origin_s`` in metrics.json.
"""

from __future__ import annotations

import os
import time as _time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

import mixnav

from ..alignment import align_from_gnss_velocity, align_level_then_gnss, coarse_align
from ..attitude import euler_to_dcm
from ..config.dataset_schema import Dataset
from ..config.loader import corruption, imu_model
from ..data import GnssFixes, ImuData, OdometerData, Trajectory
from ..errors import ArgumentError, ConfigError, DataError
from . import methods
from .aiding import AidingInputs, installation_check
from ..filters.ekf import FilterResult, InitialState
from ..ins.mechanization import nav_vector
from ..io import drive0708, generic_csv, kfgins, psins, rtklib
from ..io.imu_checks import check_spikes
from ..sim.gnss import in_windows
from .run import _lla_frame, solution_table, write_outputs
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


def find_data_dir(ds: Dataset, data: str | None, source: str) -> Path:
    """The data folder: ``--data``, else the config's ``data_dir`` relative to
    the working directory, to the folder of the config file, or to the
    repository (for the shipped configs); ``$MIXNAV_DATA/<name>`` last."""
    if data is not None:
        p = Path(data)
        if not p.is_dir():
            raise DataError(f"data folder given with --data does not exist: {p}")
        return p
    d = Path(ds.dataset.data_dir)
    tried = []
    candidates = [d] if d.is_absolute() else [Path.cwd() / d, Path(source).parent / d,
                                               Path(mixnav.__file__).resolve().parents[2] / d]
    if "MIXNAV_DATA" in os.environ:
        candidates.append(Path(os.environ["MIXNAV_DATA"]) / d.name)
    for c in candidates:
        tried.append(str(c))
        if c.is_dir():
            return c
    raise DataError(f"data folder '{ds.dataset.data_dir}' not found (tried {', '.join(tried)}); "
                    "give it with --data DIR", file=source)


def read_imu(ds: Dataset, folder: Path) -> ImuData:
    c = ds.imu
    f = folder / c.file
    if c.format == "drive-0708":
        return drive0708.read_drive_imu(f, folder / c.tag if c.tag else None, time_offset=0.0,
                                        max_gap=c.max_gap, gap_action=c.gap_action, spike_action=c.spike_action)
    if c.format == "kf-gins":
        return kfgins.read_kfgins_imu(f, max_gap=c.max_gap, gap_action=c.gap_action, spike_action=c.spike_action)
    if c.format == "psins":
        imu = psins.read_psins_imu(f)[0]
        return imu if c.spike_action == "fail" else check_spikes(imu, None, c.spike_action)
    return generic_csv.read_imu_csv(f, max_gap=c.max_gap, gap_action=c.gap_action, spike_action=c.spike_action)


def read_gnss(ds: Dataset, folder: Path) -> GnssFixes:
    c = ds.gnss
    f = folder / c.file
    if c.velocity_delay and c.format != "rtklib-pos":
        raise ConfigError(f"velocity_delay is supported for the rtklib-pos format only, not '{c.format}'",
                          key="gnss.velocity_delay")
    if c.format == "rtklib-pos":
        fixes = rtklib.read_pos(f).fixes(qualities=c.qualities, min_sigma=c.min_sigma,
                                         velocity_delay=c.velocity_delay)
    elif c.format == "kf-gins":
        fixes = kfgins.read_kfgins_gnss(f)
    else:
        fixes = generic_csv.read_gnss_csv(f)
    if c.min_sigma > 0:
        fixes = replace(fixes, pos_sigma=np.maximum(fixes.pos_sigma, c.min_sigma))
    if not c.use_velocity and fixes.vel_n is not None:
        fixes = replace(fixes, vel_n=None, vel_sigma=None)
    return fixes


def read_odometer(ds: Dataset, folder: Path, t0: float) -> OdometerData | None:
    """The odometer samples of ``[aiding.odometer]`` on the processing time axis (``t0``: the
    first IMU sample's time, subtracted like from the IMU and GNSS), or None."""
    c = ds.aiding.odometer if ds.aiding is not None else None
    if c is None or c.file is None:
        return None
    from ..io import odometer_csv
    odo = odometer_csv.read_odometer_csv(folder / c.file, sigma=c.sigma,
                                         max_gap=None if c.max_gap is None else float(c.max_gap),
                                         gap_action=c.gap_action)
    return _shift(odo, t0)


def read_reference(ds: Dataset, folder: Path) -> Trajectory | None:
    c = ds.reference
    if c is None:
        return None
    f = folder / c.file
    if c.velocity_delay and c.format != "rtklib-pos":
        raise ConfigError(f"velocity_delay is supported for the rtklib-pos format only, not '{c.format}'",
                          key="reference.velocity_delay")
    if c.format == "rtklib-pos":
        pos = rtklib.read_pos(f)
        ref = pos.reference(qualities=c.qualities)
        if c.velocity_delay and ref.v_n is not None:
            # the reference velocity at its epochs, as the filter's GNSS velocity is
            ref = replace(ref, v_n=pos.velocity_at_epochs(c.velocity_delay)[pos.select(c.qualities)])
        return ref
    if c.format == "kf-gins-nav":
        return kfgins.read_kfgins_nav(f)
    return generic_csv.read_reference_csv(f)


def _corrupt(fixes: GnssFixes, process, rng) -> tuple[GnssFixes, np.ndarray]:
    """Add a noise process (NED metres) to recorded fixes; also the systematic part of what
    was added (M, 3) (:meth:`~mixnav.noise.processes.NoiseProcess.sample_detail`)."""
    dp, _, bias = process.sample_detail(fixes.time, 3, rng)
    return replace(fixes, lla=displace(fixes.lla, dp)), bias


def _shift(obj, t0):
    return replace(obj, time=obj.time - t0)


def install(imu: ImuData, ds: Dataset) -> ImuData:
    """IMU axes to body axes, and the IMU time offset."""
    inst = ds.installation
    c_bi = euler_to_dcm(np.asarray(inst.imu_misalignment)) @ euler_to_dcm(np.asarray(inst.imu_rotation))
    return ImuData(time=imu.time + inst.imu_time_offset, dt=imu.dt, dtheta=imu.dtheta @ c_bi.T,
                   dvel=imu.dvel @ c_bi.T, source=imu.source, gaps=imu.gaps, spikes=imu.spikes)


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


def process(ds: Dataset, source: str, data: str | None = None):
    """Read, align and filter a dataset with every configured method.

    A ``gnss-raw`` dataset is solved epoch by epoch instead, and filtered on the
    constant-velocity model when its methods say so
    (:func:`mixnav.experiment.spp_process.process_raw`, returning an ``SppOutput``).
    """
    folder = find_data_dir(ds, data, source)
    if ds.dataset.kind == "gnss-raw":
        from .spp_process import process_raw
        return process_raw(ds, source, folder)
    if ds.raw_gnss is not None:
        from .rinex_ins import process_rinex_ins
        return process_rinex_ins(ds, source, folder)
    t_read = _time.perf_counter()
    imu = install(read_imu(ds, folder), ds)
    all_fixes = read_gnss(ds, folder)
    reference = read_reference(ds, folder)
    read_time = _time.perf_counter() - t_read
    t0 = imu.start_time
    imu = _shift(imu, t0)
    all_fixes = _shift(all_fixes, t0)
    if reference is not None:
        reference = _shift(reference, t0)
    checks = data_checks(ds, source, imu, all_fixes)
    corrupt = corruption(ds, source)
    if corrupt is not None:
        all_fixes, bias = _corrupt(all_fixes, corrupt, np.random.default_rng(ds.gnss.corrupt_seed))
        gnss_bias = (all_fixes.time.copy(), bias)
    else:
        gnss_bias = None
    withheld = tuple(tuple(w) for w in ds.gnss.withhold)
    keep = ~in_windows(all_fixes.time, withheld)
    fixes = GnssFixes(time=all_fixes.time[keep], lla=all_fixes.lla[keep], pos_sigma=all_fixes.pos_sigma[keep],
                      vel_n=None if all_fixes.vel_n is None else all_fixes.vel_n[keep],
                      vel_sigma=None if all_fixes.vel_sigma is None else all_fixes.vel_sigma[keep],
                      source=all_fixes.source)
    inst = ds.installation
    lever = np.asarray(inst.antenna_position, float) - np.asarray(inst.imu_position, float)
    init = initial_state(ds, imu, fixes, lever)
    out_times = None
    if reference is not None:
        out_times = reference.time[(reference.time > init.time) & (reference.time <= imu.time[-1])]
        if out_times.size == 0:
            raise DataError("the reference does not overlap the processed time span", file=source)
    results = {}
    t_filt = _time.perf_counter()
    model = imu_model(ds.imu.grade, ds.imu.errors, source, "imu.errors", "imu.grade")
    aiding = AidingInputs(ds.aiding, imu, fixes, init.time, float(imu.time[-1]),
                          odometer=read_odometer(ds, folder, t0), source=source)
    for i, m in enumerate(ds.methods):
        filt, meas = methods.build(m, model, fixes, lever, source, i, aiding=aiding)
        results.update(methods.run_method(m, filt, imu, init, meas, source, i, [x.name for x in ds.methods],
                                          output_times=out_times))
    filter_time = _time.perf_counter() - t_filt
    return ProcessOutput(ds, source, folder, t0, imu, fixes, all_fixes, reference, lever, results, init,
                         read_time, filter_time, aiding.summary(),
                         installation_check(imu, ds.alignment.static_duration, results, aiding.stillness,
                                            configured={"antenna_position": inst.antenna_position,
                                                        "imu_time_offset": inst.imu_time_offset}),
                         odometer=aiding.odometer, gnss_bias=gnss_bias, checks=checks)


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


def withheld_windows(po: ProcessOutput) -> tuple:
    """The GNSS windows withheld from the filters, ``((start, end), ...)`` [s]."""
    return tuple(tuple(w) for w in gnss_section(po.dataset)[0].withhold)


def gnss_section(ds: Dataset):
    """The dataset's GNSS section and its key: ``([gnss], "gnss")`` (fixes) or
    ``([raw_gnss], "raw_gnss")`` (RINEX observations); both have ``withhold``, ``max_gap``
    and ``gap_action``."""
    return (ds.gnss, "gnss") if ds.gnss is not None else (ds.raw_gnss, "raw_gnss")


def process_tables(po: ProcessOutput) -> dict[str, pd.DataFrame]:
    """The solution table of every method, errors against the reference for the point it
    gives (the antenna or the IMU)."""
    ref = po.dataset.reference
    lever = po.lever if ref is not None and ref.point == "antenna" else None
    return {name: solution_table(res, po.reference, withheld_windows(po), lever=lever)
            for name, res in po.results.items()}


def write_process(out_dir: Path, po: ProcessOutput, config_text: str | None = None,
                  overwrite: bool = False) -> dict:
    """Solutions, metrics (against the reference), figures and report of a processed dataset
    (the folder policy of :mod:`mixnav.io.outdir`)."""
    if po.dataset.dataset.kind == "gnss-raw":
        from .spp_process import write_raw
        return write_raw(out_dir, po, config_text, overwrite=overwrite)
    withheld = withheld_windows(po)
    tables = process_tables(po)
    for t in tables.values():
        t.insert(1, "gps_time_s", t["time_s"] + po.time_origin)
    duration = float(po.imu.time[-1] - po.init.time)
    header = {"dataset": po.dataset.dataset.name, "source": po.source, "data_dir": str(po.data_dir),
              "time_origin_s": po.time_origin, "start_s": po.init.time, "duration_s": duration,
              "read_time_s": po.read_time_s, "filter_time_s": po.filter_time_s,
              "real_time_factor": duration / (po.read_time_s + po.filter_time_s),
              "gnss_withheld_s": [list(w) for w in withheld],
              "imu_gaps_accepted": int(po.imu.gaps),
              **({} if po.odometer is None else {"odometer_gaps_accepted": int(po.odometer.gaps)}),
              **({"imu_spikes_rejected": int(po.imu.spikes)} if po.imu.spikes else {}),
              **po.checks}
    if po.aiding:
        header["aiding"] = po.aiding
    notes = [f"Times are seconds since the first IMU sample (GPS time {po.time_origin:.3f} s since 1970).",
             f"Aligned at t = {po.init.time:.2f} s ({po.dataset.alignment.method}).",
             "Errors are estimate minus reference, at the reference's valid epochs, for the point the "
             "reference gives (antenna or IMU); windows are the GNSS epochs withheld from the filter."]
    if po.installation:
        header["installation_check"] = po.installation
        for w in po.installation.get("warnings", []):
            notes.append("Installation check: " + w + ".")
        for name, est in po.installation.get("estimated", {}).items():
            said = [f"{k.removeprefix('suggested_')} = {v}" for k, v in est.items() if k.startswith("suggested_")]
            if said:
                notes.append(f"Installation estimated by '{name}': " + ", ".join(said) + ".")
    ref = None if po.reference is None else _lla_frame(po.reference.time, po.reference.lla)
    return write_outputs(out_dir, f"mixnav process: {po.dataset.dataset.name}", header, po.results, tables,
                         withheld, ref, _lla_frame(po.fixes.time, po.fixes.lla), notes, config_text, po.gnss_bias,
                         command="process", overwrite=overwrite, protect=[po.source, po.data_dir])
