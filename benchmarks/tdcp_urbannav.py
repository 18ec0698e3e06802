"""TDCP in the GNSS-only filters on urbannav-tst-static: the shipped constant-velocity filters
with pseudoranges alone (as `mixnav process` runs them) beside the same filters with the
file's carrier as TDCP (measurements/tdcp_pseudorange.PseudorangeTdcp, cycle slips from
gnss/cycle_slips.py).

    python benchmarks/tdcp_urbannav.py [--carrier-sigma 0.003]

The shipped dataset (src/mixnav/config/datasets/urbannav-tst-static.toml: GPS, GLONASS,
Galileo, BeiDou, 15 deg mask, its [motion] noise, its methods) is solved by the pipeline
(mixnav.experiment.spp_process.solve_raw). The TDCP runs rebuild the pipeline's filter inputs
(the same corrected pseudoranges, start, layout, motion and clock noise: the lines of
spp_process.run_filters, repeated here) and add the carrier of each pseudorange row with its
corrections (gnss.cycle_slips.carrier_of_rows), told ``carrier_sigma`` (default 3 mm, the
scenarios' value; not tuned on this file). Only the estimators that carry a stochastic clone
run TDCP (ekf, robust-adaptive, gaussian-mixture, student-t); the others are listed as not
run. Scored as the pipeline scores: horizontal error against the surveyed point at every
one of the 986 epochs (an epoch before the first fix counts as unsolved), RMSE, median,
95th percentile, and the availability. Writes benchmarks/results/tdcp_urbannav.md and its numbers as
tdcp_urbannav.json.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from mixnav.config.loader import load_dataset
from mixnav.errors import ArgumentError
from mixnav.experiment.methods import run_methods
from mixnav.experiment.spp_process import (_epoch_times, filter_systems, filter_table, options,
                                           read_raw, solve_raw)
from mixnav.geodesy.frames import lla_to_ecef
from mixnav.gnss.cycle_slips import REASONS, carrier_of_rows, slips_of_observations, static_tdcp_residuals
from mixnav.gnss.pseudoranges import SYSTEM_LETTERS
from mixnav.ins.error_model import ClockModel
from mixnav.measurements.tdcp_pseudorange import PseudorangeTdcp
from mixnav.motion.constant_velocity import (ConstantVelocityMotion, ConstantVelocityNoise, clock_ticks,
                                             constant_velocity_layout)

ROOT = Path(__file__).resolve().parents[1]


def horizontal(table) -> tuple[float, float, float, int]:
    h = np.hypot(table["err_n_m"].to_numpy(), table["err_e_m"].to_numpy())
    ok = np.isfinite(h)
    return (float(np.sqrt(np.mean(h[ok] ** 2))), float(np.median(h[ok])), float(np.percentile(h[ok], 95)),
            int(ok.sum()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--carrier-sigma", type=float, default=0.003)
    a = ap.parse_args()
    ds, source, _ = load_dataset("urbannav-tst-static")
    folder = (ROOT / ds.dataset.data_dir).resolve()
    obs, eph, read_s = read_raw(ds, source, folder)
    t0 = time.perf_counter()
    po = solve_raw(ds, source, folder, obs, eph, read_s)
    shipped_s = time.perf_counter() - t0
    tr, mc = po.track, ds.motion
    times = _epoch_times(tr)
    epochs, init, offset = po.epochs, po.init, po.clock_offset
    rho = np.asarray(obs.pseudorange, float) - offset[np.asarray(obs.epoch, int)]
    epoch_of = np.searchsorted(times, epochs.time - 1e-6)
    slips = slips_of_observations(obs)
    carrier, cont, src = carrier_of_rows(obs, epochs, rho, epoch_of, slips)
    codes = {v: k for k, v in SYSTEM_LETTERS.items()}
    letters = filter_systems(tr)
    lay = constant_velocity_layout(clock=True, system_offsets=len(letters) - 1)
    model = PseudorangeTdcp(epochs, carrier, cont, lay, systems=tuple(codes[s] for s in letters),
                            variance="given", elevation_mask=options(ds).elevation_mask, sigma_cp=a.carrier_sigma)
    noise = ConstantVelocityNoise(float(mc.accel_sigma), float(mc.vertical_accel_sigma))
    clock = ClockModel(float(mc.clock_q_bias), float(mc.clock_q_drift))
    ticks = clock_ticks(init.time, float(times[-1]), float(mc.step))
    out_t = times[times > init.time]
    filters = [(k, m) for k, m in enumerate(ds.run_methods()) if m.estimator != "wls"]
    with_tdcp, not_run = {}, {}
    w0, c0 = time.perf_counter(), time.process_time()
    for k, m in filters:
        plain = m.model_copy(update={"smooth": False})
        try:
            res = run_methods([(k, plain)], lambda: ConstantVelocityMotion(lay, noise, clock), [model], ticks, init,
                              out_t, source, 0, motion="constant-velocity")[m.name]
            with_tdcp[m.name] = res
        except ArgumentError as exc:
            not_run[m.name] = str(exc)
    tdcp_wall, tdcp_cpu = time.perf_counter() - w0, time.process_time() - c0
    n_pairs = sum(0 if (p := model.tdcp_pairs(i, _Prev(i - 1))) is None else len(p[0]) for i in range(1, len(epochs)))
    lines = ["# TDCP in the GNSS-only filters: urbannav-tst-static", "",
             f"Generated by `benchmarks/tdcp_urbannav.py` on {datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC')} "
             f"({platform.python_version()}). Dataset: the shipped `urbannav-tst-static.toml` (systems "
             f"{', '.join(letters)}; [motion] accel_sigma {float(mc.accel_sigma):g} m/s^2/sqrt(Hz), a static "
             f"receiver's). TDCP: carrier sigma {1e3 * a.carrier_sigma:g} mm (the scenarios' value, not tuned here), "
             f"rows only across continuous carriers (gnss/cycle_slips.py defaults); {n_pairs} TDCP pairs available "
             f"over {len(epochs)} epochs. Horizontal error against the surveyed point, all {len(times)} epochs "
             "(unsolved epochs counted in the availability).", "",
             "| method | TDCP | RMSE [m] | median [m] | 95 % [m] | epochs solved |",
             "|---|---|---|---|---|---|"]
    record = {"epochs": len(times), "tdcp_pairs": int(n_pairs), "carrier_sigma_m": a.carrier_sigma,
              "filters": {}, "carrier": {"continuous": {}, "flagged": {}}}

    def row(table) -> dict:
        rmse, med, p95, n = horizontal(table)
        return {"rmse_m": rmse, "median_m": med, "p95_m": p95, "epochs_solved": n}

    for name, res in po.results.items():
        record["filters"][name] = {"without_tdcp": row(filter_table(po, res))}
        rmse, med, p95, n = horizontal(filter_table(po, res))
        lines.append(f"| {name} | no | {rmse:.2f} | {med:.2f} | {p95:.2f} | {n}/{len(times)} |")
        if name in with_tdcp:
            record["filters"][name]["with_tdcp"] = row(filter_table(po, with_tdcp[name]))
            rmse, med, p95, n = horizontal(filter_table(po, with_tdcp[name]))
            lines.append(f"| {name} | yes | {rmse:.2f} | {med:.2f} | {p95:.2f} | {n}/{len(times)} |")
    # the carrier itself, without a filter: TDCP less the range change from the surveyed point
    # and each epoch's clock change (median of its continuous pairs)
    rp = ds.reference_point
    point = lla_to_ecef(np.array([rp.latitude, rp.longitude, rp.height]))
    r_i, _, d = static_tdcp_residuals(epochs, carrier, point, cont)
    lines += ["", "## The carrier against the surveyed point", "",
              "TDCP of consecutive epochs less the range change from the surveyed antenna and less the "
              "epoch's clock change (median over its continuous pairs): noise, multipath and any slip "
              "(`gnss.cycle_slips.static_tdcp_residuals`; the filters' rows, 15 deg mask).", "",
              "| pairs | system | count | 1.4826 MAD [mm] | 95 % abs [mm] | max abs [mm] | above 9 cm (half a cycle) |",
              "|---|---|---|---|---|---|---|"]
    sysl = np.array([SYSTEM_LETTERS[int(c)] for c in epochs.system[r_i]])
    flags = slips.flags[src[r_i]]
    good = cont[r_i]
    def carrier_row(v) -> dict:
        return {"count": len(v), "robust_sigma_mm": 1e3 * 1.4826 * float(np.median(v)),
                "p95_abs_mm": 1e3 * float(np.percentile(v, 95)), "max_abs_mm": 1e3 * float(v.max()),
                "above_half_cycle": int((v > 0.09).sum())}

    for s in letters:
        v = np.abs(d[good & (sysl == s)])
        record["carrier"]["continuous"][s] = carrier_row(v)
        lines.append(f"| continuous | {s} | {len(v)} | {1e3 * 1.4826 * np.median(v):.1f} | "
                     f"{1e3 * np.percentile(v, 95):.1f} | {1e3 * v.max():.1f} | {(v > 0.09).sum()} |")
    for reason, bit in REASONS.items():
        sel = ~good & ((flags & bit) != 0)
        if sel.any():
            v = np.abs(d[sel])
            record["carrier"]["flagged"][reason] = carrier_row(v)
            lines.append(f"| flagged: {reason} | all | {len(v)} | {1e3 * 1.4826 * np.median(v):.1f} | "
                         f"{1e3 * np.percentile(v, 95):.1f} | {1e3 * v.max():.1f} | {(v > 0.09).sum()} |")
    only_doppler = ~good & (flags == REASONS["Doppler"])
    record["carrier"]["doppler_only_pairs"] = int(only_doppler.sum())
    record["carrier"]["doppler_only_above_half_cycle"] = int((np.abs(d[only_doppler]) > 0.09).sum())
    cs = record["carrier"]["continuous"].values()
    record["carrier"]["continuous_robust_sigma_mm_min"] = min(c["robust_sigma_mm"] for c in cs)
    record["carrier"]["continuous_robust_sigma_mm_max"] = max(c["robust_sigma_mm"] for c in cs)
    record["carrier"]["continuous_max_abs_mm"] = max(c["max_abs_mm"] for c in cs)
    lines += ["", f"Pairs flagged by the Doppler check alone: {int(only_doppler.sum())}, of which "
              f"{int((np.abs(d[only_doppler]) > 0.09).sum())} carry a jump above half a cycle: on this file the "
              "Doppler alarms are the Doppler's own multipath, not carrier slips (a TDCP row lost each); the "
              "slips the carrier shows are the ones the loss-of-lock and half-cycle flags mark.", ""]
    lines += ["", "Not run with TDCP (no stochastic clone): " +
              ("; ".join(f"{k}: {v}" for k, v in not_run.items()) or "none"), "",
              f"Times (one run each, the machine shared): the shipped pipeline (SPP + every filter) {shipped_s:.1f} s "
              f"wall; the {len(with_tdcp)} TDCP filters {tdcp_wall:.1f} s wall, {tdcp_cpu:.1f} s CPU.", ""]
    out = ROOT / "benchmarks" / "results" / "tdcp_urbannav.md"
    out.write_text("\n".join(lines))
    record["times"] = {"shipped_pipeline_wall_s": shipped_s, "tdcp_filters_wall_s": tdcp_wall,
                       "tdcp_filters_cpu_s": tdcp_cpu}
    record["not_run_with_tdcp"] = not_run
    out.with_suffix(".json").write_text(json.dumps(record, indent=1) + "\n")
    print("\n".join(lines))


class _Prev:
    """A memory stand-in naming the previous epoch (for counting the pairs)."""

    def __init__(self, i):
        self.i = i


if __name__ == "__main__":
    main()
