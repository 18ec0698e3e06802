"""smartloc-berlin: why some track-alignment windows are biased, and what the start sweep does about it (issue 34).

Run:  PYTHONPATH=src python benchmarks/smartloc_alignment_bias.py [--data ../shared/data] [--out benchmarks/results]

A **diagnostic**: it uses the reference to find causes, never to choose a shipped value.

1. Every 20 s window starting at S = 0, 10, ..., 150 s (the shipped config, ``[alignment]
   start = S``): the window fit's error at the window's end (2-D, heading, height above the
   reference), the satellites whose mean LOS responsibility is >= 0.5, the fit's own
   1-sigma (its information matrix with the LOS rows' correlation factor, the one the
   filter gets), the spread of the height over leave-one-5-s-block-out refits
   (jackknife), and the fit's log-likelihood at its maximum against the best fit with
   position and heading held at the reference's (the dead-reckoned track turned and
   shifted onto the reference). Then the same fit with the height held at the
   reference's (an oracle height): does the height bias the horizontal fit?
2. The window at 140 s satellite by satellite: the mean residual and LOS responsibility
   of each in the free fit and in the fit held at the reference.
3. The epoch mixture's start sweep (S = 0, 30, ..., 150 s; RMSE from each filter start)
   with the window fit's height held at the reference (oracle), and with the handed-over
   start sigmas widened or narrowed, each with the data-alone criterion of
   ``smartloc_choose_settings.py`` (innovation log-likelihood, rows from S + 40 s) beside.
4. The runs from 0 s and 120 s over 140-190 s: north error and heading.

The held fits run ``mixnav.alignment.track._refine`` with its ``prior``, a Gaussian
pseudo-observation on chosen components of the fit's parameters (``_refine_held``). Writes ``smartloc_alignment_bias.md`` and ``.json`` into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import time
import warnings
from pathlib import Path

import numpy as np

import mixnav.alignment.track as T
import mixnav.experiment.vehicle_process as VP
from mixnav.config.loader import load_dataset
from mixnav.experiment.data_folder import find_data_dir
from mixnav.experiment.vehicle_process import discard_before, read_vehicle, run_vehicle, vehicle_tables
from mixnav.filters.epoch_mixture import EpochMixtureEstimator
from mixnav.geodesy.frames import lla_to_ned

from smartloc_choose_settings import _LOG, _logged_update  # each epoch's innovation log-likelihood

SWEEP = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0)
WINDOWS = tuple(float(s) for s in range(0, 160, 10))
WINDOW = 20.0

#: what the patched fit does: "hold" {index: (value or f(lla_ref), sigma)}; every fit's
#: final state is appended to "fits"
HOLD: dict = {}
_orig_refine = T._refine


def _refine_held(theta0, lla_ref, tq, sat, rho, var, sidx, n_sys, track, iterations=30, band=None):
    """``track._refine`` with the components in ``HOLD["hold"]`` held near given values (its
    ``prior``), every fit's final state appended to ``HOLD["fits"]``."""
    hold = {k: (v(lla_ref) if callable(v) else v, sg) for k, (v, sg) in HOLD.get("hold", {}).items()}
    band = np.zeros(len(rho), dtype=np.int64) if band is None else band

    def record(fit):
        HOLD.setdefault("fits", []).append({**fit, "lla_ref": np.array(lla_ref), "tq": tq, "rho": rho, "sat": sat,
                                            "sidx": sidx, "band": band, "n_sys": n_sys, "track": track})
    return _orig_refine(theta0, lla_ref, tq, sat, rho, var, sidx, n_sys, track, iterations, band,
                        prior=hold, record=record)


class Drive:
    def __init__(self, data=None):
        ds, self.source, _ = load_dataset("smartloc-berlin")
        self.ds = ds
        self.folder = find_data_dir(ds, data, self.source)
        self.inputs = read_vehicle(ds, self.source, self.folder)
        self.ref = self.inputs.reference
        self.t0 = float(self.inputs.inc.time[0] - self.inputs.inc.dt[0])
        self.systems = tuple(VP.SYSTEM_CODES[s] for s in ds.pseudoranges.systems)
        self.edges = tuple(ds.alignment.cn0_edges)

    def align(self, s: float):
        cut = discard_before(self.inputs, s)
        inc = cut.inc
        HOLD.pop("fits", None)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            init, rep = T.align_track(cut.epochs, inc, float(inc.time[0] - inc.dt[0] + WINDOW), systems=self.systems,
                                      cn0_edges=self.edges)
        best = max(HOLD["fits"], key=lambda f: f["ll"])
        return init, rep, cut, best

    def truth_fit(self, cut, lla_ref):
        """The fit's p0 (north, east in lla_ref's frame), heading psi0 and the reference's median
        height over the window: the dead-reckoned track turned and shifted onto the reference."""
        inc = cut.inc
        t0 = float(inc.time[0] - inc.dt[0])
        dn, de, _ = T.dead_reckon(inc)
        tt = np.concatenate([[t0], inc.time])
        dn, de = np.r_[0.0, dn], np.r_[0.0, de]
        sel = (self.ref.time >= t0) & (self.ref.time <= t0 + WINDOW)
        p = lla_to_ned(self.ref.lla[sel], lla_ref)[:, :2]
        d = np.stack([np.interp(self.ref.time[sel], tt, dn), np.interp(self.ref.time[sel], tt, de)], 1)
        mp, md = p.mean(0), d.mean(0)
        M = (d - md).T @ (p - mp)
        ang = math.atan2(M[0, 1] - M[1, 0], M[0, 0] + M[1, 1])
        R = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
        return mp - R @ md, ang, float(np.median(self.ref.lla[sel, 2]))

    def errors(self, init):
        """2-D error [m], heading error [deg], height above the reference [m] of a start."""
        i = int(np.argmin(abs(self.ref.time - init.time)))
        j = min(i + 5, len(self.ref.time) - 1)
        dd = lla_to_ned(self.ref.lla[j][None], self.ref.lla[i])[0]
        h_true = math.degrees(math.atan2(dd[1], dd[0]))
        d = lla_to_ned(init.nav[7:10][None], self.ref.lla[i])[0]
        hd = 2 * math.degrees(math.atan2(init.nav[3], init.nav[0]))
        return math.hypot(d[0], d[1]), ((hd - h_true + 180) % 360) - 180, -d[2]


def window_table(D: Drive) -> tuple[list[dict], list[dict]]:
    rows, sats140 = [], []
    for s in WINDOWS:
        HOLD.clear()
        init, rep, cut, best = D.align(s)
        err, dpsi, up = D.errors(init)
        lla_ref = best["lla_ref"]
        p0, ang, h_ref = D.truth_fit(cut, lla_ref)
        tau = rep["los_correlation_time_s"]
        rho_c = math.exp(-0.2 / tau) if tau > 0 else 0.0
        infl = (1 + rho_c) / (1 - rho_c)
        g, var, A, th = best["g"], best["var"], best["A"], best["theta"]
        # the fit's own covariance (LOS information on the given variances times los_scale,
        # delayed rows on sd^2), times the correlation factor; mapped to the window's end
        wt = g / (rep["los_scale"] * var) + (1 - g) / best["sd"] ** 2
        P = infl * np.linalg.inv(A.T @ (A * wt[:, None]) + 1e-9 * np.eye(len(th)))
        dn_e, de_e = best["track"](np.array([best["tq"].min() + WINDOW]))
        c, sn = math.cos(th[3]), math.sin(th[3])
        J = np.zeros((3, len(th)))
        J[0, 0] = J[1, 1] = J[2, 3] = 1.0
        J[0, 3], J[1, 3] = -sn * dn_e[0] - c * de_e[0], c * dn_e[0] - sn * de_e[0]
        Pe = J @ P @ J.T
        # satellites likelier LOS than not over the window
        _, _, _, _, _, cn0, key = T._window_rows(cut.epochs, float(cut.inc.time[0] - cut.inc.dt[0]),
                                                 float(cut.inc.time[0] - cut.inc.dt[0]) + WINDOW,
                                                 {k: i for i, k in enumerate(D.systems)})
        n_los = int(sum(g[key == k].mean() >= 0.5 for k in np.unique(key)))
        # height jackknife: leave one 5 s block out, refit from the best fit
        blk = np.minimum(((best["tq"] - best["tq"].min()) / 5.0).astype(int), 3)
        hs = []
        for b in range(4):
            m = blk != b
            HOLD["fits"] = []
            t_b = _refine_held(th, lla_ref, best["tq"][m], best["sat"][m], best["rho"][m], var[m], best["sidx"][m],
                               best["n_sys"], best["track"], band=best["band"][m])[0]
            hs.append(t_b[2])
        hs = np.array(hs)
        jk_h = math.sqrt(3.0 / 4.0 * ((hs - hs.mean()) ** 2).sum())
        # held at the reference: position and heading (the likelihood there), height only (oracle height)
        HOLD.clear()
        HOLD["hold"] = {0: (p0[0], 0.01), 1: (p0[1], 0.01), 3: (ang, 1e-4), 2: (lambda l, h=h_ref: l[2] - h, 0.01)}
        _, _, _, anch = D.align(s)
        oracle = []
        for dh in (0.0, D.height_offset):
            HOLD.clear()
            HOLD["hold"] = {2: (lambda l, h=h_ref + dh: l[2] - h, 0.01)}
            init_h, _, _, _ = D.align(s)
            oracle.append(D.errors(init_h)[:2])
        HOLD.clear()
        rows.append({"start_s": s, "err_2d_m": err, "heading_err_deg": dpsi, "height_above_ref_m": up,
                     "los_satellites": n_los, "satellites": int(len(np.unique(key))),
                     "fit_sigma_2d_m": math.sqrt(Pe[0, 0] + Pe[1, 1]), "fit_sigma_heading_deg": math.degrees(
                         math.sqrt(Pe[2, 2])), "correlation_factor": infl, "height_jackknife_sd_m": jk_h,
                     "log_likelihood": best["ll"], "log_likelihood_at_reference": anch["ll"],
                     "oracle_height_err_2d_m": oracle[0][0], "oracle_height_heading_err_deg": oracle[0][1],
                     "oracle_height_plus_offset_err_2d_m": oracle[1][0],
                     "oracle_height_plus_offset_heading_err_deg": oracle[1][1]})
        if s == 140.0:
            u = best["u"]
            az = np.degrees(np.arctan2(u[:, 1], u[:, 0])) % 360
            el = np.degrees(np.arcsin(-u[:, 2]))
            for k in np.unique(key):
                m = key == k
                sats140.append({"satellite": str(int(k)),
                                "rows": int(m.sum()), "azimuth_deg": float(np.median(az[m])),
                                "elevation_deg": float(np.median(el[m])), "cn0_dbhz": float(np.nanmedian(cn0[m])),
                                "free_mean_residual_m": float(best["e"][m].mean()), "free_los": float(g[m].mean()),
                                "held_mean_residual_m": float(anch["e"][m].mean()), "held_los": float(anch["g"][m].mean())})
    return rows, sats140


def sweep(D: Drive, method_options=None, alignment=None, oracle_height=None) -> dict:
    """The epoch mixture from each start of SWEEP: RMSE from its start and the criterion."""
    m = next(x for x in D.ds.methods if x.name == "epoch-mixture")
    if method_options:
        m = m.model_copy(update={"options": {**m.options, **method_options}})
    out = {}
    for s in SWEEP:
        al = D.ds.alignment.model_copy(update={"start": s, **(alignment or {})})
        d = D.ds.model_copy(update={"alignment": al, "methods": [m]})
        HOLD.clear()
        if oracle_height is not None:
            cut = discard_before(D.inputs, s)
            t0 = float(cut.inc.time[0] - cut.inc.dt[0])
            sel = (D.ref.time >= t0) & (D.ref.time <= t0 + WINDOW)
            h = float(np.median(D.ref.lla[sel, 2])) + oracle_height
            HOLD["hold"] = {2: (lambda l, h=h: l[2] - h, 0.01)}
        _LOG.clear()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            vo = run_vehicle(d, D.source, D.folder, D.inputs)
        HOLD.clear()
        tabs = vehicle_tables(vo)
        t = tabs["epoch-mixture"]
        e = np.hypot(t["err_n_m"], t["err_e_m"]).to_numpy()
        lg = np.array(_LOG)
        out[s] = {"rmse_m": float(np.sqrt(np.mean(e ** 2))),
                  "log_likelihood": float(lg[lg[:, 0] - D.t0 > s + 40.0, 1].sum()), "table": t,
                  "smoothed": tabs.get("epoch-mixture-smoothed")}
    r = [out[s]["rmse_m"] for s in SWEEP]
    return {"rmse_m": r, "median_m": float(np.median(r)), "worst_m": float(max(r)),
            "log_likelihood": float(sum(out[s]["log_likelihood"] for s in SWEEP)),
            "tables": {s: out[s]["table"] for s in SWEEP}, "smoothed": out[SWEEP[0]]["smoothed"]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    a = ap.parse_args(argv)
    t_wall = time.perf_counter()
    T._refine = _refine_held

    EpochMixtureEstimator.update = _logged_update(EpochMixtureEstimator.update)
    D = Drive(a.data)
    shipped = sweep(D)
    # the height the pseudoranges put the car at, relative to the reference: the smoothed
    # epoch mixture's median height above the reference over the drive from 0 s
    D.height_offset = float(np.median(-shipped["smoothed"]["err_d_m"].to_numpy()))
    rows, sats = window_table(D)
    variants = [("shipped (height free in the window fit)", shipped),
                ("window fit's height held at the reference's (oracle)", sweep(D, oracle_height=0.0)),
                (f"... at the reference's + {D.height_offset:.1f} m", sweep(D, oracle_height=D.height_offset))]
    sig = []
    for ps in (5.0, 10.0, 20.0, 40.0):
        for hs in (3.0, 6.0, 12.0, 24.0):
            r = shipped if (ps, hs) == (10.0, 6.0) else sweep(
                D, alignment={"position_sigma": ps, "heading_sigma": math.radians(hs)})
            sig.append((ps, hs, r))
    elapsed = time.perf_counter() - t_wall

    L = ["# smartLoc Berlin: the biased track-alignment windows (issue 34)", "",
         f"Produced by `benchmarks/smartloc_alignment_bias.py` ({platform.machine()}, Python "
         f"{platform.python_version()}; {elapsed:.0f} s), the shipped `smartloc-berlin` config (C/N0 bands "
         f"{list(D.edges)}). A diagnostic: the reference finds causes here, it chooses nothing. Numbers: the `.json`.",
         "", "## 1. The 20 s window fit from each start", "",
         "At the window's end: 2-D error, heading error, height above the reference. LOS satellites: mean LOS "
         "responsibility >= 0.5 over the window (of all). Fit 1-sigma: the fit's information matrix times the "
         "LOS rows' correlation factor (shown). Height jackknife: leave-one-5-s-block-out refits. Log-likelihood: "
         "the fit's maximum, and its best with position, heading and height held at the reference's. Oracle "
         "height: the fit with its height held at the reference's, and at the reference's + "
         f"{D.height_offset:.1f} m (the smoothed epoch mixture's median height above the reference over the drive "
         "from 0 s: where the pseudoranges put the car). EM starts from the held height there, from the median "
         "height of the window's Huber fixes otherwise.", "",
         "| start [s] | 2-D err [m] | heading err [deg] | height above ref [m] | LOS sats | fit 1-sigma 2-D [m] / "
         "heading [deg] | corr. factor | height jackknife sd [m] | log-lik. max / at reference | oracle height: 2-D "
         "err [m] / heading err [deg] | oracle height + offset: 2-D err / heading err |",
         "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        L.append(f"| {r['start_s']:g} | {r['err_2d_m']:.1f} | {r['heading_err_deg']:+.1f} | "
                 f"{r['height_above_ref_m']:.1f} | {r['los_satellites']} of {r['satellites']} | "
                 f"{r['fit_sigma_2d_m']:.1f} / {r['fit_sigma_heading_deg']:.1f} | {r['correlation_factor']:.0f} | "
                 f"{r['height_jackknife_sd_m']:.0f} | {r['log_likelihood']:.0f} / {r['log_likelihood_at_reference']:.0f} | "
                 f"{r['oracle_height_err_2d_m']:.1f} / {r['oracle_height_heading_err_deg']:+.1f} | "
                 f"{r['oracle_height_plus_offset_err_2d_m']:.1f} / {r['oracle_height_plus_offset_heading_err_deg']:+.1f} |")
    L += ["", "## 2. The window at 140 s, satellite by satellite", "",
          "Mean residual [m] and mean LOS responsibility of each satellite's rows: the free fit (its maximum) and "
          "the fit held at the reference's position, heading and height. Satellite: system code x 1000 + number "
          "(1: GPS, 4: GLONASS).", "",
          "| satellite | rows | azimuth [deg] | elevation [deg] | C/N0 [dB-Hz] | free: mean residual / LOS | held at "
          "reference: mean residual / LOS |", "|---|---|---|---|---|---|---|"]
    for r in sats:
        L.append(f"| {r['satellite']} | {r['rows']} | {r['azimuth_deg']:.0f} | {r['elevation_deg']:.0f} | "
                 f"{r['cn0_dbhz']:.0f} | {r['free_mean_residual_m']:.1f} / {r['free_los']:.2f} | "
                 f"{r['held_mean_residual_m']:.1f} / {r['held_los']:.2f} |")
    L += ["", "## 3. The start sweep's epoch mixture", "",
          "2-D RMSE from each filter start [m]; the criterion of `smartloc_choose_settings.py` (innovation "
          "log-likelihood, rows from S + 40 s, summed over the starts) beside.", "",
          "| variant | criterion | " + " | ".join(f"{s:g} s" for s in SWEEP) + " | median | worst |",
          "|---|---|" + "---|" * (len(SWEEP) + 2)]
    for name, v in variants:
        L.append(f"| {name} | {v['log_likelihood']:.0f} | " + " | ".join(f"{x:.2f}" for x in v["rmse_m"])
                 + f" | {v['median_m']:.2f} | {v['worst_m']:.2f} |")
    L += ["", "Start sigmas handed to the filters (`position_sigma`, `heading_sigma`; shipped 10 m, 6 deg):", "",
          "| position [m] | heading [deg] | criterion | " + " | ".join(f"{s:g} s" for s in SWEEP)
          + " | median | worst |", "|---|---|---|" + "---|" * (len(SWEEP) + 2)]
    for ps, hs, v in sig:
        L.append(f"| {ps:g} | {hs:g} | {v['log_likelihood']:.0f} | " + " | ".join(f"{x:.2f}" for x in v["rmse_m"])
                 + f" | {v['median_m']:.2f} | {v['worst_m']:.2f} |")
    L += ["", "## 4. The shipped runs from 0 s and from 120 s over 140-190 s", "",
          "North error [m] and heading [deg] (the road runs east from about 140 s).", "",
          "| time [s] | from 0 s: north err / heading | from 120 s: north err / heading |", "|---|---|---|"]
    t0s, t120 = shipped["tables"][0.0], shipped["tables"][120.0]
    series = {}
    for t in range(140, 195, 5):
        cells = []
        for tab in (t0s, t120):
            tt = tab["time_s"].to_numpy() - D.t0
            i = int(np.searchsorted(tt, t))
            cells.append((float(tab["err_n_m"].iloc[i]), float(tab["yaw_deg"].iloc[i])))
        series[t] = cells
        L.append(f"| {t} | {cells[0][0]:.1f} / {cells[0][1]:.0f} | {cells[1][0]:.1f} / {cells[1][1]:.0f} |")
    L.append("")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    strip = (lambda v: {k: x for k, x in v.items() if k not in ("tables", "smoothed")})
    (out / "smartloc_alignment_bias.json").write_text(json.dumps(
        {"height_offset_m": D.height_offset, "windows": rows, "satellites_140s": sats, "sweep": {n: strip(v) for n, v in variants},
         "start_sigmas": [{"position_sigma_m": p, "heading_sigma_deg": h, **strip(v)} for p, h, v in sig],
         "runs_140_190s": {str(k): v for k, v in series.items()}}, indent=1))
    (out / "smartloc_alignment_bias.md").write_text("\n".join(L) + "\n")
    print("\n".join(L))


if __name__ == "__main__":
    main()
