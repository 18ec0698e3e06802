"""Per-epoch cost of the coloured-noise mixture EKF (M6) beside M3 and the EKF.

One seeded run of P2-s2 (tight pseudorange + Doppler, ~9 satellites: ~18 rows
per epoch, 410 epochs), every filter on the same data in one process, best of
``REPEAT`` runs each (the machine is shared: best-of removes most of the
waiting for a core; compare the ratios, not the absolute times):

- M1 EKF (17 states);
- M3 with the scenario's mixtures (16 kept components x 2 process children);
- M6 with H = Psi = 0.9: the 9 AR(1) process-noise states and the 8-state
  differencing clone in every component (34 states per component);
- M6 with the process part only and with the measurement part only;
- M6 with the augmentation forced at zero coefficients (what M6 would cost
  were the zero-coefficient case not reduced to M3);
- the 23-state variants (scale factors estimated) of M3 and M6.

Writes benchmarks/results/colored.md and .json.
"""

from __future__ import annotations

import json
import platform
import time
from pathlib import Path

import numpy as np

from mixnav.config.loader import load_scenario
from mixnav.experiment import methods as registry
from mixnav.filters.colored import ColoredMixtureEkf
from mixnav.ins.error_model import ClockModel
from mixnav.measurements.differenced import DifferencedMeasurement
from mixnav.sim.scenario import simulate

REPEAT = 3
OUT = Path(__file__).parent / "results"


def main(seed: int = 3) -> dict:
    sc, src, _ = load_scenario("P2-s2")
    sim = simulate(sc, seed, src)
    s = sc.gnss.satellites
    clock = ClockModel(q_bias=s.clock_bias_noise ** 2, q_drift=s.clock_drift_noise ** 2)
    by_name = {m.name: m for m in sc.methods}

    def build(name, **colored):
        m = by_name[name]
        if colored:
            m = m.model_copy(update={"mixture": m.mixture.model_copy(update={
                "colored": m.mixture.colored.model_copy(update=colored)})})
        return registry.build(m, sim.imu_model, sim.fixes, np.zeros(3), src, 0,
                              observations=sim.observations, clock=clock)

    def forced():
        f, meas = build("gmekf")
        g = ColoredMixtureEkf(f.layout, f.imu_model, f.mixtures, psi_process=0.0, max_components=16,
                              clock=clock, augment=True)
        psi = {"pseudorange": 0.0, "range_rate": 0.0}
        return g, [DifferencedMeasurement(x, f.layout, psi) for x in meas]

    cases = {
        "EKF (M1)": lambda: build("ekf"),
        "M3 GMEKF": lambda: build("gmekf"),
        "M6 (process + measurement colour)": lambda: build("m6"),
        "M6 process colour only": lambda: build("m6", measurement={"pseudorange": 0.0, "range_rate": 0.0}),
        "M6 measurement colour only": lambda: build("m6", process=0.0),
        "M6 forced augmentation, zero coefficients": forced,
        "M3 GMEKF, 23 states": lambda: build("gmekf-sf"),
        "M6, 23 states": lambda: build("m6-sf"),
    }
    rows = {}
    for label, make in cases.items():
        best = None
        for _ in range(REPEAT):
            f, meas = make()
            t0 = time.process_time()
            r = f.run(sim.imu, sim.init, meas)
            cpu = (time.process_time() - t0) / r.timing["measurement_epochs"] * 1e6
            if best is None or cpu < best[0]:
                best = (cpu, r.timing["epoch_time_mean_us"], r.timing.get("bank_components_max", 1.0))
        rows[label] = {"cpu_us_per_epoch": best[0], "wall_us_per_epoch": best[1],
                       "bank_components_max": best[2]}
        print(f"{label:45s} {best[0]:8.1f} us CPU/epoch")
    ref = rows["M3 GMEKF"]["cpu_us_per_epoch"]
    for r in rows.values():
        r["ratio_to_m3"] = r["cpu_us_per_epoch"] / ref
    return {"machine": platform.processor() or platform.machine(), "python": platform.python_version(),
            "scenario": "P2-s2", "seed": seed, "repeat": REPEAT, "rows": rows}


def write(res: dict) -> None:
    OUT.mkdir(exist_ok=True)
    (OUT / "colored.json").write_text(json.dumps(res, indent=2))
    lines = ["# M6 coloured-noise mixture EKF: cost per epoch (benchmarks/bench_colored.py)", "",
             f"P2-s2 seed {res['seed']}, one process, CPU time of the whole run (mechanization included) "
             f"per measurement epoch, best of {res['repeat']}; Python {res['python']}.", "",
             "| filter | us per epoch (CPU) | ratio to M3 | largest bank |", "| --- | ---: | ---: | ---: |"]
    for k, r in res["rows"].items():
        lines.append(f"| {k} | {r['cpu_us_per_epoch']:.0f} | {r['ratio_to_m3']:.2f} | "
                     f"{r['bank_components_max']:.0f} |")
    (OUT / "colored.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    write(main())
