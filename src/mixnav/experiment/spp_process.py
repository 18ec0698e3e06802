"""``mixnav process`` for ``dataset.kind = "gnss-raw"``: epoch-by-epoch SPP of raw GNSS,
and constant-velocity filters started from it.

Steps: read the raw measurement log (the raw-GNSS reader of ``raw_gnss.format``,
:mod:`mixnav.io.readers`: an Android log or a RINEX observation file) and the RINEX navigation file
(:mod:`mixnav.gnss.ephemeris`; GPS from one file), or with ``systems`` beyond GPS the
navigation files of every system (:class:`mixnav.gnss.multi_ephemeris.MultiEphemeris`; the
GLONASS frequency numbers taken from them), solve every epoch by WLS (:mod:`mixnav.gnss.spp`:
one receiver clock plus one offset per extra system in the epoch), and
score the solutions against the surveyed static point of ``[reference_point]``, or against
a moving receiver's ``[reference]`` trajectory interpolated at each epoch's GPS time
(:mod:`mixnav.experiment.raw_reference`: epochs outside its span or in its gaps are not
scored, counted): north, east, down errors, their RMS, median, maximum and 95th
percentile, the 3-D RMS, and the position NEES with the WLS covariance, with the
availability (solved epochs / epochs) beside them. Epochs without a solution are counted
by status, never raised.

Filter methods (``[[methods]]`` with an estimator other than ``wls``): the observations
with SPP's broadcast corrections applied (:func:`mixnav.gnss.spp.corrected_pseudoranges`:
satellite clock, troposphere and ionosphere, at the latest SPP fix) feed the
pseudorange model (:class:`mixnav.measurements.pseudorange.PseudorangeGnss`, SPP's
elevation weights and mask) on the constant-velocity model
(:class:`mixnav.motion.ConstantVelocityMotion`, ``[motion]``), started at the first SPP
fix (its position, clock bias and their WLS covariance; velocity and clock drift zero)
and run from the next epoch on, one engine per method
(:func:`mixnav.experiment.methods.run_methods`, the code the odometry datasets
run).

Corrected pseudoranges (``[raw_gnss] format = "smartloc"``: satellite clock and atmosphere
removed in the file, satellite positions and variances given, no navigation file, no GPS
time): the SPP of :mod:`mixnav.gnss.corrected_spp` (the file's variances as weights), the
filters on the file's rows (clock jumps taken off), times the log's own seconds (GPS week 0
in the table and metrics.json), the reference the data set's ground truth on those seconds.

Times in the solution table are seconds since the first epoch; the first
epoch's GPS week and seconds of week are in metrics.json.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .._version import __version__
from ..config.raw_gnss_schema import RawGnssDataset
from ..data import InitialState, RawPseudoranges
from ..geodesy.frames import dcm_ecef_to_ned, ecef_to_lla, lla_to_ecef
from ..errors import ArgumentError, ConfigError, DataError
from ..gnss.ephemeris import BroadcastEphemeris
from ..gnss.spp import SppOptions, SppTrack, solve_epochs
from ..io.readers import read_table
from ..io.atomic import atomic_write_dataframe, atomic_write_json
from . import figures
from .outputs import add_sweeps
from .raw_reference import EpochReference, errors_ned, reference_at_epochs
from .report import write_report
from .webmap import map_html

METHOD = "spp"


@dataclass
class SppOutput:
    """What :func:`process_raw` produced: the SPP track and the filter methods' results
    (``results``: name -> FilterResult, times in seconds since the first epoch)."""

    dataset: RawGnssDataset
    source: str
    data_dir: Path
    observations: RawPseudoranges      # what the raw-GNSS reader of the format gave (smartloc: corrected=True)
    ephemeris: BroadcastEphemeris      # or a MultiEphemeris (systems beyond GPS); None (smartloc)
    track: SppTrack
    reference_lla: np.ndarray | None   # (3,) rad, rad, m
    read_time_s: float
    solve_time_s: float
    results: dict = field(default_factory=dict)
    robust_tracks: dict = field(default_factory=dict)   # name -> SppTrack of a robust SPP method
    robust_time_s: dict = field(default_factory=dict)   # name -> its solve time [s]
    epochs: object = None              # PseudorangeEpochs the filters read (None without filters)
    init: InitialState | None = None
    filter_time_s: float = 0.0
    checks: dict = field(default_factory=dict)
    clock_offset: np.ndarray | None = None   # (k,) clock jumps taken off the filters' pseudoranges [m]
    reference: EpochReference | None = None  # [reference]: a moving receiver's trajectory at the epochs


def options(ds, method=None) -> SppOptions:
    """The SPP settings of a dataset's ``[raw_gnss]`` (a gnss-raw dataset, or an ins-gnss one
    with RINEX); with a ``wls`` method that has a ``[robust]`` table, its IGG-III thresholds
    too (the robust SPP)."""
    c = ds.raw_gnss
    robust = None if method is None or method.robust is None else (method.robust.k0, method.robust.k1)
    if c.format == "smartloc":   # the file's variances as the weights, its atmosphere removed already
        return SppOptions(elevation_mask=c.elevation_mask, sigma_a=1.0, sigma_b=0.0, troposphere=False,
                          ionosphere=False, robust=robust)
    return SppOptions(elevation_mask=c.elevation_mask, sigma_a=c.sigma_a, sigma_b=c.sigma_b,
                      troposphere=c.troposphere, ionosphere=c.ionosphere, robust=robust, weights=c.weights,
                      validate=c.validate_epochs, fde=c.fde)


def process_raw(ds: RawGnssDataset, source: str, folder: Path, seed: int = 0) -> SppOutput:
    """Read the raw log and the navigation file, solve every epoch, and run the filter
    methods (module docstring; ``seed``: the engine's random stream)."""
    return solve_raw(ds, source, folder, *read_raw(ds, source, folder), seed=seed)


def gps_rows(obs: RawPseudoranges) -> None:
    """Observations handed to the SPP or the filters directly (library use) must be GPS: a
    row of another system is an ArgumentError (its number would be taken for a GPS PRN)."""
    if obs.system is not None and (np.asarray(obs.system) != "G").any():
        others = sorted(set(np.asarray(obs.system).tolist()) - {"G"})
        raise ArgumentError(f"observations of systems {', '.join(others)}: positioning uses GPS alone so far "
                            "(read with systems = ['G'])", argument="obs")


def multi_system(c) -> bool:
    """Whether a ``[raw_gnss]`` table is solved over several systems (a MultiEphemeris of
    every navigation file): ``systems`` beyond GPS, or several navigation files."""
    return tuple(c.systems) != ("G",) or len(c.files("navigation")) > 1


#: RINEX signal codes of each system's first-frequency civil signal, the one the SPP models
#: (the group delays of mixnav.gnss.multi_ephemeris and the frequencies of
#: mixnav.gnss.spp.first_frequency): band 1 (GLONASS G1, Galileo E1, QZSS L1), BeiDou B1I
#: (RINEX 3.02 wrote it C1I, the other versions C2I)
FIRST_FREQUENCY_CODES = {"G": ("C1", "P1", "C1C", "C1S", "C1L", "C1X", "C1P", "C1W", "C1Y", "C1M"),
                         "R": ("C1", "P1", "C1C", "C1P"), "E": ("C1", "C1A", "C1B", "C1C", "C1X", "C1Z"),
                         "C": ("C1", "C2", "C1I", "C1Q", "C2I", "C2Q", "C2X"),
                         "J": ("C1", "C1C", "C1S", "C1L", "C1X", "C1Z")}


def check_first_frequency(c, source: str) -> None:
    """The SPP of several systems models each system's first-frequency civil signal: a
    ``signals`` entry naming another (``C5Q``, ``C7I``...) is a ConfigError naming the key."""
    for letter, codes in c.signals.items():
        bad = [code for code in codes if code not in FIRST_FREQUENCY_CODES.get(letter, ())]
        if bad:
            raise ConfigError(f"{letter}: {', '.join(bad)} is not the system's first-frequency civil signal, the "
                              f"one the SPP's group delays and ionosphere scaling are for (use one of "
                              f"{', '.join(FIRST_FREQUENCY_CODES[letter])})", file=source,
                              key=f"raw_gnss.signals.{letter}")


def read_navigation(c, folder: Path, source: str):
    """The broadcast ephemeris of a ``[raw_gnss]`` table: GPS from one file
    (BroadcastEphemeris, as before), else a MultiEphemeris of every file. A system of
    ``systems`` no file gives records for is warned about, naming it and the files (its
    satellites are then left out, counted per system); no records at all for any of them is
    a ConfigError naming ``raw_gnss.navigation``."""
    paths = [folder / f for f in c.files("navigation")]
    if not multi_system(c):
        return BroadcastEphemeris.from_rinex(paths[0])
    from ..gnss.multi_ephemeris import SYSTEM_NAMES, MultiEphemeris
    eph = MultiEphemeris.from_rinex(paths)
    missing = [s for s in c.systems if s not in eph]
    if len(missing) == len(c.systems):
        raise ConfigError(f"no navigation records for any of the systems {', '.join(c.systems)} in "
                          f"{', '.join(str(p) for p in paths)}", file=source, key="raw_gnss.navigation")
    if missing:
        import warnings
        from ..io.imu_checks import DataWarning
        names = ", ".join(f"{SYSTEM_NAMES[s]} ({s})" for s in missing)
        warnings.warn(f"{source}: raw_gnss.navigation: no navigation records for {names} in "
                      f"{', '.join(str(p) for p in paths)}; its satellites are left out (metrics.json: "
                      "satellites_skipped_by_system)", DataWarning, stacklevel=3)
    return eph


def read_raw(ds: RawGnssDataset, source: str, folder: Path) -> tuple[RawPseudoranges, BroadcastEphemeris, float]:
    """The raw log (the raw-GNSS reader of ``raw_gnss.format``) and the navigation file(s),
    and the time it took [s]. With several systems the GLONASS frequency numbers of the
    navigation records are attached to the observations."""
    c = ds.raw_gnss
    if c.format == "smartloc":
        return read_corrected(c, folder, source)
    if multi_system(c):
        check_first_frequency(c, source)
    t0 = _time.perf_counter()
    obs = read_table("raw-gnss", c, folder, "raw_gnss", source)
    eph = read_navigation(c, folder, source)
    if "R" in c.systems and hasattr(eph, "states_of") and "R" in eph:
        obs = obs.with_glonass_channels(eph["R"].channels())
    return obs, eph, _time.perf_counter() - t0


def read_corrected(c, folder: Path, source: str) -> tuple:
    """``[raw_gnss] format = "smartloc"``: the corrected pseudoranges (the raw-GNSS reader of the
    format: RawPseudoranges with ``corrected = True``) of the systems of ``systems``; rows of
    other systems are left out and counted (``rejected``, by ``system not read: <letter>``).
    Returns ``(observations, None, read time [s])``: no navigation data."""
    t0 = _time.perf_counter()
    obs = read_table("raw-gnss", c, folder, "raw_gnss", source).keep_systems(c.systems)
    if not len(obs.prn):
        raise ConfigError(f"no pseudorange of the systems {list(c.systems)} in {folder / c.file}", file=source,
                          key="raw_gnss.systems")
    return obs, None, _time.perf_counter() - t0


def corrected(po) -> bool:
    """Whether ``po`` solved corrected pseudoranges (``format = "smartloc"``)."""
    return po.observations.corrected


def _iono_alpha(eph):
    """The Klobuchar alpha the SPP uses (GPS's: a MultiEphemeris's GPS header), or None."""
    if eph is None:
        return None
    if hasattr(eph, "states_of"):
        return eph["G"].iono_alpha if "G" in eph else None
    return eph.iono_alpha


def _systems_of(obs, eph):
    """``(system, glonass_channel)`` to hand the SPP: None, None for GPS with GPS records;
    a row of another system without a MultiEphemeris is an ArgumentError."""
    if not hasattr(eph, "states_of"):
        if obs.system is not None and (np.asarray(obs.system) != "G").any():
            others = sorted(set(np.asarray(obs.system).tolist()) - {"G"})
            raise ArgumentError(f"observations of systems {', '.join(others)} with GPS navigation records alone: "
                                "give their navigation files (a MultiEphemeris; [raw_gnss] navigation = [...])",
                                argument="obs")
        return None, None
    system = obs.systems()
    chan = obs.glonass_channel() if (system == "R").any() else None
    return system, chan


def solve_raw(ds: RawGnssDataset, source: str, folder: Path, obs, eph: BroadcastEphemeris, read_time_s: float = 0.0,
              seed: int = 0) -> SppOutput:
    """SPP of every epoch of ``obs`` (read observations: GPS with a BroadcastEphemeris, any
    systems with a MultiEphemeris; corrected pseudoranges without one) and the filter methods:
    :func:`solve_spp`, then :func:`run_filters`."""
    po = solve_spp(ds, source, folder, obs, eph, read_time_s)
    run_filter_methods(po, seed)
    return po


def run_filter_methods(po: SppOutput, seed: int = 0, inputs: FilterInputs | None = None) -> None:
    """:func:`run_filters` on every method of ``po.dataset`` that is not an SPP (``wls``);
    ``inputs`` as there."""
    methods = [(k, m) for k, m in enumerate(po.dataset.run_methods()) if m.estimator != "wls"]
    if methods:
        run_filters(po, methods, seed, inputs)


def solve_spp(ds: RawGnssDataset, source: str, folder: Path, obs, eph: BroadcastEphemeris,
              read_time_s: float = 0.0) -> SppOutput:
    """The epoch-by-epoch part of :func:`solve_raw`: the SPP track, the robust SPP methods and
    the moving reference, no filter run (``results`` empty). It depends on ``[raw_gnss]``,
    ``[reference]``, ``[reference_point]`` and the ``wls`` methods only, never on ``[motion]``
    or a filter method's settings (``mixnav tune`` computes it once for every candidate)."""
    if obs.corrected:
        return _solve_corrected(ds, source, folder, obs, read_time_s)
    system, chan = _systems_of(obs, eph)
    c = ds.raw_gnss
    # the moving reference first: a file that does not cover the log is refused before the solve
    moving = None if ds.reference is None else reference_at_epochs(ds.reference, folder, source, obs.week, obs.tow)
    if c.ionosphere and _iono_alpha(eph) is None:   # asked for, and impossible: said, not silent
        import warnings
        from ..io.imu_checks import DataWarning
        warnings.warn(f"{', '.join(str(folder / f) for f in c.files('navigation'))}: no GPS header with ionosphere "
                      "(Klobuchar) coefficients, so the ionosphere correction is skipped and every pseudorange "
                      "keeps its 2-10 m delay (metrics.json: ionosphere)", DataWarning, stacklevel=3)
    t1 = _time.perf_counter()
    track = solve_epochs(eph, obs.week, obs.tow, obs.epoch, obs.prn, obs.pseudorange, options(ds), system=system,
                         glonass_channel=chan)
    t2 = _time.perf_counter()
    rp = ds.reference_point
    ref = None if rp is None else np.array([rp.latitude, rp.longitude, rp.height])
    po = SppOutput(ds, source, folder, obs, eph, track, ref, read_time_s, t2 - t1, reference=moving)
    for m in ds.run_methods():
        if m.estimator == "wls" and m.robust is not None:
            t3 = _time.perf_counter()
            po.robust_tracks[m.name] = solve_epochs(eph, obs.week, obs.tow, obs.epoch, obs.prn, obs.pseudorange,
                                                    options(ds, m), system=system, glonass_channel=chan)
            po.robust_time_s[m.name] = _time.perf_counter() - t3
    return po


def _solve_corrected(ds, source: str, folder: Path, obs: RawPseudoranges, read_time_s: float) -> SppOutput:
    """:func:`solve_spp` of corrected pseudoranges (:mod:`mixnav.gnss.corrected_spp`, on their
    epochs grouped by :meth:`~mixnav.gnss.pseudoranges.PseudorangeEpochs.from_raw`): times
    are the log's own seconds (week 0)."""
    from ..gnss.corrected_spp import solve_corrected
    from ..gnss.pseudoranges import PseudorangeEpochs
    pe = PseudorangeEpochs.from_raw(obs)
    week = np.zeros(len(pe), int)
    moving = None if ds.reference is None else reference_at_epochs(ds.reference, folder, source, week, pe.time)
    t1 = _time.perf_counter()
    track = solve_corrected(pe, options(ds))
    po = SppOutput(ds, source, folder, obs, None, track, None, read_time_s, _time.perf_counter() - t1,
                   reference=moving)
    for m in ds.run_methods():
        if m.estimator == "wls" and m.robust is not None:
            t3 = _time.perf_counter()
            po.robust_tracks[m.name] = solve_corrected(pe, options(ds, m))
            po.robust_time_s[m.name] = _time.perf_counter() - t3
    return po


def _epoch_times(track: SppTrack) -> np.ndarray:
    t_abs = track.week * 604800.0 + track.tow
    return t_abs - t_abs[0]


def filter_start(po: SppOutput) -> InitialState:
    """The filters' start: the first SPP fix (position and clock bias with their WLS
    covariance times ``motion.position_sigma_factor``; velocity and clock drift zero with
    ``motion.velocity_sigma``, ``motion.clock_drift_sigma``)."""
    tr, mc = po.track, po.dataset.motion
    ok = np.nonzero(tr.ok)[0]
    if len(ok) == 0:
        raise DataError(f"no epoch could be solved (status counts: {tr.status_counts()}), so the filters have "
                        "no first fix to start from", file=po.observations.source)
    if mc.start > 0:   # [motion] start: the first fix at or after it
        ok = ok[_epoch_times(tr)[ok] >= float(mc.start) - 1e-9]
        if len(ok) == 0:
            raise ConfigError(f"start {float(mc.start):g} s: no SPP fix at or after it (the log ends at "
                              f"{float(_epoch_times(tr)[-1]):.1f} s)", file=po.source, key="motion.start")
    j = int(ok[0])
    lla = ecef_to_lla(tr.pos_ecef[j])
    C_ne = dcm_ecef_to_ned(lla[0], lla[1])
    f = float(mc.position_sigma_factor)
    sig_pos = f * np.sqrt(np.diag(C_ne @ tr.cov[j, :3, :3] @ C_ne.T))
    nav = np.zeros(10)
    nav[0] = 1.0
    nav[7:10] = lla
    clock0, aux0 = tr.clock_bias[j], None
    letters = filter_systems(tr)
    if len(letters) > 1:
        # the filter's clock is its first system's; the others start at the fix's offsets to it
        # (0 for a system the fix did not use)
        ref = tr.offsets[letters[0]][j]
        ref = ref if np.isfinite(ref) else 0.0
        clock0 = clock0 + ref
        aux0 = {"system_offset": np.array([v - ref if np.isfinite(v := tr.offsets[s][j]) else 0.0
                                           for s in letters[1:]])}
    return InitialState(time=float(_epoch_times(tr)[j]), nav=nav, sigma_att=np.zeros(3),
                        sigma_vel=np.full(3, float(mc.velocity_sigma)), sigma_pos=sig_pos,
                        sigma_clock=np.array([f * np.sqrt(tr.cov[j, 3, 3]), float(mc.clock_drift_sigma)]),
                        clock0=np.array([clock0, 0.0]), aux0=aux0)


def filter_systems(tr: SppTrack) -> tuple[str, ...]:
    """The systems the filters estimate a clock (the first) and offsets for: those with a
    satellite in some SPP solution, in the order ``G R E C J`` (GPS alone without
    offsets)."""
    if not tr.offsets:
        return ("G",)
    return tuple(s for s, v in tr.offsets.items() if np.isfinite(v).any())


@dataclass(frozen=True)
class FilterInputs:
    """What the filters read that no filter setting changes: the corrected pseudorange epochs
    and the clock jumps taken off them, from the SPP track, ``[raw_gnss]`` and
    ``motion.clock_jump`` alone (:func:`filter_inputs`; :func:`run_filters` reuses them)."""

    times: np.ndarray          # (n,) the epochs' times [s since the first epoch]
    offset: np.ndarray         # (n,) clock jumps taken off the pseudoranges [m]
    jumps: list
    spikes: int
    epochs: object             # PseudorangeEpochs
    skipped: dict              # observations not filtered, by reason
    elevation_mask: float


def filter_inputs(po: SppOutput) -> FilterInputs:
    """The filters' pseudoranges of ``po`` (module docstring): SPP's broadcast corrections at
    the latest fix, the clock jumps the SPP saw taken off."""
    from ..gnss.spp import clock_jumps, corrected_pseudoranges
    ds, tr, obs = po.dataset, po.track, po.observations
    # the atmosphere at the latest fix (causal): a first fix is metres to tens of metres off,
    # which moves the delays by millimetres
    last = np.maximum.accumulate(np.where(tr.ok, np.arange(len(tr.tow)), -1))
    rx = np.where((last >= 0)[:, None], tr.pos_ecef[np.maximum(last, 0)], np.nan)
    opts = options(ds)
    times = _epoch_times(tr)
    # a receiver clock that jumps (millisecond steps) would throw every filter off: the
    # jumps seen by the SPP come off the pseudoranges first (the first fix has none)
    offset, jumps, spikes = clock_jumps(times, tr.clock_bias, tr.ok, float(ds.motion.clock_jump))
    if corrected(po):   # the file's pseudoranges, clock jumps off; the rows' own variances
        from dataclasses import replace
        from ..gnss.pseudoranges import PseudorangeEpochs
        pe = PseudorangeEpochs.from_raw(obs)
        epochs, skipped = replace(pe, pseudorange=pe.pseudorange - np.repeat(offset, pe.counts())), {}
    else:
        rho = np.asarray(obs.pseudorange, float) - offset[np.asarray(obs.epoch, int)]
        system, chan = _systems_of(obs, po.ephemeris)
        epochs, skipped = corrected_pseudoranges(po.ephemeris, obs.week, obs.tow, obs.epoch, obs.prn, rho,
                                                 rx, opts, cn0=getattr(obs, "cn0", None), source=obs.source,
                                                 system=system, glonass_channel=chan)
    return FilterInputs(times, offset, jumps, spikes, epochs, skipped, opts.elevation_mask)


def run_filters(po: SppOutput, methods, seed: int = 0, inputs: FilterInputs | None = None) -> None:
    """Run the ``(index, method)`` filters on the constant-velocity model (module docstring);
    results into ``po``. ``inputs``: :func:`filter_inputs` of an SppOutput of the same SPP
    track, ``[raw_gnss]`` and ``motion.clock_jump`` (reused, not recomputed; the same numbers)."""
    from ..ins.error_model import ClockModel
    from ..measurements.pseudorange import PseudorangeGnss
    from ..motion.constant_velocity import (ConstantVelocityMotion, ConstantVelocityNoise, clock_ticks,
                                            constant_velocity_layout)
    from .methods import run_methods
    ds, tr, obs = po.dataset, po.track, po.observations
    mc = ds.motion
    t_prep = _time.perf_counter()
    init = filter_start(po)
    if inputs is None:
        inputs = filter_inputs(po)
    times, offset, jumps, spikes = inputs.times, inputs.offset, inputs.jumps, inputs.spikes
    epochs, skipped = inputs.epochs, inputs.skipped
    end = float(times[-1])
    if not end > init.time:
        raise DataError("the first SPP fix is at the last epoch: nothing left to filter", file=obs.source)
    from ..gnss.pseudoranges import SYSTEM_LETTERS
    codes = {v: k for k, v in SYSTEM_LETTERS.items()}
    letters = filter_systems(tr)
    lay = constant_velocity_layout(clock=True, system_offsets=len(letters) - 1)
    model = PseudorangeGnss(epochs, lay, systems=tuple(codes[s] for s in letters), variance="given",
                            elevation_mask=inputs.elevation_mask)
    noise = ConstantVelocityNoise(float(mc.accel_sigma), float(mc.vertical_accel_sigma))
    clock = ClockModel(float(mc.clock_q_bias), float(mc.clock_q_drift))
    ticks = clock_ticks(init.time, end, float(mc.step))
    out_t = times[times > init.time]
    prep = _time.perf_counter() - t_prep
    t_filter = _time.perf_counter()
    po.results = run_methods(methods, lambda: ConstantVelocityMotion(lay, noise, clock), [model], ticks, init, out_t,
                             po.source, seed, motion="constant-velocity")
    po.filter_time_s = prep + _time.perf_counter() - t_filter
    po.epochs, po.init, po.clock_offset = epochs, init, offset
    po.checks = {"filter_start_s": init.time, "clock_jumps": [list(j) for j in jumps],
                 "clock_spikes_ignored": spikes,
                 "observations_not_filtered": skipped,
                 "pseudorange_rows_skipped": model.skipped_rows}


def ionosphere_applied(po: SppOutput) -> str:
    """``"klobuchar"`` (applied), ``"off"`` (``raw_gnss.ionosphere = false``), ``"skipped"``
    (asked for, but the navigation header has no Klobuchar coefficients; warned) or
    ``"removed in the file"`` (corrected pseudoranges, ``format = "smartloc"``)."""
    if corrected(po):
        return "removed in the file"
    if not po.dataset.raw_gnss.ionosphere:
        return "off"
    return "klobuchar" if _iono_alpha(po.ephemeris) is not None else "skipped"


def solution_table(po: SppOutput, track: SppTrack | None = None) -> pd.DataFrame:
    """One row per epoch (NaN where the epoch has no solution) of the plain SPP, or of
    ``track`` (a robust SPP method's)."""
    tr = po.track if track is None else track
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
    elif po.reference is not None:
        # estimate minus the reference interpolated at the epoch, in NED there; NaN where not scored
        ref = po.reference.lla
        err = errors_ned(tr.pos_ecef, ref)
        # the sigmas in NED at the reference point, or at the solution where the reference is not
        at = np.where(np.isfinite(ref[:, :1]), ref, lla)
        C_ne = dcm_ecef_to_ned(at[:, 0], at[:, 1])
        cov_ned = np.einsum("kij,kjl,kml->kim", C_ne, tr.cov[:, :3, :3], C_ne)
        for j, ax in enumerate("ned"):
            df[f"err_{ax}_m"] = err[:, j]
        for j, ax in enumerate("ned"):
            df[f"sig_{ax}_m"] = np.sqrt(cov_ned[:, j, j])
        nees = np.full(len(tr.tow), np.nan)
        sc = ok & po.reference.scored
        if sc.any():
            nees[sc] = np.einsum("ki,ki->k", err[sc], np.linalg.solve(cov_ned[sc], err[sc][..., None])[..., 0])
        df["nees_pos"] = nees
    return df


def filter_table(po: SppOutput, res) -> pd.DataFrame:
    """The solution table of a filter method, one row per epoch as the SPP's (NaN and status
    ``not started`` up to the first fix; columns in docs/outputs.md)."""
    tr = po.track
    times = _epoch_times(tr)
    k = len(times)
    idx = np.searchsorted(times, res.time)       # output times are epoch times
    lay = res.layout

    def col(values):
        out = np.full(k, np.nan)
        out[idx] = values
        return out
    lla = res.nav[:, 7:10]
    df = pd.DataFrame({"time_s": times, "gps_week": tr.week, "gps_tow_s": tr.tow,
                       "lat_deg": col(np.degrees(lla[:, 0])), "lon_deg": col(np.degrees(lla[:, 1])),
                       "height_m": col(lla[:, 2]),
                       "vn_mps": col(res.nav[:, 4]), "ve_mps": col(res.nav[:, 5]), "vd_mps": col(res.nav[:, 6])})
    clk = res.estimates.get("clock")
    jumps = po.clock_offset if po.clock_offset is not None else 0.0
    df["clock_bias_m"] = col(clk[:, 0]) + jumps if clk is not None else np.nan   # the receiver's, jumps included
    df["clock_drift_mps"] = col(clk[:, 1]) if clk is not None else np.nan
    n_sat = np.zeros(k, int)
    if po.epochs is not None:
        model_rows = {float(t): len(rows) for t, rows in
                      ((po.epochs.time[e], _used(po, e)) for e in range(len(po.epochs)))}
        n_sat[idx] = [model_rows.get(float(t), 0) for t in res.time]
    df["n_sat"] = n_sat
    status = np.full(k, "not started", dtype=object)
    status[idx] = "ok"
    df["status"] = status.astype(str)
    if po.reference_lla is not None:
        ref = po.reference_lla
        err = np.full((k, 3), np.nan)
        # estimate minus reference in NED at the reference, as the SPP table's
        err[idx] = (lla_to_ecef(lla) - lla_to_ecef(ref)) @ dcm_ecef_to_ned(ref[0], ref[1]).T
        for j, ax in enumerate("ned"):
            df[f"err_{ax}_m"] = err[:, j]
    elif po.reference is not None:
        err = np.full((k, 3), np.nan)
        err[idx] = errors_ned(lla_to_ecef(lla), po.reference.lla[idx])   # as the SPP table's
        for j, ax in enumerate("ned"):
            df[f"err_{ax}_m"] = err[:, j]
    for j, ax in enumerate("ned"):
        df[f"sig_{ax}_m"] = col(res.sigma[:, lay.pos][:, j])
    for j, ax in enumerate(("vn", "ve", "vd")):
        df[f"sig_{ax}_mps"] = col(res.sigma[:, lay.vel][:, j])
    if po.reference_lla is not None or po.reference is not None:
        from .metrics import nees
        df["nees_pos"] = col(nees(err[idx], res.pv_cov[:, 3:, 3:]))
    return df


def _used(po: SppOutput, e: int) -> np.ndarray:
    """The filters' model rows of epoch ``e`` (the satellites above the mask)."""
    el = po.epochs.elevation[po.epochs.rows_of(e)]
    return np.nonzero(~(el < po.dataset.raw_gnss.elevation_mask))[0]


def raw_tables(po: SppOutput) -> dict[str, pd.DataFrame]:
    """Every method's solution table, in the order of ``[[methods]]`` (a smoothed solution
    after its filter)."""
    tables = {}
    for m in po.dataset.run_methods():
        if m.estimator == "wls":
            tables[m.name] = solution_table(po, po.robust_tracks.get(m.name))
            continue
        for name in (m.name, f"{m.name}-smoothed"):
            if name in po.results:
                tables[name] = filter_table(po, po.results[name])
    return tables


def spp_metrics(table: pd.DataFrame, solve_time_s: float) -> dict:
    """Accuracy of the solved epochs against the reference (keys in docs/outputs.md): the
    static point, or a moving reference at the solved epochs it covers (``n_scored``; the
    others have NaN errors); ``availability``: solved epochs / epochs of the table. A
    filter's table adds its speed (``horizontal_speed_rms_mps``, ``vertical_speed_rms_mps``:
    the velocity error of a static receiver; with a moving reference, its speed)."""
    ok = (table["status"] == "ok").to_numpy()
    m: dict = {"n_epochs": int(ok.sum()),
               "availability": float(ok.sum() / max(len(table), 1)),
               "epoch_time_mean_us": 1e6 * solve_time_s / max(len(table), 1),
               "n_sat_mean": float(table["n_sat"][ok].mean()) if ok.any() else float("nan")}
    if "pdop" in table:
        m["pdop_median"] = float(table["pdop"][ok].median()) if ok.any() else float("nan")
        m["residual_rms_median_m"] = float(table["rms_residual_m"][ok].median()) if ok.any() else float("nan")
    # scored: solved, and (a moving reference) covered by the reference; every solved epoch of a static one
    sc = ok & np.isfinite(table["err_n_m"].to_numpy(dtype=float)) if "err_n_m" in table else ok
    if "err_n_m" in table:
        m["n_scored"] = int(sc.sum())
    if "err_n_m" in table and sc.any():
        e = table.loc[sc, ["err_n_m", "err_e_m", "err_d_m"]].to_numpy(dtype=float)
        h = np.hypot(e[:, 0], e[:, 1])
        v = np.abs(e[:, 2])
        m.update({"horizontal_rmse_m": float(np.sqrt(np.mean(h**2))), "horizontal_max_m": float(h.max()),
                  "horizontal_p95_m": float(np.percentile(h, 95)), "horizontal_median_m": float(np.median(h)),
                  "vertical_rmse_m": float(np.sqrt(np.mean(v**2))), "vertical_max_m": float(v.max()),
                  "vertical_p95_m": float(np.percentile(v, 95)),
                  "error_3d_rmse_m": float(np.sqrt(np.mean(np.sum(e**2, 1)))),
                  "mean_error_ned_m": [float(x) for x in e.mean(0)],
                  "nees_pos_mean": float(table["nees_pos"][sc].mean())})
    if "vn_mps" in table and ok.any():
        v = table.loc[ok, ["vn_mps", "ve_mps", "vd_mps"]].to_numpy(dtype=float)
        m["horizontal_speed_rms_mps"] = float(np.sqrt(np.mean(v[:, 0] ** 2 + v[:, 1] ** 2)))
        m["vertical_speed_rms_mps"] = float(np.sqrt(np.mean(v[:, 2] ** 2)))
    return m


def method_metrics(po: SppOutput, name: str, table: pd.DataFrame) -> dict:
    """:func:`spp_metrics` of a method, with a filter's NIS and counted recoveries."""
    res = po.results.get(name)
    if name in po.robust_tracks:
        return {**spp_metrics(table, po.robust_time_s[name]), "robust": dict(po.robust_tracks[name].robust)}
    if res is None:
        return spp_metrics(table, po.solve_time_s)
    m = spp_metrics(table, res.timing.get("wall_time_s", 0.0))
    m["epoch_time_mean_us"] = float(res.timing.get("epoch_time_mean_us", m["epoch_time_mean_us"]))
    m["nis_per_dof_mean"] = float(np.sum(res.nis) / max(np.sum(res.nis_dim), 1))
    m["recoveries"] = {k: int(v) for k, v in res.recoveries.items() if v}
    return m


def write_raw(out_dir: Path, po: SppOutput, config_text: str | None = None, overwrite: bool = False,
              sweeps=()) -> dict:
    """Solution table (CSV + Parquet), metrics.json, figures and report of an SPP run
    (the folder policy of :mod:`mixnav.io.outdir`, as ``mixnav process``), with ``sweeps``
    (:func:`mixnav.experiment.outputs.add_sweeps`)."""
    from ..io.outdir import staged_output
    with staged_output(out_dir, "process", overwrite, [po.source, po.data_dir]) as folder:
        return _write_raw(folder.path, po, config_text, sweeps)


def _write_raw(out_dir: Path, po: SppOutput, config_text: str | None, sweeps=()) -> dict:
    table = solution_table(po)
    tables = raw_tables(po)
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
    work = po.solve_time_s + sum(po.robust_time_s.values()) + po.filter_time_s
    metrics: dict = {
        "dataset": po.dataset.dataset.name, "kind": po.dataset.dataset.kind, "source": po.source,
        "data_dir": str(po.data_dir), "mixnav_version": __version__,
        "gps_week_start": int(tr.week[0]), "gps_tow_start_s": float(tr.tow[0]),
        "duration_s": duration, "read_time_s": po.read_time_s, "filter_time_s": work,
        "real_time_factor": duration / max(po.read_time_s + work, 1e-9),
        "epochs_total": len(table) + empty, "epochs_used": used, "epochs_skipped": len(table) + empty - used,
        "epoch_status": counts, "satellites_skipped": dict(tr.skipped_satellites),
        "measurements_rejected": dict(po.observations.rejected),
        "event_records_skipped": dict(getattr(po.observations, "event_records", {})),
        "reference_point": None if po.reference_lla is None else
        {"lat_deg": float(np.degrees(po.reference_lla[0])), "lon_deg": float(np.degrees(po.reference_lla[1])),
         "height_m": float(po.reference_lla[2])},
        **({"reference": {"file": po.reference.file, "format": po.dataset.reference.format,
                          "max_gap_s": float(po.dataset.reference.max_gap),
                          "reference_epochs": dict(po.reference.counts)}} if po.reference is not None else {}),
        "ionosphere": ionosphere_applied(po),
        "systems": list(po.dataset.raw_gnss.systems),
        **({"satellites_skipped_by_system": dict(tr.skipped_by_system),
            "system_offsets_median_m": {s: float(np.nanmedian(v)) for s, v in tr.offsets.items()
                                        if np.isfinite(v).any()}} if tr.offsets else {}),
        **({"filters": po.checks} if po.results else {}),
        "methods": {name: method_metrics(po, name, t) for name, t in tables.items()},
    }
    for name, t in tables.items():
        atomic_write_dataframe(out_dir / f"solution_{name}.csv", t)
        atomic_write_dataframe(out_dir / f"solution_{name}.parquet", t)
    oks = {name: t[t["status"] == "ok"] for name, t in tables.items()}
    figs = {}
    if "err_n_m" in table:
        figs["horizontal_error"] = figures.horizontal_error_figure(oks)
    ref = None
    if po.reference_lla is not None:
        ref = pd.DataFrame({"time_s": [0.0], "lat_deg": [np.degrees(po.reference_lla[0])],
                            "lon_deg": [np.degrees(po.reference_lla[1])], "height_m": [po.reference_lla[2]]})
    elif po.reference is not None:   # the reference's samples over the log's span
        rt = po.reference.trajectory
        keep = (rt.time >= table["time_s"].iloc[0] - 1.0) & (rt.time <= table["time_s"].iloc[-1] + 1.0)
        ref = pd.DataFrame({"time_s": rt.time[keep], "lat_deg": np.degrees(rt.lla[keep, 0]),
                            "lon_deg": np.degrees(rt.lla[keep, 1]), "height_m": rt.lla[keep, 2]})
    if any(len(o) for o in oks.values()):
        figs["trajectory"] = figures.trajectory_figure({n: o for n, o in oks.items() if len(o)}, ref)
    opts = options(po.dataset)
    iono = {"klobuchar": "Klobuchar (broadcast coefficients)", "off": "none (switched off)",
            "skipped": "none: the navigation header has no coefficients",
            "removed in the file": "removed in the file"}[ionosphere_applied(po)]
    from ..gnss.signals import SYSTEMS
    sysnames = "+".join(SYSTEMS[s] for s in po.dataset.raw_gnss.systems)
    what = "GPS L1 C/A pseudoranges" if sysnames == "GPS" else (
        f"{sysnames} first-frequency pseudoranges (one receiver clock, one offset per extra system in the epoch)")
    if corrected(po):
        what = (f"{sysnames} pseudoranges corrected in the file (satellite clock and atmosphere removed, satellite "
                "positions given; one receiver clock, one offset per extra system in the epoch)")
        weights = (f"Elevation mask {np.degrees(opts.elevation_mask):.1f} deg; sigma: the file's variances; "
                   "troposphere and ionosphere: removed in the file.")
    else:
        weights = (f"Elevation mask {np.degrees(opts.elevation_mask):.1f} deg; sigma = sqrt({opts.sigma_a:g}^2 + "
                   f"{opts.sigma_b:g}^2 / sin^2(el)) m; troposphere: {'Saastamoinen' if opts.troposphere else 'none'}; "
                   f"ionosphere: {iono}.")
    notes = [f"Single-point positioning, {what}, {used} of {len(table)} epochs solved "
             f"(status counts: {counts}).",
             weights,
             ("Errors are estimate minus the surveyed point, in NED at that point; " if po.reference is None else
              f"Errors are estimate minus the reference trajectory ({po.reference.file}) interpolated at the epoch, "
              f"in NED there; scored epochs: {po.reference.counts['scored']} of {len(table)} (not scored: "
              f"{po.reference.counts['before_reference']} before the reference, "
              f"{po.reference.counts['after_reference']} after it, {po.reference.counts['in_reference_gaps']} in "
              f"{po.reference.counts['reference_gaps']} gap(s) longer than "
              f"{float(po.dataset.reference.max_gap):g} s); availability counts every solved epoch; ") +
             "times are seconds since "
             + (f"the first epoch ({float(tr.tow[0]):.3f} s of the log: the file has no GPS time)." if corrected(po)
                else f"the first epoch (GPS week {int(tr.week[0])}, {float(tr.tow[0]):.3f} s of week)."),
             f"Measurements rejected by the reader: {po.observations.rejected or 'none'}; satellites "
             f"left out: {tr.skipped_satellites or 'none'}."]
    if po.results:
        mc = po.dataset.motion
        notes.append(f"Filters ({', '.join(po.results)}): constant velocity (white acceleration "
                     f"{mc.accel_sigma:g} m/s^2/sqrt(Hz) horizontal, {mc.vertical_accel_sigma:g} vertical; clock "
                     f"q_bias {mc.clock_q_bias:g} m^2/s, q_drift {mc.clock_q_drift:g} m^2/s^3), the same "
                     f"corrected pseudoranges and weights as the SPP, started at the first fix "
                     f"(t = {po.init.time:.2f} s).")
    sections = add_sweeps(out_dir, metrics, figs, sweeps)
    title = f"mixnav process: {po.dataset.dataset.name}"
    write_report(out_dir, title, metrics, figs, notes=notes, config_text=config_text, sections=sections,
                 web_map=map_html({n: o for n, o in oks.items() if len(o)},
                                  reference=ref if po.reference is not None else None, title=title,
                                  reference_point=None if po.reference_lla is None else
                                  (*np.degrees(po.reference_lla[:2]), po.reference_lla[2])))
    atomic_write_json(out_dir / "metrics.json", metrics)       # last: marks a complete folder
    return metrics
