"""Single-point positioning (SPP) by iterated weighted least squares: GPS L1 C/A, or several
systems' first-frequency pseudoranges (GPS, GLONASS, Galileo, BeiDou, QZSS).

Model of one pseudorange (all in metres)::

    rho_i = | R3(OMEGA_E tau_i) r_sat_i - r_rx | + b - c dt_sv_i + T_i + I_i + e_i

- ``r_sat_i``: satellite position at its transmit time in the ECEF frame of
  that time; ``R3(OMEGA_E tau_i)`` turns it into the ECEF frame of the
  reception time (Earth rotation during the travel time ``tau_i``, recomputed
  from the geometric range at every iteration).
- ``b``: receiver clock bias [m]; ``dt_sv_i``: satellite clock [s] with the
  relativistic term and T_GD (IS-GPS-200 20.3.3.3.3.1-2, see
  :mod:`mixnav.gnss.ephemeris`).
- ``T_i``: troposphere, Saastamoinen's zenith delays for a standard atmosphere
  at the receiver height (pressure 1013.25 hPa, 15 C at sea level, lapse
  6.5 K/km, relative humidity 0.5), mapped with ``1 / sin(el)``; applied when
  ``troposphere=True``. The ``1/sin`` mapping is the simple one: it is within
  a few centimetres of the Niell mapping above 15 deg, a few decimetres at
  5 deg.
- ``I_i``: ionosphere, the broadcast Klobuchar model (IS-GPS-200
  20.3.3.5.2.5, Figure 20-4) when its alpha/beta coefficients are given (the
  RINEX navigation header's ION ALPHA / ION BETA), else not applied.
- ``e_i``: noise with the elevation-dependent variance
  ``sigma_i^2 = sigma_a^2 + sigma_b^2 / sin^2(el_i)`` (the usual
  RTKLIB-style model), times a per-satellite factor if the caller gives one.
  The weights are ``1 / sigma_i^2``.

The unknowns ``x = (r_rx [m] ECEF, b [m])`` are found by Gauss-Newton
iterations of WLS, from the Earth's centre (or a given start) until the
position step is below ``tol``. The covariance is the inverse of the WLS
normal matrix ``(H^T W H)^-1`` (solved through its Cholesky factor); it is
the covariance of the estimate if the ``sigma_i`` are right. DOPs are from
the unweighted ``(H^T H)^-1`` in the local east-north-up frame. Elevation
mask, troposphere and ionosphere are applied once the iterate is within
500 km of the Earth's surface (the first steps from the Earth's centre have
no meaningful elevation).

Robust solution (``SppOptions.robust = (k0, k1)``), data snooping with IGG-III
weights, one row at a time: from the converged WLS solution, each row's
residual is standardised by its own variance in that solution, ``t_i = v_i /
sqrt(sigma_i^2 - h_i N^-1 h_i^T)`` (one gross error spreads into the other
rows' residuals through the geometry; the standardisation is what lets the bad
row stand out). The row with the largest ``t`` beyond ``k0`` gets the IGG-III
factor (:func:`mixnav.noise.igg3.igg3_factors`: a down-weighting, or weight
zero beyond ``k1``), WLS is solved again, and the remaining untouched rows are
tested the same way, until none is beyond ``k0``. It needs redundancy: with
fewer than 6 rows (2 spare) a single error cannot be located (``robust_status
= "untestable"``, plain WLS), and testing stops when fewer than 6 rows keep a
weight. A row is only blamed if the data tell it from every other row: its
standardised residual must exceed each other row's by
:data:`SEPARATION_SIGMAS` (3) standard deviations of their difference,
``sqrt(2 (1 - |r|))`` for residual correlation ``r`` (an error on row j moves
row k's standardised residual by ``r`` times j's). Otherwise the other row is
about as likely the culprit and a guess makes the solution worse, so the epoch
keeps what it has (``"not_separable"``; the phone of ``android-static``, 6 GPS
satellites and metre-level noise, is in that case at every epoch with an
injected 80 m error). A row whose residual variance is below 5 % of its
sigma^2 (the geometry hardly checks it) is not tested. The covariance is that
of the final weights.

Several systems (:func:`solve_epochs` with ``system``; :func:`wls_position` with
``system``): ``b`` is the receiver clock of the first system present (order ``G R E C
J``) and each other system with a satellite used adds an offset unknown ``b_s`` to its
pseudoranges (receiver inter-system biases, the systems' time offsets, group delays not
in the broadcast ones); ``I_i`` is Klobuchar's L1 delay times ``(f_L1 / f_i)^2``
(:func:`first_frequency`, :func:`iono_scale_factors`). The robust solution's
redundancy thresholds are then "2 rows beyond the unknowns" (6 for one system). One
system is exactly the single-system solution.

RTKLIB's weights (``SppOptions.weights = "rtklib"``): RTKLIB pntpos's variance of a
first-frequency pseudorange (demo5 EX 2.5.1 src/pntpos.c varerr and its caller, written
anew here), ``sigma_i^2 = f_s^2 0.9^2 (1 + 1/sin(max(el, 5 deg))) + sigma_eph^2 + 0.3^2 +
(0.5 I_i)^2 + (0.3 / (sin el + 0.1))^2``: the code term (RTKLIB's default error ratio 300
times 0.003 m, its ``1/sin`` not squared) with the system factor ``f_s`` (1.5 for GLONASS,
else 1), the broadcast record's orbit + clock variance (URA, SISA, 5 m for GLONASS:
:func:`mixnav.gnss.multi_ephemeris.ephemeris_variance`), the code bias, half the ionosphere
delay applied (5 m without the model) and the Saastamoinen error (3 m without). It
needs a MultiEphemeris; ``sigma_a``, ``sigma_b`` are not used; ``sigma_scale`` scales the
code term. ``weights = "rtklib-2.4.3"``: RTKLIB 2.4.3 b34's variance, the same with a code sigma
of 0.3 m instead of 0.9 m (b34's varerr scales 0.003 m by ``err[0]`` = 100, demo5's by its error
ratio 300): the variances b34's chi-square validation judges the residuals by. On urbannav-tst-static it reproduces RTKLIB demo5's single-point results
(tests/test_spp_multi.py). RTKLIB's rejection of records with URA beyond 300 m is not
copied (the record choice stays mixnav's).

Validation (``SppOptions.validate``, off by default), RTKLIB pntpos's valsol rule written
anew: a converged epoch's solution fails when the chi-square of its post-fit residuals,
``sum v_i^2 / sigma_i^2`` over the rows of the solution with their variances in it (a robust
solution: the rows it kept, at full or IGG-III-reduced weight, ``sigma_i^2 / gamma_i``; the
rows it excluded are not in it), exceeds the 99.9 % quantile of chi-square with
``rows - unknowns`` degrees of freedom (no test without a spare row), or when its GDOP
(``sqrt(PDOP^2 + TDOP^2)``: position and receiver clock of the unweighted cofactor with the
offsets' columns in the model) exceeds ``max_gdop`` (RTKLIB's 30). A failing epoch has status
:data:`STATUS_REJECTED`: no position, not a filter start, the next epoch starts from the
Earth's centre; ``SppTrack.validation`` counts the epochs by outcome. FDE (``SppOptions.fde``,
RTKLIB raim_fde's rule): a failing epoch is solved again (plain or robust, as the epoch) from
its failed solution's position and clock with each used satellite left out in turn; among
the solutions that pass validation with at least one spare row and at least 5 satellites,
the one of the smallest post-fit residual RMS [m] (unweighted, over the rows it used) is
kept if that RMS is at most 100 m (the later in row order on a tie: raim_fde keeps a
candidate whose RMS is not above the best so far); none: rejected.

Speed (``SppOptions.engine``): :func:`solve_epochs`' plain WLS goes by default through one
compiled loop over all epochs (:mod:`mixnav.gnss._spp_kernel`) after one batched satellite
computation for every observation (transmit time from its pseudorange, then once more with
the satellite clock off); ``engine = "numpy"`` is the epoch-by-epoch path through
:func:`wls_position`, the reference the compiled one equals within 1e-8 m (statuses and
counts equal; tests/test_spp_kernel.py), the robust solution included (the same data
snooping compiled).

A single epoch with fewer usable satellites than unknowns (4, plus one per extra
system) raises ``ValueError`` in :func:`wls_position`; :func:`solve_epochs` counts such
epochs as skipped (status ``"too few satellites"``) instead. A satellite at the mask
that enters and leaves from one iteration to the next (the steps never settle) is
settled by keeping the last set fixed and iterating on from there.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..geodesy.frames import dcm_ecef_to_ned, ecef_to_lla
from ..noise.igg3 import igg3_factors
# the compiled loop, and the constants it shares with this module (defined there, so that
# the import goes one way)
from ._spp_kernel import (CODE_FEW, CODE_NOT_CONVERGED, CODE_OK, CODE_REJECTED, VALID_CHI2, VALID_FDE,
                          VALID_GDOP, VALID_PASSED, RTKLIB_CODE_BIAS_SIGMA,  # noqa: F401
                          RTKLIB_CODE_SIGMA, RTKLIB_243_CODE_SIGMA,  # noqa: F401
                          RTKLIB_CODE_SIGMAS, RTKLIB_FDE_MAX_RMS, RTKLIB_FDE_MIN_SATELLITES, RTKLIB_IONO_FACTOR,
                          RTKLIB_IONO_OFF_SIGMA, RTKLIB_MIN_ELEVATION,
                          RTKLIB_MAX_GDOP, RTKLIB_SYSTEM_FACTOR, RTKLIB_TROPO_OFF_SIGMA, RTKLIB_TROPO_SIGMA,
                          SEPARATION_SIGMAS, spp_epochs)
from .geometry import C_LIGHT, F_L1, LAMBDA_L1, SatelliteStates, earth_rotation_correction, elevation_azimuth

#: Epoch status codes of :func:`solve_epochs`.
STATUS_OK = "ok"
STATUS_FEW = "too few satellites"
STATUS_NOT_CONVERGED = "not converged"
STATUS_REJECTED = "rejected by validation"
#: validation's chi-square test: the solution fails beyond this quantile (RTKLIB valsol's)
VALIDATION_PROBABILITY = 0.999


@dataclass(frozen=True)
class SppOptions:
    """Settings of the SPP solver (SI units, angles in rad).

    Attributes
    ----------
    elevation_mask : float
        Satellites below it are not used [rad].
    sigma_a, sigma_b : float
        Constant and ``1/sin(el)`` parts of the pseudorange sigma [m].
    troposphere, ionosphere : bool
        Apply the Saastamoinen and (if coefficients are given) Klobuchar
        models.
    max_iter : int
        Gauss-Newton iterations at most.
    tol : float
        Convergence when the position step is below it [m].
    robust : tuple (k0, k1) or None
        IGG-III thresholds on standardised residuals: the robust solution
        (module docstring, "Robust solution"); None: plain WLS.
    weights : {"elevation", "rtklib", "rtklib-2.4.3"}
        The pseudorange variance: ``"elevation"`` mixnav's ``sigma_a^2 + sigma_b^2 /
        sin^2(el)`` (module docstring); ``"rtklib"`` RTKLIB demo5 pntpos's, ``"rtklib-2.4.3"``
        RTKLIB 2.4.3 b34's (module docstring, "RTKLIB's weights"; ``sigma_a``, ``sigma_b`` not
        used), which need each satellite's broadcast accuracy (a MultiEphemeris).
    engine : {"compiled", "numpy"}
        :func:`solve_epochs`'s plain WLS: satellite states of all epochs in one batched
        call and one compiled loop over the epochs (:mod:`mixnav.gnss._spp_kernel`), or
        the numpy solution epoch by epoch (:func:`wls_position`), kept as the reference
        the compiled one is tested against (equal within 1e-6 m), the robust solution
        included.
    validate : bool
        Validate each converged solution as RTKLIB pntpos does (module docstring,
        "Validation"): chi-square of the weighted post-fit residuals and GDOP; a failing
        epoch is not a solution (status :data:`STATUS_REJECTED`). Off: no epoch is tested.
    fde : bool
        With ``validate``: a failing epoch is solved again with each used satellite left out
        in turn; the passing solution of the smallest residual RMS (at most 100 m, 5
        satellites or more) is kept (module docstring, "Validation").
    max_gdop : float
        Validation's GDOP limit (RTKLIB's default 30).
    """

    elevation_mask: float = np.deg2rad(10.0)
    sigma_a: float = 3.0
    sigma_b: float = 3.0
    troposphere: bool = True
    ionosphere: bool = True
    max_iter: int = 15
    tol: float = 1e-4
    robust: tuple[float, float] | None = None
    weights: str = "elevation"
    engine: str = "compiled"
    validate: bool = False
    fde: bool = False
    max_gdop: float = RTKLIB_MAX_GDOP

    def __post_init__(self):
        if self.fde and not self.validate:
            raise ValueError("fde: needs validate (an exclusion is tried when an epoch fails validation)")
        if not self.max_gdop > 0.0:
            raise ValueError(f"max_gdop: must be > 0, got {self.max_gdop}")
        if self.weights not in ("elevation", *RTKLIB_CODE_SIGMAS):
            raise ValueError(f"weights: must be 'elevation', 'rtklib' or 'rtklib-2.4.3', not {self.weights!r}")
        if self.engine not in ("compiled", "numpy"):
            raise ValueError(f"engine: must be 'compiled' or 'numpy', not {self.engine!r}")
        if self.robust is not None:
            k0, k1 = self.robust
            if not 0.0 < k0 < k1:
                raise ValueError(f"robust: need 0 < k0 < k1, got k0 = {k0}, k1 = {k1}")


@dataclass(frozen=True)
class SppSolution:
    """One epoch's WLS solution.

    Attributes
    ----------
    pos_ecef : ndarray (3,)
        Receiver position [m].
    clock_bias : float
        Receiver clock bias [m] (divide by c for seconds).
    cov : ndarray (4, 4)
        ``(H^T W H)^-1`` of (x, y, z, b) [m^2].
    residuals : ndarray (k,)
        Post-fit residuals, measured minus modelled [m], of the used satellites.
    prn : ndarray of int (k,)
        Satellites used.
    elevation : ndarray (k,)
        [rad].
    dop : dict
        ``gdop, pdop, hdop, vdop, tdop``.
    iterations : int
    converged : bool
    n_rejected_mask : int
        Satellites left out by the elevation mask.
    n_downweighted, n_excluded : int
        Rows the robust solution down-weighted, and left out (weight zero).
    robust_status : str
        ``"off"`` (plain WLS), ``"ok"`` (rows tested, weighed where needed),
        ``"untestable"`` (fewer than 2 rows beyond the unknowns, 6 for one system: plain
        WLS) or ``"not_separable"`` (the suspect row's residual moves with another's: left
        as it was). Module docstring.
    chi2, dof : float, int
        Sum of the squared post-fit residuals over their variances in the solution (a
        robust solution's kept rows with their IGG-III-reduced weights), and rows minus
        unknowns.
    validation : str
        ``"off"`` (not validated), ``"passed"``, ``"fde"`` (passed once satellite
        ``excluded`` was left out), or why it failed: ``"chi-square"``, ``"gdop"``.
    excluded : int
        Index in the input satellites of the one FDE left out (-1 none).
    used_index : ndarray of int (k,)
        Index in the input satellites of each satellite used.
    system : ndarray of str (k,) or None
        System letter of each satellite used (None: one system, no ``system`` given).
    offsets : dict of str -> float
        Several systems: the inter-system offset [m] of each system other than the
        clock's (the first of ``G R E C J`` with a satellite used), added to the clock
        for that system's pseudoranges; the clock's own system maps to 0. Empty for one
        system. ``cov`` is then ``(4 + len(offsets) - 1)`` square, offsets in the order
        of ``offsets``.
    """

    pos_ecef: np.ndarray
    clock_bias: float
    cov: np.ndarray
    residuals: np.ndarray
    prn: np.ndarray
    elevation: np.ndarray
    dop: dict
    iterations: int
    converged: bool
    n_rejected_mask: int = 0
    n_downweighted: int = 0
    n_excluded: int = 0
    robust_status: str = "off"
    system: np.ndarray | None = None
    offsets: dict = field(default_factory=dict)
    chi2: float = float("nan")
    dof: int = 0
    validation: str = "off"
    excluded: int = -1
    used_index: np.ndarray | None = None

    @property
    def n_sat(self) -> int:
        return len(self.prn)

    @property
    def valid(self) -> bool:
        """False when validation rejected the epoch (``validation`` a failure reason)."""
        return self.validation in ("off", "passed", "fde")


# ---------------------------------------------------------------- atmosphere
def saastamoinen(lat, h, elevation, humidity: float = 0.5):
    """Tropospheric delay [m] for a standard atmosphere (Saastamoinen 1972).

    Parameters
    ----------
    lat : float
        Receiver geodetic latitude [rad].
    h : float
        Receiver ellipsoidal height [m] (used as height above sea level;
        clipped to [0, 10 km] for the standard atmosphere).
    elevation : ndarray (n,)
        [rad], > 0.
    humidity : float
        Relative humidity in [0, 1].
    """
    hgt = float(np.clip(h, 0.0, 1.0e4))
    p_hpa = 1013.25 * (1.0 - 2.2557e-5 * hgt) ** 5.2568          # standard atmosphere
    t_k = 288.15 - 6.5e-3 * hgt
    t_c = t_k - 273.15
    e_hpa = 6.108 * humidity * np.exp(17.15 * t_c / (t_c + 234.7))  # water vapour pressure (Magnus)
    zhd = 0.0022768 * p_hpa / (1.0 - 0.00266 * np.cos(2.0 * lat) - 0.00028 * hgt / 1e3)
    zwd = 0.002277 * (1255.0 / t_k + 0.05) * e_hpa
    return (zhd + zwd) / np.sin(np.asarray(elevation, float))


def klobuchar(lat, lon, elevation, azimuth, tow, alpha, beta):
    """Broadcast ionospheric L1 delay [m] (IS-GPS-200 20.3.3.5.2.5, Figure 20-4).

    Parameters
    ----------
    lat, lon : float
        Receiver geodetic latitude, longitude [rad].
    elevation, azimuth : ndarray (n,)
        [rad].
    tow : float
        GPS seconds of week of the reception [s].
    alpha, beta : ndarray (4,)
        Broadcast coefficients (s, s/semicircle^k).
    """
    el = np.asarray(elevation, float) / np.pi                      # semicircles
    az = np.asarray(azimuth, float)
    phi_u, lam_u = lat / np.pi, lon / np.pi
    psi = 0.0137 / (el + 0.11) - 0.022                              # Earth's central angle
    phi_i = np.clip(phi_u + psi * np.cos(az), -0.416, 0.416)       # sub-ionospheric latitude
    lam_i = lam_u + psi * np.sin(az) / np.cos(phi_i * np.pi)       # and longitude
    phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * np.pi)        # geomagnetic latitude
    t = np.mod(4.32e4 * lam_i + tow, 86400.0)                       # local time
    f = 1.0 + 16.0 * (0.53 - el) ** 3                               # obliquity factor
    powers = phi_m[:, None] ** np.arange(4)
    amp = np.maximum(powers @ np.asarray(alpha, float), 0.0)
    per = np.maximum(powers @ np.asarray(beta, float), 72000.0)
    x = 2.0 * np.pi * (t - 50400.0) / per
    day = f * (5.0e-9 + amp * (1.0 - x**2 / 2.0 + x**4 / 24.0))
    return C_LIGHT * np.where(np.abs(x) < 1.57, day, f * 5.0e-9)


# ---------------------------------------------------------------- solver
def _dops(H: np.ndarray, pos_ecef: np.ndarray) -> dict:
    lla = ecef_to_lla(pos_ecef)
    c_ne = dcm_ecef_to_ned(lla[0], lla[1])
    c_ue = np.array([c_ne[1], c_ne[0], -c_ne[2]])                  # ECEF -> ENU
    G = np.column_stack([H[:, :3] @ c_ue.T, H[:, 3:]])          # clock (and offsets) columns
    q = np.linalg.solve(G.T @ G, np.eye(G.shape[1]))
    d = np.diag(q)
    return {"gdop": float(np.sqrt(d.sum())), "pdop": float(np.sqrt(d[:3].sum())),
            "hdop": float(np.sqrt(d[:2].sum())), "vdop": float(np.sqrt(d[2])), "tdop": float(np.sqrt(d[3]))}


def wls_position(pseudorange, sats: SatelliteStates, options: SppOptions = SppOptions(), x0=None,
                 sigma_scale=None, iono_alpha=None, iono_beta=None, tow: float = 0.0, system=None,
                 iono_scale=None, ephemeris_var=None) -> SppSolution:
    """WLS position and clock of one epoch (one or several systems).

    Several systems (``system`` naming more than one): the unknowns are position, the
    clock of the first system present (order ``G R E C J``) and one inter-system offset
    [m] per other system that has a satellite in the epoch (module docstring of
    :func:`solve_epochs`); a system whose satellites all fall below the mask loses its
    offset. One system (``system`` None or one letter throughout): exactly the
    single-system solution.

    Parameters
    ----------
    pseudorange : ndarray (n,)
        Measured pseudoranges [m], one per satellite of ``sats``.
    sats : SatelliteStates
        The satellites at their transmit times (ECEF of the transmit time),
        with their clocks [s].
    options : SppOptions
    x0 : ndarray (4,) or (4 + offsets,) or None
        Start (ECEF position [m], clock [m], offsets [m], zeros when not given); None: the
        Earth's centre.
    sigma_scale : ndarray (n,) or None
        Per-satellite factor on the elevation-dependent sigma.
    iono_alpha, iono_beta : ndarray (4,) or None
        Klobuchar coefficients; the model is applied when both are given and
        ``options.ionosphere``.
    tow : float
        Reception time of week [s] (Klobuchar's local time).
    system : array_like of str (n,) or None
        RINEX system letter of each satellite; None: one system.
    iono_scale : ndarray (n,) or None
        Factor on the Klobuchar (L1) delay per satellite, ``(f_L1 / f)^2`` for a signal
        on frequency ``f`` (:func:`iono_scale_factors`); None: 1.
    ephemeris_var : ndarray (n,) or None
        Orbit + clock variance [m^2] of each satellite's record
        (:meth:`~mixnav.gnss.multi_ephemeris.MultiEphemeris.ephemeris_variances`): needed by
        ``options.weights = "rtklib"``, not used otherwise.

    Raises
    ------
    ValueError
        Fewer satellites than unknowns (given, or left after the elevation mask: 4, plus
        one per extra system), or inputs of inconsistent length.
    """
    rho = np.asarray(pseudorange, float)
    n = len(sats)
    if rho.shape != (n,):
        raise ValueError(f"pseudorange has shape {rho.shape}, expected ({n},) (one per satellite)")
    if not np.all(np.isfinite(rho)):
        raise ValueError("pseudoranges must be finite")
    if n < 4:
        raise ValueError(f"{n} satellites: at least 4 are needed for position and clock")
    scale = np.ones(n) if sigma_scale is None else np.asarray(sigma_scale, float)
    sys_col, letters = _system_columns(system, n)
    n_off = len(letters) - 1 if sys_col is not None else 0
    x = np.zeros(4 + n_off)
    if x0 is not None:
        start = np.asarray(x0, float)
        x[:len(start)] = start[:len(x)]
    if iono_scale is not None:
        iono_scale = np.asarray(iono_scale, float)
        if iono_scale.shape != (n,):
            raise ValueError(f"iono_scale has shape {iono_scale.shape}, expected ({n},)")
    rho_corr = rho + C_LIGHT * sats.clock_bias                      # satellite clock removed
    rtk = None
    if options.weights != "elevation":
        if ephemeris_var is None:
            raise ValueError("weights = 'rtklib' needs ephemeris_var (each satellite's broadcast accuracy)")
        letters_n = np.full(n, "G") if system is None else np.asarray(system).astype(str)
        fact = np.array([RTKLIB_SYSTEM_FACTOR.get(c, 1.0) for c in letters_n.tolist()])
        rtk = (fact, np.asarray(ephemeris_var, float))
    atm = (options, iono_alpha, iono_beta, tow, iono_scale, sys_col, n_off, rtk)
    x, sel, it, converged = _gauss_newton(rho_corr, sats, x, scale, np.ones(n, bool), atm)
    if not converged and abs(np.linalg.norm(x[:3]) - 6.371e6) < 5e5:
        # a satellite at the mask can enter and leave from one step to the next, so the steps
        # never settle: the last step's set is kept fixed and the iterations go on from there
        x, sel, k, converged = _gauss_newton(rho_corr, sats, x, scale, sel, atm, mask=False)
        it += k
    gamma, status = np.ones(n), "off"
    if options.robust is not None and converged:
        x, gamma, status, k = _igg3_solution(rho_corr, sats, x, scale, sel, atm)
        it += k
    # post-fit quantities at the final estimate (the last step is below tol)
    used = sel & (gamma > 0)
    H, model, el, iono = _linearise(x, sats, atm, always=True)
    sigma = _sigma(options, el, scale, atm, iono)[used] / np.sqrt(gamma[used])
    act = _active(used, sys_col, n_off)
    H = H[used] if act is None else H[used][:, act]
    N = H.T @ (H / sigma[:, None] ** 2)
    L = np.linalg.cholesky(N)
    L_inv = np.linalg.solve(L, np.eye(H.shape[1]))
    cov = L_inv.T @ L_inv
    offsets: dict = {}
    sys_used = None
    if sys_col is not None:
        full = np.full((4 + n_off, 4 + n_off), np.nan)
        full[np.ix_(act, act)] = cov
        cov = full
        sys_used = np.asarray(system).astype(str)[used]
        ref = letters[0] if np.any(used & (sys_col < 0)) else None
        for k, letter in enumerate(letters[1:]):
            if act[4 + k]:
                offsets[letter] = float(x[4 + k])
            elif ref is None and np.any(used & (sys_col == k)):
                ref = letter                                     # the clock took this system
        if ref is not None:
            offsets = {ref: 0.0, **offsets}
    residuals = (rho_corr - model)[used]
    sol = SppSolution(pos_ecef=x[:3].copy(), clock_bias=float(x[3]), cov=cov, residuals=residuals,
                      prn=np.asarray(sats.prn)[used], elevation=el[used], dop=_dops(H, x[:3]), iterations=it,
                      converged=converged, n_rejected_mask=int(n - sel.sum()),
                      n_downweighted=int(np.sum((gamma > 0) & (gamma < 1))), n_excluded=int(np.sum(gamma == 0)),
                      robust_status=status, system=sys_used, offsets=offsets,
                      chi2=float(np.sum((residuals / sigma) ** 2)), dof=int(H.shape[0] - H.shape[1]),
                      used_index=np.flatnonzero(used))
    if not (options.validate and converged):
        return sol
    why = _validation_failure(sol, options)
    if why is None:
        return dataclasses.replace(sol, validation="passed")
    if not options.fde:
        return dataclasses.replace(sol, validation=why)
    # FDE: each used satellite left out in turn, from this solution's position and clock;
    # the passing solution of the smallest post-fit residual RMS [m], at most
    # RTKLIB_FDE_MAX_RMS, with at least RTKLIB_FDE_MIN_SATELLITES rows, the later on a tie
    # (RTKLIB raim_fde)
    inner = dataclasses.replace(options, validate=False, fde=False)
    start = np.append(sol.pos_ecef, sol.clock_bias)
    best, best_score = None, RTKLIB_FDE_MAX_RMS
    for i in sol.used_index.tolist():
        others = np.arange(n) != i
        try:
            cand = wls_position(rho[others], sats.select(others), inner, x0=start, sigma_scale=scale[others],
                                iono_alpha=iono_alpha, iono_beta=iono_beta, tow=tow,
                                system=None if system is None else np.asarray(system)[others],
                                iono_scale=None if iono_scale is None else iono_scale[others],
                                ephemeris_var=None if ephemeris_var is None else np.asarray(ephemeris_var)[others])
        except (ValueError, np.linalg.LinAlgError):
            continue
        # a candidate with no spare row has nothing to check it by: not a validated solution
        if not cand.converged or cand.dof < 1 or cand.n_sat < RTKLIB_FDE_MIN_SATELLITES or \
                _validation_failure(cand, options) is not None:
            continue
        score = float(np.sqrt(np.mean(cand.residuals ** 2)))
        if score <= best_score:
            best, best_score = (i, cand), score
    if best is None:
        return dataclasses.replace(sol, validation=why)
    i, cand = best
    keep = np.flatnonzero(np.arange(n) != i)
    return dataclasses.replace(cand, validation="fde", excluded=int(i), used_index=keep[cand.used_index],
                               iterations=sol.iterations + cand.iterations)


def chi2_limit(dof: int) -> float:
    """The chi-square quantile of :data:`VALIDATION_PROBABILITY` for ``dof`` >= 1 degrees of
    freedom (the table the compiled loop uses too)."""
    return float(_chi2_table()[dof - 1])


_CHI2_TABLE = None


def _chi2_table() -> np.ndarray:
    """Quantiles for 1..256 degrees of freedom (more rows than any epoch has)."""
    global _CHI2_TABLE
    if _CHI2_TABLE is None:
        from scipy.stats import chi2
        _CHI2_TABLE = chi2.ppf(VALIDATION_PROBABILITY, np.arange(1, 257))
    return _CHI2_TABLE


def _validation_failure(sol: SppSolution, options: SppOptions):
    """Why ``sol`` fails validation (``"chi-square"``, ``"gdop"``), None when it passes: the
    chi-square of its weighted residuals beyond :func:`chi2_limit` of its spare rows (not
    tested without a spare row), then its GDOP (position and receiver clock) beyond
    ``options.max_gdop``."""
    if sol.dof >= 1 and sol.chi2 > chi2_limit(sol.dof):
        return "chi-square"
    if np.hypot(sol.dop["pdop"], sol.dop["tdop"]) > options.max_gdop:
        return "gdop"
    return None


#: the order in which systems take the receiver clock (the first present) and their offsets
SYSTEM_ORDER = ("G", "R", "E", "C", "J")


def _system_columns(system, n: int):
    """``(sys_col, letters)``: per satellite the index of its offset unknown (-1: the
    clock's system) and the systems present in clock-then-offset order; ``sys_col`` None
    for one system (the single-system solution)."""
    if system is None:
        return None, ()
    sysarr = np.asarray(system).astype(str)
    if sysarr.shape != (n,):
        raise ValueError(f"system has shape {sysarr.shape}, expected ({n},) (one per satellite)")
    seen = set(sysarr.tolist())
    letters = tuple(s for s in SYSTEM_ORDER if s in seen) + tuple(sorted(seen - set(SYSTEM_ORDER)))
    if len(letters) < 2:
        return None, letters
    sys_col = np.full(n, -1, dtype=np.int64)
    for k, letter in enumerate(letters[1:]):
        sys_col[sysarr == letter] = k
    return sys_col, letters


def _active(rows, sys_col, n_off: int):
    """Which unknowns the rows ``rows`` (bool (n,)) determine: position and clock, and the
    offset of each system with a row; when the clock's system has none, the first system
    with rows takes the clock (its offset held). None for one system."""
    if sys_col is None:
        return None
    has = np.array([bool(np.any(rows & (sys_col == k))) for k in range(n_off)], dtype=bool)
    act = np.concatenate([np.ones(4, bool), has])
    if not np.any(rows & (sys_col < 0)) and has.any():
        act[4 + int(np.argmax(has))] = False
    return act


def _sigma(options: SppOptions, el, scale, atm=None, iono=None):
    """The pseudorange sigma [m] (module docstring): mixnav's elevation model, or RTKLIB's
    (``atm``'s per-row system factors and ephemeris variances, ``iono`` the ionosphere
    delays applied, None when not)."""
    if options.weights == "elevation":
        return scale * np.sqrt(options.sigma_a**2 + options.sigma_b**2 / np.sin(np.maximum(el, 1e-3)) ** 2)
    fact, var_eph = atm[7]
    code = (scale * fact * RTKLIB_CODE_SIGMAS[options.weights]) ** 2 * \
        (1.0 + 1.0 / np.sin(np.maximum(el, RTKLIB_MIN_ELEVATION)))
    ion = RTKLIB_IONO_OFF_SIGMA**2 if iono is None else (RTKLIB_IONO_FACTOR * iono) ** 2
    trop = ((RTKLIB_TROPO_SIGMA / (np.sin(np.maximum(el, 0.0)) + 0.1)) ** 2 if options.troposphere
            else RTKLIB_TROPO_OFF_SIGMA**2)
    return np.sqrt(code + var_eph + RTKLIB_CODE_BIAS_SIGMA**2 + ion + trop)


def _linearise(x, sats, atm, always: bool = False):
    """Design matrix (n, 4), modelled pseudoranges (n,), elevations (n,) at ``x`` and the
    ionosphere delays in the model (n,) (None when the ionosphere is not applied; zeros
    before the atmosphere is); the atmosphere (and true elevations) once ``x`` is within
    500 km of the surface, or ``always``."""
    options, iono_alpha, iono_beta, tow, iono_scale, sys_col, n_off, rtk = atm
    r_geo = np.linalg.norm(sats.pos_ecef - x[:3], axis=1)
    sat_rx = earth_rotation_correction(sats.pos_ecef, r_geo / C_LIGHT)
    rng = np.linalg.norm(sat_rx - x[:3], axis=1)
    u = (sat_rx - x[:3]) / rng[:, None]
    model = rng + x[3]
    if sys_col is not None:
        model = model + np.append(x[4:], 0.0)[sys_col]             # index -1: the clock's system
    el = np.full(len(rng), np.pi / 2)
    iono_on = options.ionosphere and iono_alpha is not None and iono_beta is not None
    iono = np.zeros(len(rng)) if iono_on else None
    if always or abs(np.linalg.norm(x[:3]) - 6.371e6) < 5e5:
        el, az = elevation_azimuth(x[:3], sat_rx)
        lla = ecef_to_lla(x[:3])
        if rtk is None:
            model = model + atmosphere_delay(lla, el, az, tow, options, iono_alpha, iono_beta,
                                             iono_scale=iono_scale)
        else:   # RTKLIB's weights need the ionosphere part apart
            if iono_on:
                iono = atmosphere_delay(lla, el, az, tow, dataclasses.replace(options, troposphere=False),
                                        iono_alpha, iono_beta, iono_scale=iono_scale)
            model = model + atmosphere_delay(lla, el, az, tow, dataclasses.replace(options, ionosphere=False))
            if iono_on:
                model = model + iono
    H = np.column_stack([-u, np.ones(len(rng))])
    if sys_col is not None:
        H = np.hstack([H, (sys_col[:, None] == np.arange(n_off)[None, :]).astype(float)])
    return H, model, el, iono


def _gauss_newton(rho_corr, sats, x, scale, use, atm, mask: bool = True, gamma=None):
    """WLS iterations from ``x`` on the rows ``use`` above the elevation mask (``mask``
    False: on the rows ``use`` as they are): ``(x, sel, iterations, converged)``, ``sel``
    the rows of the last step; ``gamma`` (n,) weight factors (the robust solution's)."""
    options = atm[0]
    sel = use.copy()
    converged = False
    it = 0
    for it in range(1, options.max_iter + 1):
        near_surface = abs(np.linalg.norm(x[:3]) - 6.371e6) < 5e5
        H, model, el, iono = _linearise(x, sats, atm)
        sel = use.copy()
        if near_surface and mask:
            # the rows below the mask are left out of the solution: what is added to them is moot
            sel &= el >= options.elevation_mask
        act = _active(sel, atm[5], atm[6])
        need = 4 if act is None else int(act.sum())
        if sel.sum() < need:
            raise ValueError(f"{int(sel.sum())} satellites above the elevation mask "
                             f"({np.rad2deg(options.elevation_mask):.1f} deg): at least {need} are needed")
        sigma = _sigma(options, el, scale, atm, iono)
        if gamma is not None:
            sigma = sigma / np.sqrt(gamma)
        Hs = H[sel] if act is None else H[sel][:, act]
        w = 1.0 / sigma[sel] ** 2
        dz = (rho_corr - model)[sel]
        N = Hs.T @ (w[:, None] * Hs)
        L = np.linalg.cholesky(N)
        dx = np.linalg.solve(L.T, np.linalg.solve(L, Hs.T @ (w * dz)))
        if act is None:
            x = x + dx
        else:
            step = np.zeros(len(x))
            step[act] = dx
            x = x + step
        if np.linalg.norm(dx[:3]) < options.tol and near_surface:
            converged = True
            break
    return x, sel, it, converged


def _igg3_solution(rho_corr, sats, x_plain, scale, sel, atm):
    """The robust solution from the converged plain one (module docstring, "Robust
    solution"): ``(x, gamma, status, iterations)``, ``gamma`` (n,) the weight factors."""
    options = atm[0]
    k0, k1 = options.robust
    n = len(rho_corr)
    act = _active(sel, atm[5], atm[6])
    if int(sel.sum()) < (4 if act is None else int(act.sum())) + 2:
        return x_plain, np.ones(n), "untestable", 0
    x, gamma, iterations, status = x_plain, np.ones(n), 0, "ok"
    touched = ~sel.copy()
    while True:
        keep = sel & (gamma > 0)
        act = _active(keep, atm[5], atm[6])
        # one more row out would leave nothing to check it by (two rows beyond the unknowns)
        if int(keep.sum()) < (4 if act is None else int(act.sum())) + 2:
            break
        H, model, el, iono = _linearise(x, sats, atm)
        sigma = _sigma(options, el, scale, atm, iono)[keep] / np.sqrt(gamma[keep])
        Hs = H[keep] if act is None else H[keep][:, act]
        N_inv = np.linalg.inv(Hs.T @ (Hs / sigma[:, None] ** 2))
        # each residual's own variance in this solution, sigma^2 - h N^-1 h^T: the standardisation
        q = sigma**2 - np.einsum("ij,jk,ik->i", Hs, N_inv, Hs)
        idx = np.nonzero(keep)[0]
        # a row the geometry can hardly check, or one already weighed, is not tested again
        ok = (q > 0.05 * sigma**2) & ~touched[idx]
        if not ok.any():
            break
        t_all = np.abs((rho_corr - model)[idx]) / np.sqrt(np.maximum(q, 1e-300))
        t = np.where(ok, t_all, 0.0)
        j = int(np.argmax(t))
        if t[j] <= k0:
            break
        # blame row j only if the data tell it from every other row k: under "the error is on
        # j" the gap t_j - t_k has mean (1 - |r_jk|) delta and sd sqrt(2 (1 - |r_jk|)), r_jk
        # the residuals' correlation; a gap under SEPARATION_SIGMAS sds (rows whose residuals
        # move together: low redundancy for the geometry) and k is about as likely the culprit
        Q = np.diag(sigma**2) - Hs @ N_inv @ Hs.T
        r = np.abs(Q[j]) / np.sqrt(np.maximum(q[j] * q, 1e-300))
        gap = t[j] - t_all
        sd = np.sqrt(2.0 * np.maximum(1.0 - r, 0.0))
        others = np.arange(len(idx)) != j
        if np.any(others & ((r > 0.999) | (gap < SEPARATION_SIGMAS * sd))):
            status = "not_separable"
            break
        worst = idx[j]
        gamma[worst] = igg3_factors(t[j:j + 1], k0, k1)[0]
        touched[worst] = True
        keep = sel & (gamma > 0)
        if options.weights == "elevation":
            eff = np.where(keep, scale / np.sqrt(np.where(keep, gamma, 1.0)), scale)
            x, _, k, _ = _gauss_newton(rho_corr, sats, x, eff, keep, atm)
        else:   # the factor on the whole variance, not on its code part
            x, _, k, _ = _gauss_newton(rho_corr, sats, x, scale, keep, atm, gamma=np.where(keep, gamma, 1.0))
        iterations += k
    return x, gamma, status, iterations


def satellites_at_transmit(ephemeris, prn, pseudorange, week, tow_rx, apply_tgd: bool = True):
    """Satellite states at each signal's transmit time.

    The transmit time in GPS time is ``t_rx - rho / c - dt_sv`` (the
    pseudorange measures the receiver clock minus the satellite clock);
    ``dt_sv`` is taken from a first evaluation at ``t_rx - rho / c`` (its
    change over that microseconds-to-milliseconds shift is far below 1 ns).

    Returns
    -------
    states : SatelliteStates
        The satellites with usable ephemeris.
    keep : ndarray of bool (n,)
        Which of the inputs they are.
    skips : EphemerisSkips
    """
    prn = np.asarray(prn, int)
    rho = np.asarray(pseudorange, float)
    t_tx = tow_rx - rho / C_LIGHT
    first, skips = ephemeris.states_and_skips(week, t_tx, prn, apply_tgd=apply_tgd)
    keep = ~np.isin(prn, skips.prn)
    t_tx = t_tx[keep] - first.clock_bias
    states = ephemeris.states(week, t_tx, prn[keep], apply_tgd=apply_tgd)
    return states, keep, skips


#: BeiDou B1I carrier [Hz] (BDS-SIS-ICD-B1I 3.0, 4.2)
F_B1I = 1561.098e6
#: GLONASS L1 FDMA carrier of channel k: ``F_G1 + k * DF_G1`` [Hz] (GLONASS ICD 5.1, 3.3.1.4)
F_G1, DF_G1 = 1602.0e6, 0.5625e6
#: a GLONASS satellite without a frequency channel number, when the ionosphere is applied
NO_GLONASS_CHANNEL = "no GLONASS frequency number"


def first_frequency(system, channel=None) -> np.ndarray:
    """Carrier frequency [Hz] (m,) of each system's first-frequency civil signal, the one
    the SPP models (group delays of :mod:`mixnav.gnss.multi_ephemeris`): GPS L1, QZSS L1 and
    Galileo E1 1575.42 MHz, BeiDou B1I 1561.098 MHz, GLONASS G1 ``1602 + 0.5625 k`` MHz
    with the channel ``k`` of ``channel`` (m,) (NaN where it is missing or out of -7..13).

    Parameters
    ----------
    system : array_like of str (m,)
        RINEX system letters.
    channel : array_like of int (m,) or None
        GLONASS frequency channel numbers (any value for other systems).
    """
    sysarr = np.asarray(system).astype(str)
    f = np.full(len(sysarr), F_L1)
    f[sysarr == "C"] = F_B1I
    glo = sysarr == "R"
    if glo.any():
        k = np.full(len(sysarr), np.nan) if channel is None else np.asarray(channel, float)
        ok = glo & (k >= -7) & (k <= 13)
        f[glo] = np.nan
        f[ok] = F_G1 + k[ok] * DF_G1
    return f


def iono_scale_factors(frequency) -> np.ndarray:
    """``(f_L1 / f)^2`` (m,): the ionospheric group delay on frequency ``f`` [Hz] relative
    to GPS L1's (first order, delay proportional to ``1 / f^2``), what the Klobuchar L1
    delay is multiplied by."""
    return (F_L1 / np.asarray(frequency, float)) ** 2


def satellites_at_transmit_multi(ephemeris, sat_ids, pseudorange, week, tow_rx, apply_tgd: bool = True):
    """:func:`satellites_at_transmit` over several systems
    (:class:`~mixnav.gnss.multi_ephemeris.MultiEphemeris`, queried in GPS time; each system
    converts to its own time scale, BDT for BeiDou, GLONASST for GLONASS).

    Parameters
    ----------
    sat_ids : array_like of str (n,)
        Satellites like ``"G05"``, ``"C08"``.
    pseudorange : ndarray (n,)
        [m].
    week, tow_rx : int, float
        Reception time (GPS week, seconds of week [s]).

    Returns
    -------
    states : SatelliteStates
        The satellites with usable ephemeris (``prn`` within their system).
    system : ndarray of str (k,)
        Their system letters.
    keep : ndarray of bool (n,)
        Which of the inputs they are.
    skips : dict of str -> EphemerisSkips
        Per system letter, the satellites left out and why.
    """
    ids = np.asarray(sat_ids)
    rho = np.asarray(pseudorange, float)
    t_tx = tow_rx - rho / C_LIGHT
    first, _, keep, skips = ephemeris.states_of(ids, week, t_tx, apply_tgd)
    states, letters, again, _ = ephemeris.states_of(ids[keep], week, t_tx[keep] - first.clock_bias, apply_tgd)
    if not again.all():   # a record choice flipped within the travel time: left out with it
        keep[np.flatnonzero(keep)[~again]] = False
    return states, letters, keep, skips


@dataclass
class SppTrack:
    """Epoch-by-epoch SPP (epochs without a solution hold NaN).

    Attributes
    ----------
    week : ndarray (k,)
    tow : ndarray (k,)
        Reception time, GPS week and seconds of week [s].
    pos_ecef : ndarray (k, 3)
        [m].
    clock_bias : ndarray (k,)
        [m].
    cov : ndarray (k, 4, 4)
        [m^2].
    n_sat : ndarray of int (k,)
        Satellites used.
    pdop, hdop, vdop : ndarray (k,)
    rms_residual : ndarray (k,)
        [m].
    status : ndarray of str (k,)
        ``ok``, ``too few satellites``, ``not converged`` or ``rejected by validation``.
    skipped_satellites : dict
        Satellite observations left out over all epochs, per reason
        (ephemeris reasons and ``below elevation mask``).
    robust : dict
        The robust solution's counts over the solved epochs (empty for plain
        WLS): ``rows_downweighted``, ``rows_excluded``, and the epochs per
        :attr:`SppSolution.robust_status`.
    offsets : dict of str -> ndarray (k,)
        Several systems: per system letter its offset to the receiver clock [m] at each
        epoch (0 for the clock's system, NaN where the system had no satellite used or
        the epoch no solution); empty for one system.
    clock_system : ndarray of str (k,) or None
        Several systems: the system whose time ``clock_bias`` is ("" where unsolved).
    n_sat_system : dict of str -> ndarray of int (k,)
        Several systems: satellites used per system letter.
    skipped_by_system : dict of str -> dict
        Several systems: per system name (``GPS``, ``BeiDou``...) the satellite
        observations left out per reason (the ones in ``skipped_satellites``).
    validation : dict
        ``SppOptions.validate``: over the converged epochs, ``epochs_passed``,
        ``epochs_passed_after_exclusion`` (FDE) and ``epochs_rejected_chi-square``,
        ``epochs_rejected_gdop`` (status :data:`STATUS_REJECTED`); empty when off.
    """

    week: np.ndarray
    tow: np.ndarray
    pos_ecef: np.ndarray
    clock_bias: np.ndarray
    cov: np.ndarray
    n_sat: np.ndarray
    pdop: np.ndarray
    hdop: np.ndarray
    vdop: np.ndarray
    rms_residual: np.ndarray
    status: np.ndarray
    skipped_satellites: dict = field(default_factory=dict)
    robust: dict = field(default_factory=dict)
    offsets: dict = field(default_factory=dict)
    clock_system: np.ndarray | None = None
    n_sat_system: dict = field(default_factory=dict)
    skipped_by_system: dict = field(default_factory=dict)
    validation: dict = field(default_factory=dict)

    @property
    def ok(self) -> np.ndarray:
        return self.status == STATUS_OK

    def status_counts(self) -> dict[str, int]:
        vals, counts = np.unique(self.status, return_counts=True)
        return {str(v): int(c) for v, c in zip(vals, counts)}


def _record(out: "SppTrack", j: int, sol, options: SppOptions) -> bool:
    """Book epoch ``j``'s solution into ``out`` (single- or multi-system alike): the robust
    counts, then, when it converged, position, clock, the position + clock covariance (4, 4;
    the inter-system offsets' rows are not kept), satellites, DOPs and residual RMS. False
    (status ``not converged``) when it did not converge."""
    if options.robust is not None:
        rb = out.robust
        rb["rows_downweighted"] = rb.get("rows_downweighted", 0) + sol.n_downweighted
        rb["rows_excluded"] = rb.get("rows_excluded", 0) + sol.n_excluded
        rb[f"epochs_{sol.robust_status}"] = rb.get(f"epochs_{sol.robust_status}", 0) + 1
    if not sol.converged:
        out.status[j] = STATUS_NOT_CONVERGED
        return False
    if options.validate:
        key = {"passed": "epochs_passed", "fde": "epochs_passed_after_exclusion"}.get(
            sol.validation, f"epochs_rejected_{sol.validation}")
        out.validation[key] = out.validation.get(key, 0) + 1
        if not sol.valid:
            out.status[j] = STATUS_REJECTED
            return False
    out.pos_ecef[j] = sol.pos_ecef
    out.clock_bias[j] = sol.clock_bias
    out.cov[j] = sol.cov[:4, :4]
    out.n_sat[j] = sol.n_sat
    out.pdop[j], out.hdop[j], out.vdop[j] = sol.dop["pdop"], sol.dop["hdop"], sol.dop["vdop"]
    out.rms_residual[j] = float(np.sqrt(np.mean(sol.residuals**2)))
    return True


def _record_systems(out: "SppTrack", j: int, sol, letters, present) -> None:
    """Book a recorded multi-system epoch ``j``: satellites used per system of ``present``,
    each system's offset to the receiver clock and the system whose time the clock is.
    ``letters``: the system letter of each satellite given to the solver."""
    # one system in the epoch: the solution names no systems; its used satellites are all of it
    sys_used = np.full(sol.n_sat, letters[0]) if sol.system is None else sol.system
    for s in present:
        out.n_sat_system[s][j] = int(np.sum(sys_used == s))
    if sol.offsets:
        for s, v in sol.offsets.items():
            out.offsets[s][j] = v
        out.clock_system[j] = next(iter(sol.offsets))
    else:
        out.clock_system[j] = str(sys_used[0]) if len(sys_used) else ""
        out.offsets[out.clock_system[j]][j] = 0.0


def solve_epochs(ephemeris, week, tow_rx, epoch, prn, pseudorange, options: SppOptions = SppOptions(),
                 sigma_scale=None, system=None, glonass_channel=None) -> SppTrack:
    """SPP at every epoch; epochs without a solution are counted, not raised.

    Several systems (``system`` given with a
    :class:`~mixnav.gnss.multi_ephemeris.MultiEphemeris`): each satellite at its transmit
    time from its own system's broadcast records (:func:`satellites_at_transmit_multi`),
    one receiver clock (the first of ``G R E C J`` present in the epoch) plus one offset
    per other system with a satellite in the epoch (an epoch needs 4 + that many
    satellites above the mask, else status ``too few satellites``), the Klobuchar delay
    (GPS coefficients, as RTKLIB) scaled per satellite by ``(f_L1 / f)^2``
    (:func:`first_frequency`: GLONASS by its channel ``k``, BeiDou B1I), Saastamoinen,
    Sagnac and the elevation mask as for GPS. A satellite whose system has no navigation
    data is left out and counted (reason ``no navigation data for the system``, per
    system in ``skipped_by_system``); so is a GLONASS satellite without a frequency
    number when the ionosphere is applied (:data:`NO_GLONASS_CHANNEL`). GPS alone (no
    ``system``, or every letter ``G``) is the single-system solution, bit for bit.

    Parameters
    ----------
    ephemeris : BroadcastEphemeris or MultiEphemeris
    week, tow_rx : ndarray (k,)
        Reception time of each epoch (GPS week, seconds of week [s]).
    epoch : ndarray of int (m,)
        Epoch index (0..k-1) of each observation.
    prn, pseudorange : ndarray (m,)
        Satellite and pseudorange [m] of each observation.
    options : SppOptions
    sigma_scale : ndarray (m,) or None
        Per-observation factor on the sigma model.
    system : array_like of str (m,) or None
        RINEX system letter of each observation (``prn`` then numbers satellites within
        their system); None: GPS.
    glonass_channel : array_like of int (m,) or None
        GLONASS frequency channel number of each observation (others: any value, out of
        -7..13 for none); None: from the navigation records (``ephemeris["R"].channels()``).

    Returns
    -------
    SppTrack
        Each epoch starts from the previous solution (the Earth's centre for
        the first and after a failed one).
    """
    if options.weights != "elevation" and not hasattr(ephemeris, "ephemeris_variances"):
        raise ValueError("weights = 'rtklib' needs each satellite's broadcast accuracy: a MultiEphemeris "
                         "(mixnav.gnss.multi_ephemeris), not GPS records read by georinex")
    compiled = options.engine == "compiled"
    week = np.asarray(week)
    tow_rx = np.asarray(tow_rx, float)
    epoch = np.asarray(epoch, int)
    prn = np.asarray(prn, int)
    rho = np.asarray(pseudorange, float)
    m = len(rho)
    scale = np.ones(m) if sigma_scale is None else np.asarray(sigma_scale, float)
    if system is not None or hasattr(ephemeris, "states_of"):
        sysarr = np.full(m, "G") if system is None else np.asarray(system).astype(str)
        if hasattr(ephemeris, "states_of") or (sysarr != "G").any():
            if not hasattr(ephemeris, "states_of"):
                others = sorted(set(sysarr.tolist()) - {"G"})
                raise ValueError(f"observations of systems {', '.join(others)} need a MultiEphemeris "
                                 "(mixnav.gnss.multi_ephemeris), not GPS records alone")
            if sysarr.shape != (m,):
                raise ValueError(f"system has shape {sysarr.shape}, expected ({m},) (one per observation)")
            solve = _solve_compiled if compiled else _solve_epochs_multi
            return solve(ephemeris, week, tow_rx, epoch, prn, rho, options, scale, sysarr, glonass_channel)
    if compiled:
        return _solve_compiled(ephemeris, week, tow_rx, epoch, prn, rho, options, scale, None, None)
    k = len(tow_rx)
    nan3 = np.full((k, 3), np.nan)
    out = SppTrack(week=week.copy(), tow=tow_rx.copy(), pos_ecef=nan3, clock_bias=np.full(k, np.nan),
                   cov=np.full((k, 4, 4), np.nan), n_sat=np.zeros(k, int), pdop=np.full(k, np.nan),
                   hdop=np.full(k, np.nan), vdop=np.full(k, np.nan), rms_residual=np.full(k, np.nan),
                   status=np.full(k, STATUS_OK, dtype=object))
    skipped: dict[str, int] = {}
    order = np.argsort(epoch, kind="stable")
    bounds = np.searchsorted(epoch[order], np.arange(k + 1))
    x0 = None
    for j in range(k):
        rows = order[bounds[j]:bounds[j + 1]]
        sats, keep, skips = satellites_at_transmit(ephemeris, prn[rows], rho[rows], week[j], tow_rx[j])
        for r, c in skips.counts().items():
            skipped[r] = skipped.get(r, 0) + c
        if len(sats) < 4:
            out.status[j] = STATUS_FEW
            continue
        try:
            sol = wls_position(rho[rows][keep], sats, options, x0=x0, sigma_scale=scale[rows][keep],
                               iono_alpha=ephemeris.iono_alpha, iono_beta=ephemeris.iono_beta, tow=tow_rx[j])
        except ValueError:
            out.status[j] = STATUS_FEW
            x0 = None
            continue
        skipped["below elevation mask"] = skipped.get("below elevation mask", 0) + sol.n_rejected_mask
        if not _record(out, j, sol, options):
            x0 = None
            continue
        x0 = np.append(sol.pos_ecef, sol.clock_bias)
    out.status = out.status.astype(str)
    out.skipped_satellites = skipped
    return out


def _multi_ionosphere(ephemeris, options, system, prn, glonass_channel):
    """Several systems' ionosphere settings: ``(iono_on, alpha, beta, no_freq, iono_scale)``:
    the GPS Klobuchar coefficients (None when not applied), which observations have no
    first frequency (a GLONASS satellite without a channel: left out when the ionosphere is
    applied) and each observation's factor ``(f_L1 / f)^2`` (:func:`first_frequency`; the
    channels from the GLONASS records when ``glonass_channel`` is None)."""
    if glonass_channel is None:
        table = ephemeris["R"].channels() if "R" in ephemeris else {}
        glonass_channel = np.array([table.get(int(p), 99) if s == "R" else 99 for s, p in zip(system, prn)])
    freq = first_frequency(system, glonass_channel)
    iono_on = bool(options.ionosphere and "G" in ephemeris and ephemeris["G"].iono_alpha is not None)
    alpha = ephemeris["G"].iono_alpha if iono_on else None
    beta = ephemeris["G"].iono_beta if iono_on else None
    no_freq = ~np.isfinite(freq) if iono_on else np.zeros(len(prn), bool)
    return iono_on, alpha, beta, no_freq, iono_scale_factors(np.where(np.isfinite(freq), freq, F_L1))


def _solve_epochs_multi(ephemeris, week, tow_rx, epoch, prn, rho, options, scale, system,
                        glonass_channel) -> SppTrack:
    """:func:`solve_epochs` over several systems (its docstring; the arrays as it checked them)."""
    from .multi_ephemeris import SYSTEM_NAMES
    ids = np.char.add(system, np.char.zfill(prn.astype(str), 2))
    _, alpha, beta, no_freq, iono_scale = _multi_ionosphere(ephemeris, options, system, prn, glonass_channel)
    k = len(tow_rx)
    present = [s for s in SYSTEM_ORDER if s in set(system.tolist())]
    out = SppTrack(week=week.copy(), tow=tow_rx.copy(), pos_ecef=np.full((k, 3), np.nan),
                   clock_bias=np.full(k, np.nan), cov=np.full((k, 4, 4), np.nan), n_sat=np.zeros(k, int),
                   pdop=np.full(k, np.nan), hdop=np.full(k, np.nan), vdop=np.full(k, np.nan),
                   rms_residual=np.full(k, np.nan), status=np.full(k, STATUS_OK, dtype=object),
                   offsets={s: np.full(k, np.nan) for s in present}, clock_system=np.full(k, "", dtype=object),
                   n_sat_system={s: np.zeros(k, int) for s in present})
    skipped: dict[str, int] = {}
    by_system: dict[str, dict[str, int]] = {}

    def count(letter, reason, c=1):
        skipped[reason] = skipped.get(reason, 0) + c
        d = by_system.setdefault(SYSTEM_NAMES.get(letter, letter), {})
        d[reason] = d.get(reason, 0) + c

    order = np.argsort(epoch, kind="stable")
    bounds = np.searchsorted(epoch[order], np.arange(k + 1))
    x0 = None
    for j in range(k):
        rows = order[bounds[j]:bounds[j + 1]]
        for r in rows[no_freq[rows]]:
            count(system[r], NO_GLONASS_CHANNEL)
        rows = rows[~no_freq[rows]]
        sats, letters, keep, skips = satellites_at_transmit_multi(ephemeris, ids[rows], rho[rows], week[j], tow_rx[j])
        for letter, sk in skips.items():
            for reason, c in sk.counts().items():
                count(letter, reason, c)
        if len(sats) < 4:
            out.status[j] = STATUS_FEW
            continue
        used_rows = rows[keep]
        var_eph = None
        if options.weights != "elevation":
            var_eph = ephemeris.ephemeris_variances(letters, sats.prn, week[j], tow_rx[j] - rho[used_rows] / C_LIGHT)
        try:
            sol = wls_position(rho[used_rows], sats, options, x0=x0, sigma_scale=scale[used_rows],
                               iono_alpha=alpha, iono_beta=beta, tow=tow_rx[j], system=letters,
                               iono_scale=iono_scale[used_rows], ephemeris_var=var_eph)
        except ValueError:
            out.status[j] = STATUS_FEW
            x0 = None
            continue
        if sol.n_rejected_mask:
            for letter in letters[_below_mask(sol, sats, options)]:
                count(letter, "below elevation mask")
        if not _record(out, j, sol, options):
            x0 = None
            continue
        _record_systems(out, j, sol, letters, present)
        x0 = np.append(sol.pos_ecef, sol.clock_bias)     # the offsets start from 0 (linear: one step)
    out.status = out.status.astype(str)
    out.clock_system = out.clock_system.astype(str)
    out.skipped_satellites = skipped
    out.skipped_by_system = by_system
    return out


def _solve_compiled(ephemeris, week, tow_rx, epoch, prn, rho, options, scale, system,
                    glonass_channel) -> SppTrack:
    """:func:`solve_epochs` (plain or robust WLS) through the compiled loop (``options.engine``):
    the satellites of all observations at their transmit times in one batched call, then
    :func:`mixnav.gnss._spp_kernel.spp_epochs`, then the same bookkeeping as the numpy
    paths (:func:`_solve_epochs_multi` with ``system``, one system without)."""
    from .multi_ephemeris import SYSTEM_NAMES
    multi = system is not None
    m, k = len(rho), len(tow_rx)
    skipped: dict[str, int] = {}
    by_system: dict[str, dict[str, int]] = {}

    def count(letters, reasons):
        """Add the (letter, reason) pairs to both tallies, in first-seen order."""
        if len(reasons) == 0:
            return
        pairs, counts = np.unique(np.char.add(np.char.add(letters.astype(str), "|"), reasons.astype(str)),
                                  return_counts=True)
        for pair, c in zip(pairs.tolist(), counts.tolist()):
            letter, reason = pair.split("|", 1)
            skipped[reason] = skipped.get(reason, 0) + int(c)
            if multi:
                d = by_system.setdefault(SYSTEM_NAMES.get(letter, letter), {})
                d[reason] = d.get(reason, 0) + int(c)

    order = np.argsort(epoch, kind="stable")
    sysarr = system if multi else np.full(m, "G")
    if multi:
        iono_on, alpha, beta, no_freq, iono_scale = _multi_ionosphere(ephemeris, options, system, prn,
                                                                      glonass_channel)
        count(system[order][no_freq[order]], np.full(int(no_freq.sum()), NO_GLONASS_CHANNEL))
        order = order[~no_freq[order]]
    else:
        iono_on = options.ionosphere and ephemeris.iono_alpha is not None and ephemeris.iono_beta is not None
        alpha, beta = ephemeris.iono_alpha, ephemeris.iono_beta
        iono_scale = np.ones(m)
    # every observation's satellite at its transmit time: one batched call, then one more
    # with the satellite clock taken off (as satellites_at_transmit, epoch by epoch)
    ep = epoch[order]
    wk = week[ep]
    t_tx = tow_rx[ep] - rho[order] / C_LIGHT
    _, _, clk, _, reason = _states_batched(ephemeris, sysarr[order], prn[order], wk, t_tx, multi)
    keep = reason == ""
    count(sysarr[order][~keep], reason[~keep])
    sat, _, clk2, _, again = _states_batched(ephemeris, sysarr[order][keep], prn[order][keep], wk[keep],
                                             t_tx[keep] - clk[keep], multi)
    flipped = again != ""          # a record choice flipped within the travel time: left out with it
    rows = order[keep][~flipped]
    sat, clk2 = sat[~flipped], clk2[~flipped]
    bounds = np.searchsorted(epoch[rows], np.arange(k + 1))
    letters_used, inverse = np.unique(sysarr[rows], return_inverse=True)
    sys_idx = np.array([SYSTEM_ORDER.index(s) for s in letters_used.tolist()], np.int64)[inverse.ravel()]
    params = np.array([options.elevation_mask, options.sigma_a, options.sigma_b, float(options.troposphere),
                       float(iono_on), float(options.max_iter), options.tol,
                       RTKLIB_CODE_SIGMAS.get(options.weights, 0.0),
                       float(options.robust is not None), *(options.robust or (0.0, 0.0)), float(options.validate),
                       float(options.fde), options.max_gdop])
    if options.weights != "elevation":
        fact = np.array([RTKLIB_SYSTEM_FACTOR.get(c, 1.0) for c in SYSTEM_ORDER])[sys_idx]
        var_eph = ephemeris.ephemeris_variances(sysarr[rows], prn[rows], week[epoch[rows]],
                                                tow_rx[epoch[rows]] - rho[rows] / C_LIGHT)
    else:
        fact, var_eph = np.ones(len(rows)), np.zeros(len(rows))
    pos, clock = np.full((k, 3), np.nan), np.full(k, np.nan)
    cov, offsets = np.full((k, 4, 4), np.nan), np.full((k, len(SYSTEM_ORDER)), np.nan)
    clock_sys, status = np.full(k, -1, np.int64), np.zeros(k, np.int64)
    n_used, dops, rms = np.zeros(k, np.int64), np.full((k, 3), np.nan), np.full(k, np.nan)
    n_rejected = np.full(k, -1, np.int64)
    used, below = np.zeros(len(rows), bool), np.zeros(len(rows), bool)
    robust_code, n_down, n_excl = np.zeros(k, np.int64), np.zeros(k, np.int64), np.zeros(k, np.int64)
    valid_code, excluded = np.zeros(k, np.int64), np.full(k, -1, np.int64)
    table = _chi2_table() if options.validate else np.ones(1)
    spp_epochs(np.ascontiguousarray(sat), rho[rows] + C_LIGHT * clk2, scale[rows], fact, var_eph, iono_scale[rows],
               sys_idx, bounds,
               tow_rx, params, np.zeros(4) if alpha is None else np.asarray(alpha, float),
               np.zeros(4) if beta is None else np.asarray(beta, float), pos, clock, cov, offsets, clock_sys, status,
               n_used, dops, rms, n_rejected, used, below, robust_code, n_down, n_excl, table, valid_code, excluded)
    names = np.empty(4, dtype=object)
    names[CODE_OK], names[CODE_FEW], names[CODE_NOT_CONVERGED] = STATUS_OK, STATUS_FEW, STATUS_NOT_CONVERGED
    names[CODE_REJECTED] = STATUS_REJECTED
    out = SppTrack(week=week.copy(), tow=tow_rx.copy(), pos_ecef=pos, clock_bias=clock, cov=cov, n_sat=n_used.astype(int),
                   pdop=dops[:, 0].copy(), hdop=dops[:, 1].copy(), vdop=dops[:, 2].copy(), rms_residual=rms,
                   status=names[status].astype(str))
    # the mask's count: per satellite seen from the final position where the mask left a row
    # out (several systems), the rows left out (one system; every solved epoch adds its count)
    solved = n_rejected >= 0
    if options.robust is not None:      # over the epochs with a solution, converged or not (as _record)
        names_r = ("off", "ok", "untestable", "not_separable")
        out.robust = {"rows_downweighted": int(n_down[solved].sum()), "rows_excluded": int(n_excl[solved].sum())}
        codes = robust_code[solved]
        for c in dict.fromkeys(codes.tolist()):
            out.robust[f"epochs_{names_r[c]}"] = int(np.sum(codes == c))
    if multi:
        row_epoch = epoch[rows]
        flag = below & (n_rejected[row_epoch] > 0)
        count(sysarr[rows][flag], np.full(int(flag.sum()), "below elevation mask"))
    elif solved.any():
        skipped["below elevation mask"] = skipped.get("below elevation mask", 0) + int(n_rejected[solved].sum())
    out.skipped_satellites = skipped
    if options.validate:       # over the converged epochs (as _record)
        keys = {VALID_PASSED: "epochs_passed", VALID_FDE: "epochs_passed_after_exclusion",
                VALID_CHI2: "epochs_rejected_chi-square", VALID_GDOP: "epochs_rejected_gdop"}
        for c, key in keys.items():
            if np.any(valid_code == c):
                out.validation[key] = int(np.sum(valid_code == c))
    if not multi:
        return out
    present = [s for s in SYSTEM_ORDER if s in set(system.tolist())]
    ok = status == CODE_OK
    out.offsets = {s: np.where(ok, offsets[:, SYSTEM_ORDER.index(s)], np.nan) for s in present}
    letters = np.array(SYSTEM_ORDER + ("",))
    out.clock_system = np.where(ok, letters[clock_sys], "").astype(str)
    out.n_sat_system = {}
    for s in present:
        c = np.bincount(epoch[rows][used & (sysarr[rows] == s)], minlength=k)
        out.n_sat_system[s] = np.where(ok, c, 0).astype(int)
    out.skipped_by_system = by_system
    return out


def _states_batched(ephemeris, letters, prn, week, tow, multi: bool):
    """Satellite states of many observations at their own times: ``(pos, vel, clk, drift,
    reason)`` (n,) as :meth:`MultiEphemeris.states_by_system` (one system: the GPS
    records' selection and orbits, the same functions their ``states`` call)."""
    if multi and hasattr(ephemeris, "states_by_system"):
        return ephemeris.states_by_system(letters, prn, week, tow)
    n = len(prn)
    if multi:
        # any object with MultiEphemeris's states_of (a test's stand-in): one row at a time
        ids = np.char.add(letters.astype(str), np.char.zfill(prn.astype(str), 2))
        pos, vel = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
        clk, drift = np.full(n, np.nan), np.full(n, np.nan)
        reason = np.full(n, "", dtype=object)
        for i in range(n):
            st, _, keep, skips = ephemeris.states_of(ids[i:i + 1], week[i], tow[i:i + 1])
            if keep[0]:
                pos[i], vel[i], clk[i], drift[i] = st.pos_ecef[0], st.vel_ecef[0], st.clock_bias[0], st.clock_drift[0]
            else:
                reason[i] = next(sk.reason[0] for sk in skips.values() if len(sk))
        return pos, vel, clk, drift, reason.astype(str)
    pos, vel = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    clk, drift = np.full(n, np.nan), np.full(n, np.nan)
    reason = np.full(n, "", dtype=object)
    if not hasattr(ephemeris, "_select"):
        # any object with BroadcastEphemeris's public interface: one row at a time
        for i in range(n):
            st, sk = ephemeris.states_and_skips(week[i], tow[i:i + 1], prn[i:i + 1])
            if len(sk):
                reason[i] = sk.reason[0]
            else:
                pos[i], vel[i], clk[i], drift[i] = st.pos_ecef[0], st.vel_ecef[0], st.clock_bias[0], st.clock_drift[0]
        return pos, vel, clk, drift, reason.astype(str)
    idx = np.empty(n, int)
    t = np.empty(n)
    for c0 in range(0, n, 8192):       # the record choice's table is rows x records
        part = slice(c0, c0 + 8192)
        i, tt, sk = ephemeris._select(week[part], tow[part], prn[part])
        idx[part], t[part] = i, tt
        reason[c0 + np.flatnonzero(i < 0)] = sk.reason
    ok = idx >= 0
    p, v, c, d = ephemeris._compute(idx[ok], t[ok], True)
    pos[ok], vel[ok], clk[ok], drift[ok] = p, v, c, d
    return pos, vel, clk, drift, reason.astype(str)


def _below_mask(sol: SppSolution, sats, options: SppOptions) -> np.ndarray:
    """Which of ``sats`` are below the elevation mask seen from ``sol`` (bool (n,))."""
    r_geo = np.linalg.norm(sats.pos_ecef - sol.pos_ecef, axis=1)
    el, _ = elevation_azimuth(sol.pos_ecef, earth_rotation_correction(sats.pos_ecef, r_geo / C_LIGHT))
    return el < options.elevation_mask


def atmosphere_delay(lla, elevation, azimuth, tow: float, options: SppOptions = SppOptions(), iono_alpha=None,
                     iono_beta=None, iono_scale=None) -> np.ndarray:
    """Troposphere plus ionosphere delay [m] (n,) that SPP adds to its model, at the receiver
    ``lla`` (rad, rad, m) for satellites at ``elevation``, ``azimuth`` (n,) [rad]: Saastamoinen
    when ``options.troposphere``, Klobuchar when ``options.ionosphere`` and both coefficient
    sets are given (as :func:`wls_position`), times ``iono_scale`` (n,) when given (the
    ``(f_L1 / f)^2`` of each signal's frequency, :func:`iono_scale_factors`)."""
    el = np.asarray(elevation, float)
    d = np.zeros(len(el))
    if options.troposphere:
        d = d + saastamoinen(lla[0], lla[2], np.maximum(el, 1e-3))
    if options.ionosphere and iono_alpha is not None and iono_beta is not None:
        iono = klobuchar(lla[0], lla[1], el, azimuth, tow, iono_alpha, iono_beta)
        d = d + (iono if iono_scale is None else iono * iono_scale)
    return d


def corrected_pseudoranges(ephemeris, week, tow_rx, epoch, prn, pseudorange, receiver_ecef,
                           options: SppOptions = SppOptions(), cn0=None, source=None, doppler=None,
                           system=None, glonass_channel=None):
    """The raw pseudoranges as a :class:`~mixnav.gnss.pseudoranges.PseudorangeEpochs` with the
    broadcast corrections applied the way SPP applies them, for a filter that estimates
    position and clock itself (:class:`mixnav.measurements.pseudorange.PseudorangeGnss`).

    Per observation: the satellite at its transmit time (:func:`satellites_at_transmit`:
    ECEF of that time, the model turns it), the satellite clock (relativistic term, T_GD)
    added, and the troposphere and ionosphere (:func:`atmosphere_delay`) subtracted,
    evaluated at ``receiver_ecef[j]``, a position near the receiver at epoch ``j`` (a
    first fix: a 100 m error moves the delays by millimetres). Elevations are those
    seen from it; the variance is SPP's ``sigma_a^2 + sigma_b^2 / sin^2 el``.

    Parameters
    ----------
    ephemeris : BroadcastEphemeris
    week, tow_rx : ndarray (k,)
        Epoch reception times (GPS week, seconds of week [s]).
    epoch, prn, pseudorange : ndarray (m,)
        Epoch index, satellite and pseudorange [m] of each observation.
    receiver_ecef : ndarray (k, 3)
        [m]; epochs with a non-finite row are left out (counted: ``no position``).
    options : SppOptions
    cn0 : ndarray (m,) or None
        [dB-Hz].
    doppler : ndarray (m,) or None
        L1 Doppler [Hz] (NaN where absent): the epochs then also carry the range rate
        ``-lambda_L1 D + c ddt_sv`` (the satellite clock drift, relativistic part included,
        removed) and the satellite velocity at the transmit time (ECEF of that time).

    Returns
    -------
    epochs : PseudorangeEpochs
        Times in seconds since the first epoch of ``week, tow_rx`` (as the SPP table's
        ``time_s``), GPS (system code 1); an epoch without a usable satellite is absent.
        Several systems (``system`` (m,) letters with a MultiEphemeris, as
        :func:`solve_epochs`): each row's system code
        (:data:`mixnav.gnss.pseudoranges.SYSTEM_LETTERS`), the ionosphere scaled to its
        frequency, its Doppler by its own wavelength.
    skipped : dict
        Observations left out per reason (ephemeris reasons, ``no position``).
    """
    from .pseudoranges import PseudorangeEpochs
    if system is not None and (hasattr(ephemeris, "states_of") or (np.asarray(system) != "G").any()):
        return _corrected_multi(ephemeris, week, tow_rx, epoch, prn, pseudorange, receiver_ecef, options, cn0,
                                source, doppler, np.asarray(system).astype(str), glonass_channel)
    week = np.asarray(week)
    tow_rx = np.asarray(tow_rx, float)
    epoch = np.asarray(epoch, int)
    prn = np.asarray(prn, int)
    rho = np.asarray(pseudorange, float)
    cn = np.full(len(rho), np.nan) if cn0 is None else np.asarray(cn0, float)
    dop = None if doppler is None else np.asarray(doppler, float)
    t_abs = week * 604800.0 + tow_rx
    t_rel = t_abs - t_abs[0]
    order = np.argsort(epoch, kind="stable")
    bounds = np.searchsorted(epoch[order], np.arange(len(tow_rx) + 1))
    skipped: dict[str, int] = {}
    out = {k: [] for k in ("t", "pr", "var", "sat", "id", "el", "cn0", "vel", "rr")}
    for j in range(len(tow_rx)):
        rows = order[bounds[j]:bounds[j + 1]]
        if len(rows) == 0:
            continue
        x = np.asarray(receiver_ecef[j], float)
        if not np.isfinite(x).all():
            skipped["no position"] = skipped.get("no position", 0) + len(rows)
            continue
        sats, keep, skips = satellites_at_transmit(ephemeris, prn[rows], rho[rows], week[j], tow_rx[j])
        for r, c in skips.counts().items():
            skipped[r] = skipped.get(r, 0) + c
        if len(sats) == 0:
            continue
        r_geo = np.linalg.norm(sats.pos_ecef - x, axis=1)
        el, az = elevation_azimuth(x, earth_rotation_correction(sats.pos_ecef, r_geo / C_LIGHT))
        lla = ecef_to_lla(x)
        delay = atmosphere_delay(lla, el, az, tow_rx[j], options, ephemeris.iono_alpha, ephemeris.iono_beta)
        s_el = np.sin(np.maximum(el, 1e-3))
        n = len(sats)
        out["t"].append(np.full(n, t_rel[j]))
        out["pr"].append(rho[rows][keep] + C_LIGHT * sats.clock_bias - delay)
        out["var"].append(options.sigma_a ** 2 + options.sigma_b ** 2 / s_el ** 2)
        out["sat"].append(sats.pos_ecef)
        out["id"].append(prn[rows][keep])
        out["el"].append(el)
        out["cn0"].append(cn[rows][keep])
        if dop is not None:
            out["vel"].append(sats.vel_ecef)
            out["rr"].append(-LAMBDA_L1 * dop[rows][keep] + C_LIGHT * sats.clock_drift)
    vec = ("sat", "vel")
    if not out["t"]:
        cat = {k: np.zeros((0, 3)) if k in vec else np.zeros(0) for k in out}
    else:
        cat = {k: (np.vstack(v) if k in vec else np.concatenate(v)) if v else None for k, v in out.items()}
    ep = PseudorangeEpochs.from_rows(cat["t"], cat["pr"], cat["var"], cat["sat"], cat["id"],
                                     np.ones(len(cat["pr"]), int), elevation=cat["el"], cn0=cat["cn0"],
                                     source=source, sat_vel=cat["vel"] if dop is not None else None,
                                     range_rate=cat["rr"] if dop is not None else None)
    return ep, skipped


def _corrected_multi(ephemeris, week, tow_rx, epoch, prn, pseudorange, receiver_ecef, options, cn0, source,
                     doppler, system, glonass_channel):
    """:func:`corrected_pseudoranges` over several systems (its docstring)."""
    from .pseudoranges import SYSTEM_LETTERS, PseudorangeEpochs
    codes = {v: k for k, v in SYSTEM_LETTERS.items()}
    week = np.asarray(week)
    tow_rx = np.asarray(tow_rx, float)
    epoch = np.asarray(epoch, int)
    prn = np.asarray(prn, int)
    rho = np.asarray(pseudorange, float)
    m = len(rho)
    cn = np.full(m, np.nan) if cn0 is None else np.asarray(cn0, float)
    dop = None if doppler is None else np.asarray(doppler, float)
    ids = np.char.add(system, np.char.zfill(prn.astype(str), 2))
    if glonass_channel is None:
        table = ephemeris["R"].channels() if "R" in ephemeris else {}
        glonass_channel = np.array([table.get(int(p), 99) if s == "R" else 99 for s, p in zip(system, prn)])
    freq = first_frequency(system, glonass_channel)
    iono_on = options.ionosphere and "G" in ephemeris and ephemeris["G"].iono_alpha is not None
    alpha = ephemeris["G"].iono_alpha if iono_on else None
    beta = ephemeris["G"].iono_beta if iono_on else None
    no_freq = ~np.isfinite(freq) if (iono_on or dop is not None) else np.zeros(m, bool)
    iono_scale = iono_scale_factors(np.where(np.isfinite(freq), freq, F_L1))
    t_abs = week * 604800.0 + tow_rx
    t_rel = t_abs - t_abs[0]
    order = np.argsort(epoch, kind="stable")
    bounds = np.searchsorted(epoch[order], np.arange(len(tow_rx) + 1))
    skipped: dict[str, int] = {}
    out = {k: [] for k in ("t", "pr", "var", "sat", "id", "sys", "el", "cn0", "vel", "rr")}
    for j in range(len(tow_rx)):
        rows = order[bounds[j]:bounds[j + 1]]
        if len(rows) == 0:
            continue
        x = np.asarray(receiver_ecef[j], float)
        if not np.isfinite(x).all():
            skipped["no position"] = skipped.get("no position", 0) + len(rows)
            continue
        if no_freq[rows].any():
            skipped[NO_GLONASS_CHANNEL] = skipped.get(NO_GLONASS_CHANNEL, 0) + int(no_freq[rows].sum())
            rows = rows[~no_freq[rows]]
        sats, letters, keep, skips = satellites_at_transmit_multi(ephemeris, ids[rows], rho[rows], week[j], tow_rx[j])
        for sk in skips.values():
            for r, c in sk.counts().items():
                skipped[r] = skipped.get(r, 0) + c
        if len(sats) == 0:
            continue
        used = rows[keep]
        r_geo = np.linalg.norm(sats.pos_ecef - x, axis=1)
        el, az = elevation_azimuth(x, earth_rotation_correction(sats.pos_ecef, r_geo / C_LIGHT))
        delay = atmosphere_delay(ecef_to_lla(x), el, az, tow_rx[j], options, alpha, beta, iono_scale=iono_scale[used])
        s_el = np.sin(np.maximum(el, 1e-3))
        n = len(sats)
        out["t"].append(np.full(n, t_rel[j]))
        out["pr"].append(rho[used] + C_LIGHT * sats.clock_bias - delay)
        out["var"].append(options.sigma_a ** 2 + options.sigma_b ** 2 / s_el ** 2)
        out["sat"].append(sats.pos_ecef)
        out["id"].append(prn[used])
        out["sys"].append(np.array([codes[s] for s in letters], int))
        out["el"].append(el)
        out["cn0"].append(cn[used])
        if dop is not None:
            out["vel"].append(sats.vel_ecef)
            out["rr"].append(-(C_LIGHT / freq[used]) * dop[used] + C_LIGHT * sats.clock_drift)
    vec = ("sat", "vel")
    if not out["t"]:
        cat = {k: np.zeros((0, 3)) if k in vec else np.zeros(0) for k in out}
        cat["sys"] = np.zeros(0, int)
    else:
        cat = {k: (np.vstack(v) if k in vec else np.concatenate(v)) if v else None for k, v in out.items()}
    ep = PseudorangeEpochs.from_rows(cat["t"], cat["pr"], cat["var"], cat["sat"], cat["id"], cat["sys"],
                                     elevation=cat["el"], cn0=cat["cn0"], source=source,
                                     sat_vel=cat["vel"] if dop is not None else None,
                                     range_rate=cat["rr"] if dop is not None else None)
    return ep, skipped


#: a millisecond of light travel [m]: the size of the clock jumps of receivers that steer
#: their clock within +-0.5 ms (RINEX observation files of many receivers)
MS_JUMP = C_LIGHT * 1e-3


def clock_jumps(time, clock_bias, ok, threshold: float = 1000.0):
    """Receiver clock jumps in an SPP track, as offsets to take off the pseudoranges.

    Each solved epoch's clock bias is predicted from the last accepted one and the rate
    between the last two (a drifting clock is no jump); a departure above ``threshold``
    [m] is a jump when it is within ``threshold / 2`` of a whole number of milliseconds of
    light travel (receivers that steer their clock by millisecond steps: taken as exactly
    that), or when the next solved epoch stays at the new level (a phone re-acquiring its
    clock: taken as the departure, within the SPP's clock noise, which the filter's clock
    noise absorbs; this looks one solved epoch ahead). A departure that does not persist
    is a spike of the SPP (an outlier pulled its clock): ignored and counted.

    Parameters
    ----------
    time : ndarray (k,)
        Epoch times [s].
    clock_bias : ndarray (k,)
        SPP clock bias [m] (any value where not ``ok``).
    ok : ndarray of bool (k,)
        Solved epochs.
    threshold : float
        [m], > 0.

    Returns
    -------
    offset : ndarray (k,)
        Sum of the jumps up to each epoch [m] (a jump between solved epochs ``i`` and ``j``
        counts from ``j`` on): subtracting it from the pseudoranges of the epoch (and
        from the SPP clock) leaves a continuous clock.
    jumps : list of (float, float)
        ``(time [s], size [m])`` of each jump.
    spikes : int
        Departures ignored.
    """
    t = np.asarray(time, float)
    b = np.asarray(clock_bias, float)
    idx = np.nonzero(np.asarray(ok, bool))[0]
    offset = np.zeros(len(t))
    jumps = []
    spikes = 0
    rate, cum = 0.0, 0.0
    if len(idx) == 0:
        return offset, jumps, spikes
    ref = idx[0]                          # the last accepted epoch
    for pos in range(1, len(idx)):
        prev, j = idx[pos - 1], idx[pos]
        before = cum
        level = b[ref] - offset[ref]      # its clock without the jumps
        dev = (b[j] - cum) - (level + rate * (t[j] - t[ref]))
        if abs(dev) <= threshold:
            if t[j] > t[ref]:
                rate = ((b[j] - cum) - level) / (t[j] - t[ref])
            ref = j
        else:
            n_ms = round(dev / MS_JUMP)
            size = None
            if n_ms != 0 and abs(dev - n_ms * MS_JUMP) < threshold / 2:
                size = n_ms * MS_JUMP
            elif pos + 1 < len(idx):
                n = idx[pos + 1]
                if abs((b[n] - b[j]) - rate * (t[n] - t[j])) <= threshold:
                    size = dev
            if size is None:
                spikes += 1
            else:
                cum += size
                jumps.append((float(t[j]), float(size)))
                ref = j
        offset[prev + 1:j] = before
        offset[j] = cum
    offset[idx[-1] + 1:] = cum
    return offset, jumps, spikes
