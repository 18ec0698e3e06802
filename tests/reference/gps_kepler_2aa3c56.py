"""The GPS orbit and clock kernel of BroadcastEphemeris as it was at commit 2aa3c56, frozen.

gnss/ephemeris.py now delegates to gnss/orbits.kepler_states (one Keplerian
kernel for GPS, Galileo, QZSS and BeiDou); tests/test_multi_ephemeris.py
checks that the new kernel gives bitwise the same numbers as this copy.
Do not edit.
"""

import numpy as np

GM_GPS = 3.986005e14
OMEGA_E_GPS = 7.2921151467e-5
SECONDS_PER_WEEK = 604_800.0
F_REL = -4.442807633e-10


def old_compute(rec, idx, t, apply_tgd):
    r = {k: v[idx] for k, v in rec.items()}
    n = len(idx)
    if n == 0:
        z = np.zeros(0)
        return np.zeros((0, 3)), np.zeros((0, 3)), z, z
    A = r["sqrt_a"] ** 2                                   # semi-major axis
    n0 = np.sqrt(GM_GPS / A**3)                            # computed mean motion
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
    Om = r["omega0"] + (r["omega_dot"] - OMEGA_E_GPS) * tk - OMEGA_E_GPS * r["toe"]
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
    Om_dot = r["omega_dot"] - OMEGA_E_GPS
    xp_dot = r_dot * np.cos(u) - y_p * u_dot
    yp_dot = r_dot * np.sin(u) + x_p * u_dot
    vx = xp_dot * cO - yp_dot * ci * sO + y_p * si * sO * i_dot - y * Om_dot
    vy = xp_dot * sO + yp_dot * ci * cO - y_p * si * cO * i_dot + x * Om_dot
    vz = yp_dot * si + y_p * ci * i_dot
    # clock, IS-GPS-200 20.3.3.3.3.1
    dtc = t - (r["toc_week"] * SECONDS_PER_WEEK + r["toc"])
    rel = F_REL * e * r["sqrt_a"] * sinE
    clk = r["af0"] + r["af1"] * dtc + r["af2"] * dtc**2 + rel
    if apply_tgd:
        clk = clk - r["tgd"]
    drift = r["af1"] + 2.0 * r["af2"] * dtc + F_REL * e * r["sqrt_a"] * cosE * E_dot
    return (np.stack([x, y, z], axis=-1), np.stack([vx, vy, vz], axis=-1), clk, drift)


