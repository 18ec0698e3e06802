"""``mixnav process`` for ``dataset.kind = "gnss-raw"``: epoch-by-epoch SPP of raw GNSS.

Steps: read the raw measurement log (:mod:`mixnav.io.android`) and the RINEX
navigation file (:mod:`mixnav.gnss.ephemeris`), solve every epoch by WLS
(:mod:`mixnav.gnss.spp`), and score the solutions against the surveyed
static point of ``[reference_point]``: north, east, down errors, their RMS,
maximum and 95th percentile, and the position NEES with the WLS covariance.
Epochs without a solution are counted by status, never raised.

Times in the solution table are seconds since the first epoch; the first
epoch's GPS week and seconds of week are in metrics.json.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .. import __version__
from ..config.dataset_schema import Dataset
from ..geodesy.frames import dcm_ecef_to_ned, ecef_to_lla, lla_to_ecef
from ..errors import DataError
from ..gnss.ephemeris import BroadcastEphemeris
from ..gnss.spp import SppOptions, SppTrack, solve_epochs
from ..io import android
from ..io.atomic import atomic_write_dataframe, atomic_write_json
from . import figures
from .report import write_report

METHOD = "spp"


@dataclass
class SppOutput:
    dataset: Dataset
    source: str
    data_dir: Path
    observations: object               # android.AndroidPseudoranges or rinex_obs.RinexPseudoranges
    ephemeris: BroadcastEphemeris
    track: SppTrack
    reference_lla: np.ndarray | None   # (3,) rad, rad, m
    read_time_s: float
    solve_time_s: float


def options(ds: Dataset) -> SppOptions:
    c = ds.raw_gnss
    return SppOptions(elevation_mask=c.elevation_mask, sigma_a=c.sigma_a, sigma_b=c.sigma_b,
                      troposphere=c.troposphere, ionosphere=c.ionosphere)


def process_raw(ds: Dataset, source: str, folder: Path) -> SppOutput:
    """Read the raw log and the navigation file, and solve every epoch."""
    c = ds.raw_gnss
    t0 = _time.perf_counter()
    if c.format == "rinex-obs":
        from ..io.rinex_obs import read_rinex_obs
        obs = read_rinex_obs(folder / c.file)
    else:
        obs = android.read_gnsslogger(folder / c.file,
                                      max_sv_time_uncertainty_ns=c.max_sv_time_uncertainty * 1e9)
    eph = BroadcastEphemeris.from_rinex(folder / c.navigation)
    if c.ionosphere and eph.iono_alpha is None:   # asked for, and impossible: said, not silent
        import warnings
        from ..io.imu_checks import DataWarning
        warnings.warn(f"{folder / c.navigation}: the header has no ionosphere (Klobuchar) coefficients, so the "
                      "ionosphere correction is skipped and every pseudorange keeps its 2-10 m delay "
                      "(metrics.json: ionosphere)", DataWarning, stacklevel=2)
    t1 = _time.perf_counter()
    track = solve_epochs(eph, obs.week, obs.tow, obs.epoch, obs.prn, obs.pseudorange, options(ds))
    t2 = _time.perf_counter()
    rp = ds.reference_point
    ref = None if rp is None else np.array([rp.latitude, rp.longitude, rp.height])
    return SppOutput(ds, source, folder, obs, eph, track, ref, t1 - t0, t2 - t1)


def ionosphere_applied(po: SppOutput) -> str:
    """``"klobuchar"`` (applied), ``"off"`` (``raw_gnss.ionosphere = false``) or ``"skipped"``
    (asked for, but the navigation header has no Klobuchar coefficients; warned)."""
    if not po.dataset.raw_gnss.ionosphere:
        return "off"
    return "klobuchar" if po.ephemeris.iono_alpha is not None else "skipped"


def solution_table(po: SppOutput) -> pd.DataFrame:
    """One row per epoch (NaN where the epoch has no solution)."""
    tr = po.track
    lla = np.full((len(tr.tow), 3), np.nan)
    ok = tr.ok
    if ok.any():
        lla[ok] = ecef_to_lla(tr.pos_ecef[ok])
    t_abs = tr.week * 604800.0 + tr.tow
    df = pd.DataFrame({"time_s": t_abs - t_abs[0], "gps_week": tr.week, "gps_tow_s": tr.tow,
                       "lat_deg": np.degrees(lla[:, 0]), "lon_deg": np.degrees(lla[:, 1]), "height_m": lla[:, 2],
                       "clock_bias_m": tr.clock_bias, "n_sat": tr.n_sat, "pdop": tr.pdop, "hdop": tr.hdop,
                       "vdop": tr.vdop, "rms_residual_m": tr.rms_residual, "status": tr.status})
    if po.reference_lla is not None:
        ref = po.reference_lla
        C_ne = dcm_ecef_to_ned(ref[0], ref[1])
        err = (tr.pos_ecef - lla_to_ecef(ref)) @ C_ne.T               # estimate minus reference, NED
        cov_ned = np.einsum("ij,kjl,ml->kim", C_ne, tr.cov[:, :3, :3], C_ne)
        for j, ax in enumerate("ned"):
            df[f"err_{ax}_m"] = err[:, j]
        for j, ax in enumerate("ned"):
            df[f"sig_{ax}_m"] = np.sqrt(cov_ned[:, j, j])
        nees = np.full(len(tr.tow), np.nan)
        if ok.any():
            nees[ok] = np.einsum("ki,ki->k", err[ok], np.linalg.solve(cov_ned[ok], err[ok][..., None])[..., 0])
        df["nees_pos"] = nees
    return df


def spp_metrics(table: pd.DataFrame, solve_time_s: float) -> dict:
    """Accuracy of the solved epochs against the reference point (keys in docs/outputs.md)."""
    ok = (table["status"] == "ok").to_numpy()
    m: dict = {"n_epochs": int(ok.sum()),
               "epoch_time_mean_us": 1e6 * solve_time_s / max(len(table), 1),
               "n_sat_mean": float(table["n_sat"][ok].mean()) if ok.any() else float("nan"),
               "pdop_median": float(table["pdop"][ok].median()) if ok.any() else float("nan"),
               "residual_rms_median_m": float(table["rms_residual_m"][ok].median()) if ok.any() else float("nan")}
    if "err_n_m" in table and ok.any():
        e = table.loc[ok, ["err_n_m", "err_e_m", "err_d_m"]].to_numpy(dtype=float)
        h = np.hypot(e[:, 0], e[:, 1])
        v = np.abs(e[:, 2])
        m.update({"horizontal_rmse_m": float(np.sqrt(np.mean(h**2))), "horizontal_max_m": float(h.max()),
                  "horizontal_p95_m": float(np.percentile(h, 95)),
                  "vertical_rmse_m": float(np.sqrt(np.mean(v**2))), "vertical_max_m": float(v.max()),
                  "vertical_p95_m": float(np.percentile(v, 95)),
                  "mean_error_ned_m": [float(x) for x in e.mean(0)],
                  "nees_pos_mean": float(table["nees_pos"][ok].mean())})
    return m


def write_raw(out_dir: Path, po: SppOutput, config_text: str | None = None, overwrite: bool = False) -> dict:
    """Solution table (CSV + Parquet), metrics.json, figures and report of an SPP run
    (the folder policy of :mod:`mixnav.io.outdir`, as ``mixnav process``)."""
    from ..io.outdir import staged_output
    with staged_output(out_dir, "process", overwrite, [po.source, po.data_dir]) as folder:
        return _write_raw(folder.path, po, config_text)


def _write_raw(out_dir: Path, po: SppOutput, config_text: str | None) -> dict:
    table = solution_table(po)
    tr = po.track
    counts = tr.status_counts()
    empty = int(getattr(po.observations, "epochs_all_rejected", 0))
    if empty:   # epochs the reader dropped whole: every measurement rejected (counted, not vanished)
        counts = {**counts, "all measurements rejected": empty}
    used = counts.get("ok", 0)
    if used == 0:   # nothing to score or show: refused rather than a folder of NaNs
        raise DataError(f"no epoch could be solved (status counts: {counts}); does the navigation file cover "
                        "the log's time and satellites?", file=po.observations.source)
    duration = float(table["time_s"].iloc[-1]) if len(table) else 0.0
    metrics: dict = {
        "dataset": po.dataset.dataset.name, "kind": po.dataset.dataset.kind, "source": po.source,
        "data_dir": str(po.data_dir), "mixnav_version": __version__,
        "gps_week_start": int(tr.week[0]), "gps_tow_start_s": float(tr.tow[0]),
        "duration_s": duration, "read_time_s": po.read_time_s, "filter_time_s": po.solve_time_s,
        "real_time_factor": duration / max(po.read_time_s + po.solve_time_s, 1e-9),
        "epochs_total": len(table) + empty, "epochs_used": used, "epochs_skipped": len(table) + empty - used,
        "epoch_status": counts, "satellites_skipped": dict(tr.skipped_satellites),
        "measurements_rejected": dict(po.observations.rejected),
        "reference_point": None if po.reference_lla is None else
        {"lat_deg": float(np.degrees(po.reference_lla[0])), "lon_deg": float(np.degrees(po.reference_lla[1])),
         "height_m": float(po.reference_lla[2])},
        "ionosphere": ionosphere_applied(po),
        "methods": {METHOD: spp_metrics(table, po.solve_time_s)},
    }
    atomic_write_dataframe(out_dir / f"solution_{METHOD}.csv", table)
    atomic_write_dataframe(out_dir / f"solution_{METHOD}.parquet", table)
    ok = table[table["status"] == "ok"]
    figs = {}
    if "err_n_m" in table:
        figs["horizontal_error"] = figures.horizontal_error_figure({METHOD: ok})
    ref = None
    if po.reference_lla is not None:
        ref = pd.DataFrame({"time_s": [0.0], "lat_deg": [np.degrees(po.reference_lla[0])],
                            "lon_deg": [np.degrees(po.reference_lla[1])], "height_m": [po.reference_lla[2]]})
    if len(ok):
        figs["trajectory"] = figures.trajectory_figure({METHOD: ok}, ref)
    opts = options(po.dataset)
    iono = {"klobuchar": "Klobuchar (broadcast coefficients)", "off": "none (switched off)",
            "skipped": "none: the navigation header has no coefficients"}[ionosphere_applied(po)]
    notes = [f"Single-point positioning, GPS L1 C/A pseudoranges, {used} of {len(table)} epochs solved "
             f"(status counts: {counts}).",
             f"Elevation mask {np.degrees(opts.elevation_mask):.1f} deg; sigma = sqrt({opts.sigma_a:g}^2 + "
             f"{opts.sigma_b:g}^2 / sin^2(el)) m; troposphere: {'Saastamoinen' if opts.troposphere else 'none'}; "
             f"ionosphere: {iono}.",
             "Errors are estimate minus the surveyed point, in NED at that point; times are seconds since "
             f"the first epoch (GPS week {int(tr.week[0])}, {float(tr.tow[0]):.3f} s of week).",
             f"Measurements rejected by the reader: {po.observations.rejected or 'none'}; satellites "
             f"left out: {tr.skipped_satellites or 'none'}."]
    write_report(out_dir, f"mixnav process: {po.dataset.dataset.name}", metrics, figs, notes=notes,
                 config_text=config_text)
    atomic_write_json(out_dir / "metrics.json", metrics)       # last: marks a complete folder
    return metrics
