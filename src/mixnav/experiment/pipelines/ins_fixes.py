"""The ``ins-gnss`` pipeline with recorded GNSS fixes (``[gnss]``): read the IMU, GNSS and
reference files (the readers registered for their formats, :mod:`mixnav.io.readers`), apply
the installation (IMU axes to body axes, IMU time offset, lever arm), withhold GNSS in the
configured windows, align the INS, run every method, and score it against the reference
where the reference is valid (its chosen quality flags), reporting the withheld windows
separately.

Times inside a run are seconds since the first IMU sample (the start of its first increment); the absolute time
of that origin (as the files give it) is ``time_origin_s`` in metrics.json.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from ...config.dataset_schema import Dataset
from ...config.loader import corruption
from ...data import GnssFixes, ImuData, OdometerData, Trajectory
from ...errors import ConfigError
from ...geodesy.frames import displace
from ...io.readers import read_table
from ...io.rtklib import velocity_at_epochs
from ...sim.gnss import in_windows
from ..aiding import AidingInputs, installation_check
from ..ins_common import (ProcessOutput, _shift, data_checks, gnss_section, initial_state, install, read_imu,
                          read_reference, run_ins_methods)
from ..metrics import method_metrics
from ..outputs import lla_frame, solution_table, write_outputs


def read_gnss(ds: Dataset, folder: Path) -> GnssFixes:
    """The ``[gnss]`` fixes, by the reader registered for its format; sigmas floored at
    ``min_sigma``, velocities dropped unless ``use_velocity``. The velocities are as the
    file reports them: ``velocity_delay`` is applied by :func:`delay_velocities` to the
    fixes kept after withholding."""
    c = ds.gnss
    if c.velocity_delay and c.format != "rtklib-pos":
        raise ConfigError(f"velocity_delay is supported for the rtklib-pos format only, not '{c.format}'",
                          key="gnss.velocity_delay")
    fixes = read_table("gnss-fixes", c.model_copy(update={"velocity_delay": 0.0}), folder, "gnss")
    if c.min_sigma > 0:
        fixes = replace(fixes, pos_sigma=np.maximum(fixes.pos_sigma, c.min_sigma))
    if not c.use_velocity and fixes.vel_n is not None:
        fixes = replace(fixes, vel_n=None, vel_sigma=None)
    return fixes


def delay_velocities(fixes: GnssFixes, delay: float) -> GnssFixes:
    """The fixes with their velocities moved to the epoch times (``delay`` [s]: how much
    earlier each reported velocity is valid; :func:`mixnav.io.rtklib.velocity_at_epochs`),
    interpolated between these fixes only: withhold first, so that the last fix before a
    window carries nothing of the first withheld one."""
    if not delay or fixes.vel_n is None:
        return fixes
    return replace(fixes, vel_n=velocity_at_epochs(fixes.time, fixes.vel_n, delay))


def read_odometer(ds: Dataset, folder: Path, t0: float) -> OdometerData | None:
    """The odometer samples of ``[aiding.odometer]`` on the processing time axis (``t0``: the
    first IMU sample's time, subtracted like from the IMU and GNSS), or None."""
    c = ds.aiding.odometer if ds.aiding is not None else None
    if c is None or c.file is None:
        return None
    od = read_table("odometer", c, folder, "aiding.odometer")
    if c.time_offset:
        od = replace(od, time=od.time + c.time_offset)   # the stamps' lag ([aiding.odometer] time_offset)
    return _shift(od, t0)


def _corrupt(fixes: GnssFixes, process, rng) -> tuple[GnssFixes, np.ndarray]:
    """Add a noise process (NED metres) to recorded fixes; also the systematic part of what
    was added (M, 3) (:meth:`~mixnav.noise.processes.NoiseProcess.sample_detail`)."""
    dp, _, bias = process.sample_detail(fixes.time, 3, rng)
    return replace(fixes, lla=displace(fixes.lla, dp)), bias


@dataclass
class Inputs:
    """The files of an ins-gnss dataset with recorded fixes, read (IMU installed; native times)."""

    imu: ImuData
    fixes: GnssFixes
    reference: Trajectory | None
    read_time_s: float


def load(ds: Dataset, source: str, folder: Path) -> Inputs:
    """Read the IMU (installation applied), the GNSS fixes and the reference."""
    t_read = _time.perf_counter()
    imu = install(read_imu(ds, folder), ds)
    all_fixes = read_gnss(ds, folder)
    reference = read_reference(ds, folder)
    return Inputs(imu, all_fixes, reference, _time.perf_counter() - t_read)


def run(ds: Dataset, source: str, folder: Path, inputs: Inputs, seed: int = 0) -> ProcessOutput:
    """Onto the run's time axis, data checks, corruption, withholding, alignment, every method
    (``seed``: unused, the methods' streams are their own)."""
    imu, all_fixes, reference, read_time = inputs.imu, inputs.fixes, inputs.reference, inputs.read_time_s
    t0 = imu.start_time
    imu = _shift(imu, t0)
    reported = _shift(all_fixes, t0)          # velocities as the file reports them
    all_fixes = delay_velocities(reported, ds.gnss.velocity_delay)
    if reference is not None:
        reference = _shift(reference, t0)
    checks = data_checks(ds, source, imu, all_fixes)
    corrupt = corruption(ds, source)
    if corrupt is not None:   # positions only: the same draw for the delayed and the reported velocities
        all_fixes, bias = _corrupt(all_fixes, corrupt, np.random.default_rng(ds.gnss.corrupt_seed))
        reported = replace(reported, lla=all_fixes.lla)
        gnss_bias = (all_fixes.time.copy(), bias)
    else:
        gnss_bias = None
    withheld = tuple(tuple(w) for w in ds.gnss.withhold)
    keep = ~in_windows(reported.time, withheld)
    # withhold first, then move the velocities to the epochs between the kept fixes only
    fixes = delay_velocities(
        GnssFixes(time=reported.time[keep], lla=reported.lla[keep], pos_sigma=reported.pos_sigma[keep],
                  vel_n=None if reported.vel_n is None else reported.vel_n[keep],
                  vel_sigma=None if reported.vel_sigma is None else reported.vel_sigma[keep],
                  source=reported.source), ds.gnss.velocity_delay)
    inst = ds.installation
    lever = np.asarray(inst.antenna_position, float) - np.asarray(inst.imu_position, float)
    init = initial_state(ds, imu, fixes, lever)
    results, aiding, filter_time = run_ins_methods(
        ds, imu, fixes, init, reference, lever, source,
        lambda: AidingInputs(ds.aiding, imu, fixes, init.time, float(imu.time[-1]),
                             odometer=read_odometer(ds, folder, t0), source=source))
    return ProcessOutput(ds, source, folder, t0, imu, fixes, all_fixes, reference, lever, results, init,
                         read_time, filter_time, aiding.summary(),
                         installation_check(imu, ds.alignment.static_duration, results, aiding.stillness,
                                            configured={"antenna_position": inst.antenna_position,
                                                        "imu_time_offset": inst.imu_time_offset}),
                         odometer=aiding.odometer, gnss_bias=gnss_bias, checks=checks)


def withheld_windows(po: ProcessOutput) -> tuple:
    """The GNSS windows withheld from the filters, ``((start, end), ...)`` [s]."""
    return tuple(tuple(w) for w in gnss_section(po.dataset)[0].withhold)


def tables(po: ProcessOutput) -> dict[str, pd.DataFrame]:
    """The solution table of every method, errors against the reference for the point it
    gives (the antenna or the IMU)."""
    ref = po.dataset.reference
    lever = po.lever if ref is not None and ref.point == "antenna" else None
    return {name: solution_table(res, po.reference, withheld_windows(po), lever=lever)
            for name, res in po.results.items()}

def metrics(po: ProcessOutput, tables: dict[str, pd.DataFrame]) -> dict[str, dict]:
    """Every method's metrics (:func:`mixnav.experiment.metrics.method_metrics`: the withheld
    windows scored apart, the injected corruption's bias)."""
    withheld = withheld_windows(po)
    return {name: method_metrics(res, tables[name], withheld, po.gnss_bias) for name, res in po.results.items()}


def truth(po: ProcessOutput) -> pd.DataFrame | None:
    """The reference trajectory as a table (None without one)."""
    return None if po.reference is None else lla_frame(po.reference.time, po.reference.lla)


def write(out_dir: Path, po: ProcessOutput, config_text: str | None = None, overwrite: bool = False,
          sweeps=()) -> dict:
    """Solutions, metrics (against the reference), figures and report of a processed INS dataset
    (the folder policy of :mod:`mixnav.io.outdir`; fixes or RINEX alike), with the ``sweeps``
    run on it (:mod:`mixnav.experiment.sweep`)."""
    withheld = withheld_windows(po)
    solutions = tables(po)
    for t in solutions.values():
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
              **({"imu_partial_lines_skipped": int(po.imu.partial_lines)} if po.imu.partial_lines else {}),
              **po.checks}
    if po.aiding:
        header["aiding"] = po.aiding
    # the IMU file's own time base: what its format stamps (docs/data_formats.md)
    base = {"drive-0708": "GPS time {:.3f} s since 1970-01-01 (no leap seconds)",
            "kf-gins": "GPS second {:.3f} of the week", "psins": "the file's start time {:.3f} s"}
    origin = base.get(po.dataset.imu.format, "time {:.3f} s of the IMU file").format(po.time_origin)
    if po.dataset.raw_gnss is not None:   # the IMU file's own GPS stamps (raw_gnss.imu_time)
        origin = (f"GPS second {po.time_origin:.3f} of the week of the first RINEX epoch"
                  if po.dataset.raw_gnss.imu_time == "gps-week-seconds" else
                  f"GPS time {po.time_origin:.3f} s since 1980-01-06")
    notes = [f"Times are seconds since the start of the first IMU increment ({origin}).",
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
    ref = None if po.reference is None else lla_frame(po.reference.time, po.reference.lla)
    return write_outputs(out_dir, f"mixnav process: {po.dataset.dataset.name}", header, po.results, solutions,
                         withheld, ref, lla_frame(po.fixes.time, po.fixes.lla), notes, config_text, po.gnss_bias,
                         command="process", overwrite=overwrite, protect=[po.source, po.data_dir],
                         sweeps=sweeps)
