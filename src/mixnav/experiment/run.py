"""One run of a scenario: simulate, filter with every method, tabulate, write.

The solution tables and the output folder are :mod:`mixnav.experiment.outputs`' (the
same for every pipeline), the metrics :mod:`mixnav.experiment.metrics`'; their names
are re-exported here for the callers of ``mixnav.experiment.run``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..config.scenario_schema import Scenario
from . import methods
from .aiding import AidingInputs
from ..filters.ekf import FilterResult
from ..sim.rng import Streams
from ..sim.scenario import SimulatedRun, simulate
from .metrics import (NEES_CONDITION_LIMIT, NIS_CAUSES, NIS_CAUSES_NO_INS, NIS_WARN_MEDIAN,  # noqa: F401
                      bias_metrics, method_metrics, nees, nis_warnings)
from .outputs import (_at_true_time, _bias_columns, _held, _mode_columns, _noise_columns,  # noqa: F401
                      lla_frame, solution_table, truth_at, write_outputs)


@dataclass
class RunOutput:
    scenario: Scenario
    source: str
    sim: SimulatedRun
    results: dict[str, FilterResult]
    aiding: dict = field(default_factory=dict)   # AidingInputs.summary(): still intervals, thresholds


def run_scenario(sc: Scenario, source: str | None = None, seed: int | None = None,
                 ideal=None) -> RunOutput:
    """Simulate one seeded run and filter it with every method of the scenario."""
    seed = sc.scenario.seed if seed is None else seed
    sim = simulate(sc, seed, source, ideal=ideal)
    lever = np.asarray(sc.gnss.lever_arm, dtype=float)
    results = {}
    clock = None
    if sc.gnss.satellites is not None:
        from ..ins.error_model import ClockModel
        s = sc.gnss.satellites
        clock = ClockModel(q_bias=s.clock_bias_noise ** 2, q_drift=s.clock_drift_noise ** 2)
    training = _training(sc, seed, source)
    aiding = AidingInputs(sc.aiding, sim.imu, sim.fixes, sim.init.time, float(sim.imu.time[-1]),
                          odometer=getattr(sim, "odometer", None), source=source)
    for i, m in enumerate(sc.methods):
        filt, meas = methods.build(m, sim.imu_model, sim.fixes, lever, source, i,
                                    observations=sim.observations, clock=clock, training=training,
                                    seed=seed, aiding=aiding)
        # each estimator its own stream, independent of the simulation's and of the other methods'
        results.update(methods.run_method(m, filt, sim.imu, sim.init, meas, source, i, [x.name for x in sc.methods],
                                          rng=Streams(seed).get(f"filter:{m.name}")))
    return RunOutput(sc, source or sc.scenario.name, sim, results, aiding.summary())


def _training(sc: Scenario, seed: int, source):
    """Training residuals for the methods that learn their mixtures (one draw shared by all),
    and training series for the coloured-noise methods (M6) that fit or whiten with them;
    what each needs is its estimator's to say (registry.training_needs)."""
    from ..filters.registry import training_needs
    needs = [need for m in sc.methods for need in training_needs(m)]
    residuals = [n.residuals for n in needs if n.residuals is not None]
    series = [n.series for n in needs if n.series is not None]
    if not residuals and not series:
        return None
    from ..sim.training import training_residuals, training_series
    out = {}
    if residuals:
        kinds = sorted({k for r in residuals for k in r[0]})
        out = training_residuals(sc, seed, kinds, max(r[1] for r in residuals), any(r[2] for r in residuals), source)
    if series:
        from ..sim.training import TRAINING_CHANNELS
        kinds = sorted({k for r in series for k in r[0]})
        n = max(r[1] for r in series)
        out["series"] = training_series(sc, seed, [k for k in kinds if k in ("pseudorange", "range_rate")],
                                        -(-n // TRAINING_CHANNELS) + 1, any(r[2] for r in series), source)
    return out


def gnss_noise_sd(scenario, source: str, times: np.ndarray) -> dict:
    """The true standard deviation of the simulated GNSS noise per loose channel at
    ``times``: ``{"position_n": (n,), ..., "velocity_d": (n,)}`` (the noise process's
    :meth:`~mixnav.noise.processes.NoiseProcess.sd`, or the stated sigma when the file
    gives no process); a channel whose process has no closed-form sd is left out."""
    from ..config.loader import gnss_noise
    pos, vel = gnss_noise(scenario, source)
    g = scenario.gnss
    t = np.asarray(times, dtype=float)
    out = {}
    for name, proc, stated in (("position", pos, g.position_sigma), ("velocity", vel, g.velocity_sigma)):
        if proc is not None:
            sd = proc.sd(t, 3)
        elif stated is not None:
            sd = np.broadcast_to(np.asarray(stated, dtype=float), (t.size, 3))
        else:
            sd = None
        if sd is not None:
            out.update({f"{name}_{ax}": sd[:, i] for i, ax in enumerate("ned")})
    return out


def run_tables(run: RunOutput) -> dict[str, pd.DataFrame]:
    """The solution table of every method of a simulated run, errors against the truth."""
    return {name: solution_table(res, run.sim.truth, run.sim.outages) for name, res in run.results.items()}


def write_run(out_dir: Path, run: RunOutput, config_text: str | None = None, overwrite: bool = False) -> dict:
    """Write solutions, metrics, figures and the report of one simulated run (the folder
    policy of :mod:`mixnav.io.outdir`; ``overwrite`` clears a folder it would refuse)."""
    sim = run.sim
    tables = run_tables(run)
    notes = [f"Seed {sim.seed}; IMU errors drawn: gyro bias "
             f"{np.round(np.degrees(sim.imu_draw.gyro_bias) * 3600, 2).tolist()} deg/h, "
             f"accelerometer bias {np.round(sim.imu_draw.accel_bias / 9.80665e-6, 1).tolist()} ug.",
             "Errors are estimate minus truth; bounds are the filter's own 3-sigma."]
    header = {"scenario": run.scenario.scenario.name, "source": run.source, "seed": sim.seed}
    if run.aiding:
        header["aiding"] = run.aiding
    truth = None
    if any(c.startswith("vb_sigma_") for t in tables.values() for c in t.columns):
        truth = (sim.fixes.time, gnss_noise_sd(run.scenario, run.source, sim.fixes.time))
    return write_outputs(out_dir, f"mixnav run: {run.scenario.scenario.name}", header, run.results, tables,
                         sim.outages, lla_frame(sim.truth.time, sim.truth.lla)[::10],
                         lla_frame(sim.fixes.time, sim.fixes.lla), notes, config_text, sim.gnss_bias,
                         noise_truth=truth, command="run", overwrite=overwrite, protect=[run.source],
                         segments=run.scenario.scored_segments)
