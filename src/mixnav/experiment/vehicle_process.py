"""Odometry + raw-GNSS datasets (``kind = "odometry-gnss"``, smartLoc): dead reckoning
corrected by pseudoranges, every method of the config, scored against the reference.

The run: read the odometry (wheel speed, yaw rate) and the pseudoranges, align
(:mod:`mixnav.alignment.track`: causal, from the first ``window`` seconds; or the
reference's first epoch, reported as an oracle start), then one
:class:`~mixnav.engine.Engine` per method with the dead-reckoning motion model
(:class:`~mixnav.motion.DeadReckoningMotion`), the multi-system pseudorange model
(:class:`~mixnav.measurements.pseudorange.PseudorangeGnss`) and the method's
estimator; ``smooth = true`` adds the RTS smoother's ``<name>-smoothed``. The outputs
(solution tables, metrics.json, figures with the map and the error over time,
report.html) are those of ``mixnav run`` / ``mixnav process``
(:func:`mixnav.experiment.outputs.write_outputs`).
"""

from __future__ import annotations

import dataclasses
import math
import time as _time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..config.errors import config_keys
from ..config.vehicle_schema import SYSTEM_CODES, VehicleDataset
from ..data import InitialState, Trajectory
from ..errors import ConfigError
from ..geodesy.frames import lla_to_ned
from ..ins.error_model import ClockModel
from ..io.readers import read_table
from ..measurements.pseudorange import PseudorangeGnss
from ..motion.dead_reckoning import (DeadReckoningMotion, DeadReckoningNoise, dead_reckoning_layout,
                                     odometry_increments, set_heading)
from .methods import run_methods
from .data_folder import find_data_dir
from .outputs import lla_frame, solution_table, write_outputs

__all__ = ["VehicleOutput", "discard_before", "process_vehicle", "vehicle_tables", "write_vehicle"]


@dataclass
class VehicleOutput:
    """What :func:`process_vehicle` produced (the solutions and what they came from)."""

    dataset: VehicleDataset
    source: str
    data_dir: Path
    init: InitialState
    alignment: dict
    results: dict
    reference: Trajectory | None
    read_time_s: float
    filter_time_s: float
    end_time: float
    checks: dict = field(default_factory=dict)


def _reference_init(truth: Trajectory, inc, sigma_pos: float, sigma_heading: float) -> InitialState:
    """The oracle start: the reference's first epochs at or after the odometry's start give
    position and heading."""
    i0 = min(int(np.searchsorted(truth.time, float(inc.time[0] - inc.dt[0]) - 1e-9)), len(truth.time) - 1)
    i1 = min(i0 + 5, len(truth.time) - 1)
    d = lla_to_ned(truth.lla[i1][None], truth.lla[i0])[0]
    nav = np.zeros(10)
    set_heading(nav, math.atan2(d[1], d[0]))
    nav[7:10] = truth.lla[i0]
    t0 = max(float(truth.time[i0]), float(inc.time[0] - inc.dt[0]))
    return InitialState(time=t0, nav=nav, sigma_att=np.array([0.0, 0.0, sigma_heading]), sigma_vel=np.ones(3),
                        sigma_pos=np.full(3, sigma_pos), sigma_clock=np.array([1e4, 200.0]))


def mixture_handover(align: dict, cn0_edges) -> dict | None:
    """The epoch mixture's starting values from a track alignment's report: its LOS weight
    (per C/N0 band of ``cn0_edges``), delay mean and spread, the LOS rows' scale on the given
    variances (``los_scale``: measured on the window's fit) and the LOS errors' correlation
    time, learned on the window the filter starts after (causal). ``None`` when the report has no mixture."""
    if "nlos_mean_m" not in align:
        return None
    return {"los_weight": float(align["los_share"]), "delay_mean": float(align["nlos_mean_m"]),
            "delay_sd": float(align["nlos_sd_m"]), "los_weight_bands": list(align["los_weight_bands"]),
            "correlation_time": float(align["los_correlation_time_s"]),
            **({"los_scale": float(align["los_scale"])} if "los_scale" in align else {}),
            "cn0_edges": [float(v) for v in cn0_edges]}


@dataclass
class VehicleInputs:
    """The files of an ``odometry-gnss`` dataset, read: the odometry, its increments on the
    engine's axes (``inc``), the pseudorange epochs, the reference (or None)."""

    odometry: object          # WheelOdometry
    inc: object               # OdometryIncrements
    epochs: object            # PseudorangeEpochs, from the reader's RawPseudoranges
    reference: Trajectory | None
    read_time_s: float


def discard_before(inputs: VehicleInputs, start: float, source: str | None = None) -> VehicleInputs:
    """``inputs`` as if the recording began ``start`` [s] after the first odometry sample
    (``[alignment] start``): the odometry samples and increments before that time and the
    pseudorange epochs at or before it are dropped; the reference is kept whole (it only
    scores). ``start = 0`` returns ``inputs`` itself. A start that leaves fewer than two
    increments or no pseudorange epoch raises a :class:`ConfigError` naming
    ``alignment.start``."""
    if start == 0.0:
        return inputs
    inc, epochs = inputs.inc, inputs.epochs
    t_s = float(inc.time[0] - inc.dt[0]) + float(start)
    keep = (inc.time - inc.dt) >= t_s - 1e-6
    e_keep = epochs.time > t_s
    if keep.sum() < 2 or not e_keep.any():
        raise ConfigError(f"start {start:g} s leaves no data: the odometry ends {float(inc.time[-1]):g} s, "
                          f"the pseudoranges {float(epochs.time[-1]):g} s", file=source, key="alignment.start")
    inc2 = dataclasses.replace(inc, time=inc.time[keep], dt=inc.dt[keep], dtheta=inc.dtheta[keep],
                               dvel=inc.dvel[keep])
    e0 = int(np.argmax(e_keep))
    r0 = int(epochs.start[e0])
    opt = lambda a: None if a is None else a[r0:]  # noqa: E731
    epochs2 = dataclasses.replace(
        epochs, time=epochs.time[e0:], start=epochs.start[e0:] - r0, pseudorange=epochs.pseudorange[r0:],
        variance=epochs.variance[r0:], sat_ecef=epochs.sat_ecef[r0:], sat_id=epochs.sat_id[r0:],
        system=epochs.system[r0:], elevation=epochs.elevation[r0:], cn0=epochs.cn0[r0:],
        sat_vel=opt(epochs.sat_vel), range_rate=opt(epochs.range_rate))
    o = inputs.odometry
    ko = o.time >= t_s - 1e-6            # the samples whose interval the kept increments hold
    odo2 = dataclasses.replace(o, **{k: getattr(o, k)[ko] for k in ("time", "speed", "yaw_rate", "speed_var",
                                                                        "yaw_rate_var", "line")})
    return dataclasses.replace(inputs, odometry=odo2, inc=inc2, epochs=epochs2)


#: the shortest odometry hole that is reported (or five sample intervals, when longer): across
#: a hole the dead reckoning holds the last speed and yaw rate
ODOMETRY_GAP_S = 1.0


def check_odometry_coverage(odo_time, epoch_time, odo_file) -> dict:
    """The odometry against the pseudoranges: holes in the odometry with pseudorange epochs
    inside (the dead reckoning holds the last speed and yaw rate across them) and pseudorange
    epochs after the odometry's end (not used: the solution ends with the odometry), each
    longer than :data:`ODOMETRY_GAP_S` (or five sample intervals); a
    :class:`~mixnav.io.imu_checks.DataWarning` naming the odometry file and the times.
    Returns ``odometry_gaps_s`` ([start, end] of each hole) and
    ``pseudorange_epochs_after_odometry`` for metrics.json."""
    from ..io.imu_checks import DataWarning
    t, e = np.asarray(odo_time, float), np.asarray(epoch_time, float)
    d = np.diff(t)
    tol = max(ODOMETRY_GAP_S, 5.0 * float(np.median(d))) if d.size else ODOMETRY_GAP_S
    holes = [k for k in np.flatnonzero(d > tol) if np.any((e > t[k]) & (e < t[k + 1]))]
    after = e > t[-1] + tol
    said = []
    if holes:
        k = max(holes, key=lambda j: d[j])
        said.append(f"{len(holes)} hole(s) longer than {tol:g} s in the odometry while the pseudoranges go on, "
                    f"the longest {d[k]:.1f} s from t = {t[k]:.1f} s (the dead reckoning holds the last speed and "
                    "yaw rate across it; metrics.json: odometry_gaps_s)")
    if after.any():
        said.append(f"the odometry ends at t = {t[-1]:.1f} s but the pseudoranges go on to {e[after][-1]:.1f} s: "
                    f"their {int(after.sum())} epochs after it are not used (the solution ends with the odometry; "
                    "metrics.json: pseudorange_epochs_after_odometry)")
    if said:
        warnings.warn(f"{odo_file}: " + "; ".join(said), DataWarning, stacklevel=2)
    return {"odometry_gaps_s": [[float(t[k]), float(t[k + 1])] for k in holes],
            "pseudorange_epochs_after_odometry": int(after.sum())}


def process_vehicle(ds: VehicleDataset, source: str, data: str | None = None, seed: int = 0) -> VehicleOutput:
    """Read, align and run every method of an ``odometry-gnss`` dataset (module docstring)."""
    d = find_data_dir(ds, data, source)
    return run_vehicle(ds, source, d, read_vehicle(ds, source, d), seed)


def read_vehicle(ds: VehicleDataset, source: str, d: Path) -> VehicleInputs:
    """The odometry, pseudorange and reference files of data folder ``d`` (the readers
    registered for their formats); the pseudoranges (corrected RawPseudoranges, every system
    of the file: the model skips rows of systems it does not estimate) grouped into the
    PseudorangeEpochs the alignment and the filters read."""
    from ..gnss.pseudoranges import PseudorangeEpochs
    t_read = _time.perf_counter()
    oc, pc = ds.odometry, ds.pseudoranges
    odo = read_table("odometry", oc, d, "odometry", source)
    epochs = PseudorangeEpochs.from_raw(read_table("raw-gnss", pc, d, "pseudoranges", source))
    truth = None if ds.reference is None else read_table("reference", ds.reference, d, "reference", source)
    sign = 1.0 if oc.yaw_rate_axis == "down" else -1.0      # the engine's heading turns about down
    inc = odometry_increments(odo.time, odo.speed, sign * odo.yaw_rate, source=str(d / oc.file))
    return VehicleInputs(odo, inc, epochs, truth, _time.perf_counter() - t_read)


def track_window_end(inc, window: float, min_distance: float = 0.0, source=None) -> float:
    """End [s] of the track alignment's window over the odometry increments ``inc``: ``window``
    [s] after the data's start, later when the odometry has not yet counted ``min_distance``
    [m] by then (the first increment at which it has); a ConfigError naming
    ``alignment.min_distance`` when the data never travel that far."""
    end = float(inc.time[0] - inc.dt[0] + window)
    if min_distance <= 0.0:
        return end
    travelled = np.cumsum(np.abs(inc.dvel[:, 0]))
    k = int(np.searchsorted(travelled, min_distance))
    if k >= len(inc.time):
        raise ConfigError(f"the odometry counts only {travelled[-1]:.1f} m after the start: no track window "
                          f"travels {min_distance:g} m", file=source, key="alignment.min_distance")
    return max(end, float(inc.time[k]))


def run_vehicle(ds: VehicleDataset, source: str, d: Path, inputs: VehicleInputs, seed: int = 0) -> VehicleOutput:
    """Alignment and every method on the files read (module docstring)."""
    oc, pc = ds.odometry, ds.pseudoranges
    inputs = discard_before(inputs, float(ds.alignment.start), source)
    odo, inc, epochs, truth, read_time = inputs.odometry, inputs.inc, inputs.epochs, inputs.reference, inputs.read_time_s
    coverage = check_odometry_coverage(odo.time, epochs.time, d / oc.file)

    systems = [SYSTEM_CODES[s] for s in pc.systems]
    mc = ds.motion
    ts = float(oc.sample_interval) if oc.sample_interval is not None else float(np.median(inc.dt))
    noise = DeadReckoningNoise(
        speed_sigma=float(oc.speed_sigma) if oc.speed_sigma is not None else float(np.sqrt(np.median(odo.speed_var))),
        yaw_rate_sigma=(float(oc.yaw_rate_sigma) if oc.yaw_rate_sigma is not None
                        else float(np.sqrt(np.median(odo.yaw_rate_var)))),
        sample_interval=ts, lateral_sigma=float(mc.lateral_sigma), vertical_sigma=float(mc.vertical_sigma),
        scale_sigma0=mc.scale_sigma0, bias_sigma0=float(mc.bias_sigma0), scale_walk=mc.scale_walk,
        bias_walk=mc.bias_walk)
    lay = dead_reckoning_layout(clock=True, system_offsets=len(systems) - 1, offset_sigma0=float(mc.offset_sigma0))
    clock = ClockModel(mc.clock_q_bias, mc.clock_q_drift)
    with config_keys("pseudoranges", source):
        model = PseudorangeGnss(epochs, lay, systems=systems, variance=pc.variance, scale=pc.scale,
                                sigma_a=float(pc.sigma_a), sigma_b=float(pc.sigma_b),
                                elevation_mask=float(pc.elevation_mask))
    al = ds.alignment
    t_align = _time.perf_counter()
    if al.mode == "reference":
        if truth is None:
            raise ConfigError("alignment from the reference needs a [reference]", file=source, key="alignment.mode")
        init = _reference_init(truth, inc, float(al.position_sigma), float(al.heading_sigma))
        align = {"mode": "reference (oracle start)"}
        start = None
    else:
        from ..alignment.track import align_track
        with config_keys("alignment", source):
            init0, align = align_track(epochs, inc, track_window_end(inc, float(al.window), float(al.min_distance),
                                                                     source), systems=systems,
                                       cn0_edges=tuple(al.cn0_edges))
        init = InitialState(time=init0.time, nav=init0.nav, sigma_att=np.array([0.0, 0.0, float(al.heading_sigma)]),
                            sigma_vel=np.ones(3), sigma_pos=np.full(3, float(al.position_sigma)),
                            sigma_clock=init0.sigma_clock, clock0=init0.clock0, aux0=init0.aux0)
        align = {"mode": f"track ({float(al.window):g} s)", **align}
        start = mixture_handover(align, al.cn0_edges) if al.hand_over_mixture else None
    align["time_s"] = _time.perf_counter() - t_align
    out_t = (truth.time if truth is not None else epochs.time)
    out_t = out_t[(out_t > init.time) & (out_t <= inc.time[-1])]
    t_filter = _time.perf_counter()
    results = run_methods(list(enumerate(ds.methods)), lambda: DeadReckoningMotion(lay, noise, clock), [model], inc,
                          init, out_t, source, seed, motion="dead-reckoning", mixture_start=start)
    filter_time = _time.perf_counter() - t_filter
    checks = {"pseudorange_rows_skipped": model.skipped_rows, "odometry_rows": len(odo),
              "pseudorange_epochs": len(epochs), **coverage}
    return VehicleOutput(ds, source, d, init, align, results, truth, read_time, filter_time, float(inc.time[-1]),
                         checks)


def vehicle_tables(vo: VehicleOutput) -> dict[str, pd.DataFrame]:
    """The solution table of every method (errors against the reference when there is one)."""
    return {name: solution_table(res, vo.reference) for name, res in vo.results.items()}


def write_vehicle(out_dir, vo: VehicleOutput, config_text: str | None = None, overwrite: bool = False,
                  sweeps=()) -> dict:
    """Solutions, metrics, figures (map, error over time) and report of a processed
    ``odometry-gnss`` dataset (the folder policy of :mod:`mixnav.io.outdir`)."""
    tables = vehicle_tables(vo)
    duration = vo.end_time - vo.init.time
    header = {"dataset": vo.dataset.dataset.name, "source": vo.source, "data_dir": str(vo.data_dir),
              "start_s": vo.init.time, "duration_s": duration, "read_time_s": vo.read_time_s,
              "filter_time_s": vo.filter_time_s, "real_time_factor": duration / (vo.read_time_s + vo.filter_time_s),
              "alignment": vo.alignment, **vo.checks}
    notes = [f"Dead reckoning from wheel speed and yaw rate, corrected by pseudoranges "
             f"({', '.join(vo.dataset.pseudoranges.systems)}); aligned: {vo.alignment['mode']}, the filters start "
             f"at t = {vo.init.time:.2f} s.",
             "Errors are estimate minus reference at the reference's epochs; horizontal = 2-D."]
    ref = None if vo.reference is None else lla_frame(vo.reference.time, vo.reference.lla)
    return write_outputs(out_dir, f"mixnav process: {vo.dataset.dataset.name}", header, vo.results, tables, [],
                         ref, None, notes, config_text, command="process", overwrite=overwrite,
                         protect=[vo.source, vo.data_dir], sweeps=sweeps)
