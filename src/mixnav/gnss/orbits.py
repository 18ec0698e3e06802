"""Broadcast orbit and clock models of every GNSS, vectorised over records.

Two models cover the systems mixnav reads:

Keplerian (GPS, Galileo, QZSS, BeiDou): :func:`kepler_states`
    IS-GPS-200 20.3.3.4.3 (Table 20-IV), written once with the system's
    constants as arguments; Galileo OS SIS ICD 5.1.1 (Table 58), IS-QZSS-PNT
    4.1.2 and BDS-SIS-ICD-B1I 5.2.4.12 are the same algorithm with their own
    ``GM`` and ``Omega_e``. BeiDou GEO satellites (5.2.4.12, second table)
    take the node without the Earth-rotation term, then the rotation
    ``R_Z(Omega_e t_k) R_X(-5 deg)`` (:func:`beidou_geo_rotation`). Kepler's
    equation is solved by Newton iterations to machine precision; velocity and
    clock drift are the analytic time derivatives. The clock is ``af0 + af1 dt
    + af2 dt^2 + F e sqrt(A) sin E`` with ``F = -2 sqrt(GM) / c^2`` of the
    system, minus the record's single-frequency group delay when asked.

GLONASS (ICD 5.1, appendix A.3.1.2): :func:`glonass_states`
    The broadcast position, velocity and luni-solar acceleration at ``t_b``
    are integrated in the rotating PZ-90 frame with the central term, the
    second zonal harmonic ``J2``, the centrifugal and Coriolis terms and the
    broadcast (constant) luni-solar acceleration, by 4th-order Runge-Kutta
    with equal steps of at most ``step`` (60 s by default, as the ICD's
    example and RTKLIB use). PZ-90.11 coordinates are taken as WGS-84 ones
    (the frames agree within a few centimetres, below the broadcast orbit's
    metre-level error). The clock is ``-tau_n + gamma_n (t - t_b)``; the
    broadcast ``tau_n`` already holds the relativistic correction.

All times here are continuous seconds in the system's own time scale (the
caller converts: :mod:`mixnav.gnss.gnss_time`); records are dicts of arrays,
one entry per record evaluated (already gathered per query).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .geometry import C_LIGHT, GM_GPS, OMEGA_E_GPS, SECONDS_PER_WEEK


@dataclass(frozen=True)
class KeplerConstants:
    """The constants a Keplerian broadcast orbit depends on.

    Attributes
    ----------
    gm : float
        Earth's gravitational constant [m^3/s^2].
    omega_e : float
        Earth rotation rate [rad/s].
    f_rel : float
        Relativistic clock constant ``-2 sqrt(gm) / c^2`` [s/m^(1/2)].
    """

    gm: float
    omega_e: float
    f_rel: float

    @classmethod
    def of(cls, gm: float, omega_e: float) -> "KeplerConstants":
        return cls(gm, omega_e, -2.0 * np.sqrt(gm) / C_LIGHT**2)


#: IS-GPS-200 (F as printed there, 20.3.3.3.3.1).
GPS = KeplerConstants(GM_GPS, OMEGA_E_GPS, -4.442807633e-10)
#: IS-QZSS-PNT 4.1.2: the GPS values.
QZSS = KeplerConstants(3.986005e14, 7.2921151467e-5, -4.442807633e-10)
#: Galileo OS SIS ICD 5.1.1 / 5.1.4.
GALILEO = KeplerConstants(3.986004418e14, 7.2921151467e-5, -4.442807309e-10)
#: BDS-SIS-ICD-B1I 5.2.4.10 / 5.2.4.12 (CGCS2000).
BEIDOU = KeplerConstants.of(3.986004418e14, 7.2921150e-5)

#: BeiDou GEO inclination of the broadcast frame [rad] (BDS-SIS-ICD-B1I 5.2.4.12).
BEIDOU_GEO_TILT = np.deg2rad(-5.0)



@dataclass(frozen=True)
class GlonassConstants:
    """The PZ-90 constants of the GLONASS equations of motion.

    Attributes
    ----------
    gm : float
        [m^3/s^2].
    ae : float
        Equatorial radius [m].
    j2 : float
        Second zonal harmonic.
    omega_e : float
        Earth rotation rate [rad/s].
    """

    gm: float
    ae: float
    j2: float
    omega_e: float


#: GLONASS ICD 5.1 (2008), 3.1.3 / A.3.1.2.
GLONASS = GlonassConstants(3.986004418e14, 6378136.0, 1.08262575e-3, 7.2921151467e-5)
#: Default (largest) GLONASS integration step [s] (ICD: at most 60 s; see the module docstring).
GLONASS_STEP = 30.0


def beidou_geo_rotation(omega_e_tk) -> tuple[np.ndarray, np.ndarray]:
    """The BeiDou GEO rotation ``R_Z(Omega_e t_k) R_X(-5 deg)`` and its time derivative.

    Parameters
    ----------
    omega_e_tk : ndarray (n,)
        ``Omega_e * t_k`` [rad].

    Returns
    -------
    R : ndarray (n, 3, 3)
        Maps the GEO broadcast frame to ECEF (BDS-SIS-ICD-B1I 5.2.4.12, with
        ``R_X(p) = [[1, 0, 0], [0, cos p, sin p], [0, -sin p, cos p]]`` and
        ``R_Z(p) = [[cos p, sin p, 0], [-sin p, cos p, 0], [0, 0, 1]]``).
    dR : ndarray (n, 3, 3)
        ``d R / d(Omega_e t_k)`` (multiply by ``Omega_e`` for d/dt).
    """
    a = np.asarray(omega_e_tk, float)
    ca, sa = np.cos(a), np.sin(a)
    cp, sp = np.cos(BEIDOU_GEO_TILT), np.sin(BEIDOU_GEO_TILT)
    one, zero = np.ones_like(a), np.zeros_like(a)
    rz = np.stack([np.stack([ca, sa, zero], -1), np.stack([-sa, ca, zero], -1),
                   np.stack([zero, zero, one], -1)], -2)
    drz = np.stack([np.stack([-sa, ca, zero], -1), np.stack([-ca, -sa, zero], -1),
                    np.stack([zero, zero, zero], -1)], -2)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cp, sp], [0.0, -sp, cp]])
    return rz @ rx, drz @ rx


def kepler_states(r: dict, t, const: KeplerConstants, apply_group_delay: bool = True, geo=None):
    """Position, velocity and clock from Keplerian broadcast records.

    Parameters
    ----------
    r : dict of str -> ndarray (n,)
        One record per query: ``sqrt_a`` [m^(1/2)], ``e``, ``m0``, ``omega0``,
        ``omega``, ``i0`` [rad], ``delta_n``, ``omega_dot``, ``idot`` [rad/s],
        ``cuc``, ``cus``, ``cic``, ``cis`` [rad], ``crc``, ``crs`` [m], ``toe``
        [s of week], ``week`` (so that ``week * 604800 + toe`` is the
        reference time in the scale of ``t``), ``toc_week``, ``toc``, ``af0``
        [s], ``af1`` [s/s], ``af2`` [s/s^2], ``tgd`` [s] (the group delay the
        single-frequency user subtracts).
    t : ndarray (n,)
        Times, continuous seconds in the system's time scale [s].
    const : KeplerConstants
    apply_group_delay : bool
        Subtract ``tgd`` from the clock.
    geo : ndarray of bool (n,) or None
        BeiDou GEO records (node without Earth rotation, then
        :func:`beidou_geo_rotation`).

    Returns
    -------
    pos : ndarray (n, 3)
        ECEF [m] at ``t``.
    vel : ndarray (n, 3)
        [m/s] in the rotating frame.
    clk : ndarray (n,)
        Satellite clock offset [s], relativistic term included.
    drift : ndarray (n,)
        [s/s].
    """
    n = len(t)
    if n == 0:
        z = np.zeros(0)
        return np.zeros((0, 3)), np.zeros((0, 3)), z, z
    we = const.omega_e
    A = r["sqrt_a"] ** 2                                   # semi-major axis
    n0 = np.sqrt(const.gm / A**3)                          # computed mean motion
    tk = t - (r["week"] * SECONDS_PER_WEEK + r["toe"])     # time from ephemeris epoch
    nk = n0 + r["delta_n"]                                 # corrected mean motion
    M = r["m0"] + nk * tk                                  # mean anomaly
    e = r["e"]
    E = M.copy()
    for _ in range(8):                                     # Kepler M = E - e sin E, Newton
        E = E - (E - e * np.sin(E) - M) / (1.0 - e * np.cos(E))
    sinE, cosE = np.sin(E), np.cos(E)
    one_ecos = 1.0 - e * cosE
    nu = np.arctan2(np.sqrt(1.0 - e**2) * sinE, cosE - e)  # true anomaly
    phi = nu + r["omega"]                                  # argument of latitude
    s2, c2 = np.sin(2 * phi), np.cos(2 * phi)
    du = r["cus"] * s2 + r["cuc"] * c2                     # second-harmonic perturbations
    dr = r["crs"] * s2 + r["crc"] * c2
    di = r["cis"] * s2 + r["cic"] * c2
    u = phi + du                                           # corrected argument of latitude
    rad = A * one_ecos + dr                                # corrected radius
    inc = r["i0"] + di + r["idot"] * tk                    # corrected inclination
    x_p, y_p = rad * np.cos(u), rad * np.sin(u)            # position in the orbital plane
    # GEO: the node in the inertial-like broadcast frame (no Earth rotation over tk)
    we_node = we if geo is None else np.where(geo, 0.0, we)
    Om = r["omega0"] + (r["omega_dot"] - we_node) * tk - we * r["toe"]
    cO, sO, ci, si = np.cos(Om), np.sin(Om), np.cos(inc), np.sin(inc)
    x = x_p * cO - y_p * ci * sO
    y = x_p * sO + y_p * ci * cO
    z = y_p * si
    # time derivatives of the expressions above
    E_dot = nk / one_ecos
    phi_dot = np.sqrt(1.0 - e**2) * E_dot / one_ecos       # d(nu)/dt
    u_dot = phi_dot * (1.0 + 2.0 * (r["cus"] * c2 - r["cuc"] * s2))
    r_dot = A * e * sinE * E_dot + 2.0 * phi_dot * (r["crs"] * c2 - r["crc"] * s2)
    i_dot = r["idot"] + 2.0 * phi_dot * (r["cis"] * c2 - r["cic"] * s2)
    Om_dot = r["omega_dot"] - we_node
    xp_dot = r_dot * np.cos(u) - y_p * u_dot
    yp_dot = r_dot * np.sin(u) + x_p * u_dot
    vx = xp_dot * cO - yp_dot * ci * sO + y_p * si * sO * i_dot - y * Om_dot
    vy = xp_dot * sO + yp_dot * ci * cO - y_p * si * cO * i_dot + x * Om_dot
    vz = yp_dot * si + y_p * ci * i_dot
    pos = np.stack([x, y, z], axis=-1)
    vel = np.stack([vx, vy, vz], axis=-1)
    if geo is not None and np.any(geo):
        R, dR = beidou_geo_rotation(we * tk[geo])
        pg, vg = pos[geo], vel[geo]
        pos[geo] = np.einsum("nij,nj->ni", R, pg)
        vel[geo] = np.einsum("nij,nj->ni", R, vg) + we * np.einsum("nij,nj->ni", dR, pg)
    # clock, IS-GPS-200 20.3.3.3.3.1 (and its twins in the other ICDs)
    dtc = t - (r["toc_week"] * SECONDS_PER_WEEK + r["toc"])
    rel = const.f_rel * e * r["sqrt_a"] * sinE
    clk = r["af0"] + r["af1"] * dtc + r["af2"] * dtc**2 + rel
    if apply_group_delay:
        clk = clk - r["tgd"]
    drift = r["af1"] + 2.0 * r["af2"] * dtc + const.f_rel * e * r["sqrt_a"] * cosE * E_dot
    return pos, vel, clk, drift


@njit(cache=True)
def _glonass_rates(y, acc, gm, ae, j2c, we, out):
    """d/dt of one GLONASS state y (6,) = (x, y, z, vx, vy, vz) in the rotating PZ-90 frame, into out."""
    x, yy, z = y[0], y[1], y[2]
    r2 = x * x + yy * yy + z * z
    r = np.sqrt(r2)
    mu_r3 = gm / (r2 * r)
    j2 = 1.5 * j2c * gm * ae**2 / (r2 * r2 * r)
    zz = 5.0 * z * z / r2
    w2 = we**2
    out[0], out[1], out[2] = y[3], y[4], y[5]
    out[3] = -mu_r3 * x - j2 * x * (1.0 - zz) + w2 * x + 2.0 * we * y[4] + acc[0]
    out[4] = -mu_r3 * yy - j2 * yy * (1.0 - zz) + w2 * yy - 2.0 * we * y[3] + acc[1]
    out[5] = -mu_r3 * z - j2 * z * (3.0 - zz) + acc[2]


@njit(cache=True)
def _glonass_rk4(y0, acc, dt, step, gm, ae, j2, we):
    """Each row's state y0 (n, 6) carried over dt (n,) [s] by RK4 in ceil(|dt| / step) equal steps.

    Compiled: per row, up to 60 steps of 4 small evaluations, which cost
    ~1 ms an epoch as numpy array operations (benchmarks/results/multi_ephemeris.md).
    """
    n = y0.shape[0]
    out = np.empty_like(y0)
    k1, k2, k3, k4 = np.empty(6), np.empty(6), np.empty(6), np.empty(6)
    y, tmp = np.empty(6), np.empty(6)
    for i in range(n):
        steps = max(int(np.ceil(abs(dt[i]) / step)), 1)
        h = dt[i] / steps
        a = acc[i]
        y[:] = y0[i]
        for _ in range(steps):
            _glonass_rates(y, a, gm, ae, j2, we, k1)
            for j in range(6):
                tmp[j] = y[j] + 0.5 * h * k1[j]
            _glonass_rates(tmp, a, gm, ae, j2, we, k2)
            for j in range(6):
                tmp[j] = y[j] + 0.5 * h * k2[j]
            _glonass_rates(tmp, a, gm, ae, j2, we, k3)
            for j in range(6):
                tmp[j] = y[j] + h * k3[j]
            _glonass_rates(tmp, a, gm, ae, j2, we, k4)
            for j in range(6):
                y[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
        out[i] = y
    return out


def glonass_states(r: dict, t, step: float = GLONASS_STEP, const: GlonassConstants = GLONASS):
    """Position, velocity and clock from GLONASS broadcast records by RK4 integration.

    Parameters
    ----------
    r : dict of str -> ndarray
        One record per query: ``tb`` [s] (reference time, in the scale of
        ``t``), ``pos`` (n, 3) [m], ``vel`` (n, 3) [m/s], ``acc`` (n, 3)
        [m/s^2] (luni-solar), ``minus_tau_n`` [s] (RINEX "SV clock bias"),
        ``gamma_n`` (relative frequency bias).
    t : ndarray (n,)
        Times [s].
    step : float
        Largest integration step [s]; each query takes ``ceil(|t - tb| /
        step)`` equal steps.
    const : GlonassConstants
        ICD 5.1's by default.

    Returns
    -------
    pos, vel : ndarray (n, 3)
        PZ-90 (taken as WGS-84) ECEF [m], [m/s].
    clk : ndarray (n,)
        ``-tau_n + gamma_n (t - tb)`` [s].
    drift : ndarray (n,)
        ``gamma_n`` [s/s].
    """
    t = np.asarray(t, float)
    n = len(t)
    if n == 0:
        z = np.zeros(0)
        return np.zeros((0, 3)), np.zeros((0, 3)), z, z
    dt = t - r["tb"]
    y0 = np.ascontiguousarray(np.concatenate([r["pos"], r["vel"]], axis=1), dtype=float)
    y = _glonass_rk4(y0, np.ascontiguousarray(r["acc"], dtype=float), np.ascontiguousarray(dt), float(step),
                     const.gm, const.ae, const.j2, const.omega_e)
    clk = r["minus_tau_n"] + r["gamma_n"] * dt
    return y[:, :3].copy(), y[:, 3:].copy(), clk, np.asarray(r["gamma_n"], float).copy()
