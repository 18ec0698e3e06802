"""Compiled SPP over all epochs: what :func:`mixnav.gnss.spp.wls_position` does for one
epoch (plain WLS, one clock plus one offset per extra system), in one loop over epochs.

The maths and every rule (mask only near the surface, the fixed-set retry when the steps
never settle, which system takes the clock, the covariance and DOPs) are those of
:mod:`mixnav.gnss.spp`; the numpy functions there stay the reference it is tested against
(tests/test_spp_kernel.py). Linear algebra is a hand-written Cholesky of the (at most 8 x 8)
normal matrix, so the last bits differ from LAPACK's.

Inputs are the observations that have a satellite state, grouped by epoch
(``bounds[j]:bounds[j + 1]``); system indices are positions in ``G R E C J``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..geodesy.earth import A_WGS84, E2_WGS84
from ..linalg import cholesky_lower
from .geometry import C_LIGHT, OMEGA_E_GPS

#: the robust solution blames a row only if its standardised residual exceeds every other
#: row's by this many standard deviations of their difference (spp's module docstring,
#: "Robust solution"; re-exported by spp)
SEPARATION_SIGMAS = 3.0
#: RTKLIB pntpos's pseudorange variance (``SppOptions.weights = "rtklib"``, spp's docstring):
#: code sigma 0.9 m = its default error ratio 300 x 0.003 m (prcopt_default err[1], err[2],
#: eratio[0]) for both the constant and the 1/sin(el) term, elevation floored at 5 deg
#: (MIN_EL); per-system factors (EFACT_*); code bias 0.3 m (ERR_CBIAS); broadcast ionosphere
#: half its delay (ERR_BRDCI), 5 m without (ERR_ION); Saastamoinen 0.3 m / (sin el + 0.1)
#: (ERR_SAAS), 3 m without (ERR_TROP). RTKLIB demo5 EX 2.5.1 src/pntpos.c, src/rtklib.h.
RTKLIB_CODE_SIGMA = 0.9
#: RTKLIB 2.4.3 b34's code sigma (``SppOptions.weights = "rtklib-2.4.3"``): its pntpos.c varerr
#: scales err[1], err[2] (0.003 m) by err[0] = 100 (prcopt_default; no option key sets it in
#: b34, stats-eratio1 writes eratio[0], which b34's pntpos does not read): 0.3 m. The other
#: terms and the factors are the same in both versions.
RTKLIB_243_CODE_SIGMA = 0.3
#: the code sigma of each RTKLIB weights name
RTKLIB_CODE_SIGMAS = {"rtklib": RTKLIB_CODE_SIGMA, "rtklib-2.4.3": RTKLIB_243_CODE_SIGMA}
#: FDE: an exclusion is kept only if its post-fit residual RMS is at most this [m] and it
#: leaves at least RTKLIB_FDE_MIN_SATELLITES used rows (RTKLIB raim_fde: rms = 100.0, nvsat < 5)
RTKLIB_FDE_MAX_RMS = 100.0
RTKLIB_FDE_MIN_SATELLITES = 5
RTKLIB_MIN_ELEVATION = np.deg2rad(5.0)
RTKLIB_SYSTEM_FACTOR = {"G": 1.0, "R": 1.5, "E": 1.0, "C": 1.0, "J": 1.0}
RTKLIB_CODE_BIAS_SIGMA = 0.3
RTKLIB_IONO_FACTOR, RTKLIB_IONO_OFF_SIGMA = 0.5, 5.0
RTKLIB_TROPO_SIGMA, RTKLIB_TROPO_OFF_SIGMA = 0.3, 3.0
#: validation's GDOP limit: RTKLIB's default maxgdop (prcopt_default, 30)
RTKLIB_MAX_GDOP = 30.0

N_SYSTEMS = 5
#: status codes of :func:`spp_epochs` (mapped to spp.STATUS_* by the caller)
CODE_OK, CODE_FEW, CODE_NOT_CONVERGED = 0, 1, 2
#: robust status codes (spp.SppSolution.robust_status: off, ok, untestable, not_separable)
ROBUST_OFF, ROBUST_OK, ROBUST_UNTESTABLE, ROBUST_NOT_SEPARABLE = 0, 1, 2, 3
#: status of an epoch that validation rejected
CODE_REJECTED = 3
#: validation codes: off, passed, passed after FDE's exclusion, failed chi-square, failed GDOP
VALID_OFF, VALID_PASSED, VALID_FDE, VALID_CHI2, VALID_GDOP = 0, 1, 2, 3, 4
#: the mask and atmosphere apply within this of the Earth's mean radius [m] (as spp.py)
_R_MEAN, _NEAR = 6.371e6, 5e5


@njit(cache=True)
def _ecef_to_lla(x, y, z):
    """As :func:`mixnav.geodesy.frames.ecef_to_lla` (same fixed-point iteration)."""
    lon = math.atan2(y, x)
    rho = math.hypot(x, y)
    lat = math.atan2(z, rho * (1.0 - E2_WGS84))
    h = 0.0
    for it in range(7):
        s = math.sin(lat)
        c = math.cos(lat)
        rn = A_WGS84 / math.sqrt(1.0 - E2_WGS84 * s * s)
        if abs(c) > abs(s):
            h = rho / c - rn
        else:
            h = z / s - rn * (1.0 - E2_WGS84)
        if it < 6:
            lat = math.atan2(z, rho * (1.0 - E2_WGS84 * rn / (rn + h)))
    return lat, lon, h


@njit(cache=True)
def _saastamoinen(lat, h, el):
    """As :func:`mixnav.gnss.spp.saastamoinen` (humidity 0.5), ``el`` already >= 1e-3."""
    hgt = min(max(h, 0.0), 1.0e4)
    p_hpa = 1013.25 * (1.0 - 2.2557e-5 * hgt) ** 5.2568
    t_k = 288.15 - 6.5e-3 * hgt
    t_c = t_k - 273.15
    e_hpa = 6.108 * 0.5 * math.exp(17.15 * t_c / (t_c + 234.7))
    zhd = 0.0022768 * p_hpa / (1.0 - 0.00266 * math.cos(2.0 * lat) - 0.00028 * hgt / 1e3)
    zwd = 0.002277 * (1255.0 / t_k + 0.05) * e_hpa
    return (zhd + zwd) / math.sin(el)


@njit(cache=True)
def _klobuchar(lat, lon, el, az, tow, alpha, beta):
    """As :func:`mixnav.gnss.spp.klobuchar` for one satellite [m]."""
    e = el / math.pi
    psi = 0.0137 / (e + 0.11) - 0.022
    phi_i = min(max(lat / math.pi + psi * math.cos(az), -0.416), 0.416)
    lam_i = lon / math.pi + psi * math.sin(az) / math.cos(phi_i * math.pi)
    phi_m = phi_i + 0.064 * math.cos((lam_i - 1.617) * math.pi)
    t = (4.32e4 * lam_i + tow) % 86400.0          # Python's and numpy's mod: in [0, 86400)
    f = 1.0 + 16.0 * (0.53 - e) ** 3
    amp = alpha[0] + phi_m * alpha[1] + phi_m ** 2 * alpha[2] + phi_m ** 3 * alpha[3]
    per = beta[0] + phi_m * beta[1] + phi_m ** 2 * beta[2] + phi_m ** 3 * beta[3]
    amp = max(amp, 0.0)
    per = max(per, 72000.0)
    x = 2.0 * math.pi * (t - 50400.0) / per
    if abs(x) < 1.57:
        return C_LIGHT * f * (5.0e-9 + amp * (1.0 - x * x / 2.0 + x ** 4 / 24.0))
    return C_LIGHT * f * 5.0e-9


@njit(cache=True)
def _chol_solve(L, b, out, n):
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * out[k]
        out[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = out[i]
        for k in range(i + 1, n):
            s -= L[k, i] * out[k]
        out[i] = s / L[i, i]


@njit(cache=True)
def _chol_inverse(L, inv, n):
    """``(L L^T)^-1`` into ``inv[:n, :n]``."""
    e = np.zeros(n)
    col = np.zeros(n)
    for j in range(n):
        e[:] = 0.0
        e[j] = 1.0
        _chol_solve(L, e, col, n)
        for i in range(n):
            inv[i, j] = col[i]


@njit(cache=True)
def _linearise(x, sat, rho_corr, col, iono_scale, e0, e1, with_atm, tow, tropo, iono, alpha, beta,
               H, dz, el_out, az_out, iono_out):
    """Rows ``e0:e1`` at ``x``: ``H`` (-u, 1, offset columns by ``col``), ``dz`` (measured
    minus modelled), elevation and azimuth (pi/2, 0 without ``with_atm``), the ionosphere
    delay in the model (0 without)."""
    n_off = x.shape[0] - 4
    lat = lon = hgt = 0.0
    sl = cl = so = co = 0.0
    if with_atm:
        lat, lon, hgt = _ecef_to_lla(x[0], x[1], x[2])
        sl, cl = math.sin(lat), math.cos(lat)
        so, co = math.sin(lon), math.cos(lon)
    for i in range(e0, e1):
        r = i - e0
        dx0, dx1, dx2 = sat[i, 0] - x[0], sat[i, 1] - x[1], sat[i, 2] - x[2]
        a = OMEGA_E_GPS * (math.sqrt(dx0 * dx0 + dx1 * dx1 + dx2 * dx2) / C_LIGHT)
        c, s = math.cos(a), math.sin(a)
        sx = c * sat[i, 0] + s * sat[i, 1]
        sy = -s * sat[i, 0] + c * sat[i, 1]
        sz = sat[i, 2]
        ux, uy, uz = sx - x[0], sy - x[1], sz - x[2]
        rng = math.sqrt(ux * ux + uy * uy + uz * uz)
        ux, uy, uz = ux / rng, uy / rng, uz / rng
        model = rng + x[3]
        if col[i] >= 0:
            model += x[4 + col[i]]
        H[r, 0], H[r, 1], H[r, 2], H[r, 3] = -ux, -uy, -uz, 1.0
        for k in range(n_off):
            H[r, 4 + k] = 1.0 if col[i] == k else 0.0
        el, az = math.pi / 2, 0.0
        iono_out[r] = 0.0
        if with_atm:
            un = -sl * co * ux - sl * so * uy + cl * uz
            ue = -so * ux + co * uy
            ud = -cl * co * ux - cl * so * uy - sl * uz
            el = math.asin(min(max(-ud, -1.0), 1.0))
            az = math.atan2(ue, un)
            if az < 0.0:
                az += 2.0 * math.pi
            d = 0.0
            if tropo:
                d += _saastamoinen(lat, hgt, max(el, 1e-3))
            if iono:
                iono_out[r] = _klobuchar(lat, lon, el, az, tow, alpha, beta) * iono_scale[i]
                d += iono_out[r]
            model += d
        el_out[r], az_out[r] = el, az
        dz[r] = rho_corr[i] - model


@njit(cache=True)
def _weights(p, el, iono_d, scale, fact, var_eph, e0, n, w, gamma):
    """``w[:n]``: ``gamma`` / variance of rows ``e0:e0 + n`` (spp._sigma; ``gamma`` the
    robust solution's factors): mixnav's elevation model (``p[7]`` 0) or RTKLIB's (``p[7]`` its
    code sigma [m], RTKLIB_CODE_SIGMAS)."""
    for r in range(n):
        i = e0 + r
        if p[7] == 0.0:
            s = math.sin(max(el[r], 1e-3))
            sig = scale[i] * math.sqrt(p[1] ** 2 + p[2] ** 2 / s ** 2)
            w[r] = 1.0 / sig ** 2
        else:
            code = (scale[i] * fact[i] * p[7]) ** 2 * (1.0 + 1.0 / math.sin(max(el[r],
                                                                          RTKLIB_MIN_ELEVATION)))
            ion = (RTKLIB_IONO_FACTOR * iono_d[r]) ** 2 if p[4] > 0 else RTKLIB_IONO_OFF_SIGMA ** 2
            if p[3] > 0:
                trop = (RTKLIB_TROPO_SIGMA / (math.sin(max(el[r], 0.0)) + 0.1)) ** 2
            else:
                trop = RTKLIB_TROPO_OFF_SIGMA ** 2
            w[r] = 1.0 / (code + var_eph[i] + RTKLIB_CODE_BIAS_SIGMA ** 2 + ion + trop)
        if gamma[r] != 1.0:
            w[r] *= gamma[r]


@njit(cache=True)
def _near_surface(x):
    return abs(math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) - _R_MEAN) < _NEAR


@njit(cache=True)
def _active(sel, col, e0, e1, n_off, act):
    """As spp._active: position and clock, each offset with a row; the first system with
    rows takes the clock when the clock's own system has none. Returns the count."""
    for k in range(4):
        act[k] = True
    clock_rows = False
    for k in range(n_off):
        act[4 + k] = False
    for i in range(e0, e1):
        if sel[i - e0]:
            if col[i] < 0:
                clock_rows = True
            else:
                act[4 + col[i]] = True
    if not clock_rows:
        for k in range(n_off):
            if act[4 + k]:
                act[4 + k] = False
                break
    cnt = 0
    for k in range(4 + n_off):
        if act[k]:
            cnt += 1
    return cnt


@njit(cache=True)
def _normal(H, dz, w, sel, act, n_rows, n_unk, N, b):
    """``N = Hs^T W Hs`` and ``b = Hs^T W dz`` over the selected rows and active columns."""
    for a in range(n_unk):
        b[a] = 0.0
        for c in range(n_unk):
            N[a, c] = 0.0
    for r in range(n_rows):
        if not sel[r]:
            continue
        a = 0
        for p in range(H.shape[1]):
            if not act[p]:
                continue
            hp = H[r, p] * w[r]
            b[a] += hp * dz[r]
            c = 0
            for q in range(H.shape[1]):
                if not act[q]:
                    continue
                N[a, c] += hp * H[r, q]
                c += 1
            a += 1


@njit(cache=True)
def _gauss_newton(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0, e1, use, mask_on, p, alpha, beta,
                  tow, H, dz, el, az, iono_d, w, sel, act, N, L, b, dx, gamma):
    """As spp._gauss_newton: ``(status, iterations)``, status 1 converged, 0 not, -1 too few
    rows; ``sel`` the last step's rows. Callers pass ``mask_on`` as ``bool(True)`` /
    ``bool(False)``: a bare literal is typed ``Literal[bool]`` and each value compiles this
    kernel (and ``_linearise``) once more on a cold cache."""
    elevation_mask, tropo, iono, max_iter, tol = p[0], p[3], p[4], p[5], p[6]
    n = e1 - e0
    n_off = x.shape[0] - 4
    it = 0
    for it in range(1, int(max_iter) + 1):
        near = _near_surface(x)
        _linearise(x, sat, rho_corr, col, iono_scale, e0, e1, near, tow, tropo > 0, iono > 0, alpha, beta,
                   H, dz, el, az, iono_d)
        n_sel = 0
        for r in range(n):
            sel[r] = use[r] and not (near and mask_on and el[r] < elevation_mask)
            if sel[r]:
                n_sel += 1
        n_unk = _active(sel, col, e0, e1, n_off, act)
        if n_sel < n_unk:
            return -1, it
        _weights(p, el, iono_d, scale, fact, var_eph, e0, n, w, gamma)
        _normal(H, dz, w, sel, act, n, n_unk, N, b)
        if not cholesky_lower(N[:n_unk, :n_unk], L[:n_unk, :n_unk]):
            return -1, it
        _chol_solve(L, b, dx, n_unk)
        a = 0
        for k in range(4 + n_off):
            if act[k]:
                x[k] += dx[a]
                a += 1
        if math.sqrt(dx[0] ** 2 + dx[1] ** 2 + dx[2] ** 2) < tol and near:
            return 1, it
    return 0, it


@njit(cache=True)
def _igg3(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0, e1, sel, p, alpha, beta, tow, H, dz, el, az,
          iono_d, w, act, N, L, b, dx, gamma, touched, keep, sel2, Hc, s2, Ninv, idx, qv, t_all, t_ok):
    """As spp._igg3_solution from the converged plain solution ``x`` (changed in place):
    ``gamma`` the factors; returns the robust status code (ROBUST_*) or -1 when a step finds
    too few rows or a singular normal matrix (spp raises: too few satellites)."""
    n = e1 - e0
    n_off = x.shape[0] - 4
    k0, k1 = p[9], p[10]
    n_sel = 0
    for r in range(n):
        gamma[r] = 1.0
        touched[r] = not sel[r]
        if sel[r]:
            n_sel += 1
    if n_sel < _active(sel, col, e0, e1, n_off, act) + 2:
        return ROBUST_UNTESTABLE
    while True:
        n_keep = 0
        for r in range(n):
            keep[r] = sel[r] and gamma[r] > 0.0
            if keep[r]:
                n_keep += 1
        n_unk = _active(keep, col, e0, e1, n_off, act)
        if n_keep < n_unk + 2:          # one more row out would leave nothing to check it by
            break
        _linearise(x, sat, rho_corr, col, iono_scale, e0, e1, _near_surface(x), tow, p[3] > 0, p[4] > 0, alpha,
                   beta, H, dz, el, az, iono_d)
        _weights(p, el, iono_d, scale, fact, var_eph, e0, n, w, gamma)
        m = 0
        for r in range(n):
            if keep[r]:
                idx[m] = r
                a = 0
                for c in range(4 + n_off):
                    if act[c]:
                        Hc[m, a] = H[r, c]
                        a += 1
                s2[m] = 1.0 / w[r]
                m += 1
        for a in range(n_unk):
            for c in range(n_unk):
                t = 0.0
                for i in range(m):
                    t += Hc[i, a] * Hc[i, c] / s2[i]
                N[a, c] = t
        if not cholesky_lower(N[:n_unk, :n_unk], L[:n_unk, :n_unk]):
            return -1
        _chol_inverse(L, Ninv, n_unk)
        any_ok = False
        for i in range(m):
            hnh = 0.0
            for a in range(n_unk):
                for c in range(n_unk):
                    hnh += Hc[i, a] * Ninv[a, c] * Hc[i, c]
            qv[i] = s2[i] - hnh          # the residual's own variance in this solution
            t_all[i] = abs(dz[idx[i]]) / math.sqrt(max(qv[i], 1e-300))
            ok = qv[i] > 0.05 * s2[i] and not touched[idx[i]]
            t_ok[i] = t_all[i] if ok else 0.0
            any_ok = any_ok or ok
        if not any_ok:
            break
        j = 0
        for i in range(1, m):
            if t_ok[i] > t_ok[j]:
                j = i
        if t_ok[j] <= k0:
            break
        # blame row j only if it stands out from every other row (spp._igg3_solution)
        for i in range(m):
            if i == j:
                continue
            q_ji = 0.0
            for a in range(n_unk):
                for c in range(n_unk):
                    q_ji -= Hc[j, a] * Ninv[a, c] * Hc[i, c]
            rr = abs(q_ji) / math.sqrt(max(qv[j] * qv[i], 1e-300))
            sd = math.sqrt(2.0 * max(1.0 - rr, 0.0))
            if rr > 0.999 or t_ok[j] - t_all[i] < SEPARATION_SIGMAS * sd:
                return ROBUST_NOT_SEPARABLE
        tj = t_ok[j]
        worst = idx[j]
        gamma[worst] = 0.0 if tj > k1 else (k0 / tj) * ((k1 - tj) / (k1 - k0)) ** 2
        touched[worst] = True
        for r in range(n):
            keep[r] = sel[r] and gamma[r] > 0.0
        st, _ = _gauss_newton(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0, e1, keep, bool(True), p, alpha,
                              beta, tow, H, dz, el, az, iono_d, w, sel2, act, N, L, b, dx, gamma)
        if st < 0:
            return -1
    return ROBUST_OK


@njit(cache=True)
def _solve_rows(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0, e1, use0, use, p, alpha, beta, tow, H,
                dz, el, az, iono_d, w, sel, act, N, L, b, dx, gamma, touched, keep, sel2, Hc, s2, Ninv, idx, qv,
                t_all, t_ok):
    """One epoch's solution on the rows ``use0`` from ``x`` (changed in place), as
    spp.wls_position: WLS, the fixed-set retry when the steps never settle, the robust
    solution when asked. ``(status, robust code)``, status 1 converged, 0 not, -1 too few
    rows or a singular step; ``sel`` and ``gamma`` the solution's rows and weight factors."""
    n = e1 - e0
    for r in range(n):
        use[r] = use0[r]
        gamma[r] = 1.0
    st, _ = _gauss_newton(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0, e1, use, bool(True), p,
                          alpha, beta, tow, H, dz, el, az, iono_d, w, sel, act, N, L, b, dx, gamma)
    if st == 0 and _near_surface(x):
        # a satellite at the mask entering and leaving: keep the last set, iterate on
        for r in range(n):
            use[r] = sel[r]
        st, _ = _gauss_newton(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0, e1, use, bool(False),
                              p, alpha, beta, tow, H, dz, el, az, iono_d, w, sel, act, N, L, b, dx, gamma)
    if st < 0:
        return -1, ROBUST_OFF
    rcode = ROBUST_OFF
    if p[8] > 0 and st == 1:
        rcode = _igg3(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0, e1, sel, p, alpha, beta,
                      tow, H, dz, el, az, iono_d, w, act, N, L, b, dx, gamma, touched, keep, sel2, Hc, s2,
                      Ninv, idx, qv, t_all, t_ok)
        if rcode < 0:
            return -1, ROBUST_OFF
    return st, rcode


@njit(cache=True)
def _postfit(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0, e1, p, alpha, beta, tow, H, dz, el, az,
             iono_d, w, sel, gamma, usedr, act, N, L, b, inv, G, NG, Q):
    """The solution's quantities at ``x``: ``usedr`` (above the mask, not excluded by the
    robust weights), ``H``, ``dz``, ``el`` of every row, ``inv`` the covariance and ``Q`` the
    unweighted east-north-up cofactor (DOPs). ``(ok, unknowns, rows used, chi2)``, chi2 the
    squared residuals over their variances (robust factors included); ok False when a normal
    matrix is singular."""
    n = e1 - e0
    n_off = x.shape[0] - 4
    for r in range(n):
        usedr[r] = sel[r] and gamma[r] > 0.0
    _linearise(x, sat, rho_corr, col, iono_scale, e0, e1, bool(True), tow, p[3] > 0, p[4] > 0, alpha, beta, H, dz, el,
               az, iono_d)
    n_unk = _active(usedr, col, e0, e1, n_off, act)
    _weights(p, el, iono_d, scale, fact, var_eph, e0, n, w, gamma)
    chi2 = 0.0
    n_use = 0
    for r in range(n):
        if usedr[r]:
            chi2 += dz[r] * dz[r] * w[r]
            n_use += 1
    _normal(H, dz, w, usedr, act, n, n_unk, N, b)
    if not cholesky_lower(N[:n_unk, :n_unk], L[:n_unk, :n_unk]):
        return False, n_unk, n_use, chi2
    _chol_inverse(L, inv, n_unk)
    # DOPs: unweighted, position in east-north-up
    lat, lon, _ = _ecef_to_lla(x[0], x[1], x[2])
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    for r in range(n):
        hx, hy, hz = H[r, 0], H[r, 1], H[r, 2]
        G[r, 0] = -so * hx + co * hy
        G[r, 1] = -sl * co * hx - sl * so * hy + cl * hz
        G[r, 2] = cl * co * hx + cl * so * hy + sl * hz
        for q in range(3, 4 + n_off):
            G[r, q] = H[r, q]
        w[r] = 1.0
    _normal(G, dz, w, usedr, act, n, n_unk, NG, b)
    if not cholesky_lower(NG[:n_unk, :n_unk], L[:n_unk, :n_unk]):
        return False, n_unk, n_use, chi2
    _chol_inverse(L, Q, n_unk)
    return True, n_unk, n_use, chi2


@njit(cache=True)
def _verdict(chi2, dof, Q, max_gdop, chi2_table):
    """As spp._validation_failure: VALID_CHI2 when ``chi2`` is beyond its quantile (tested
    with a spare row), VALID_GDOP when the position + clock GDOP is beyond ``max_gdop``,
    else VALID_PASSED."""
    if dof >= 1 and chi2 > chi2_table[min(dof, chi2_table.shape[0]) - 1]:
        return VALID_CHI2
    if math.sqrt(Q[0, 0] + Q[1, 1] + Q[2, 2] + Q[3, 3]) > max_gdop:
        return VALID_GDOP
    return VALID_PASSED


@njit(cache=True)
def spp_epochs(sat, rho_corr, scale, fact, var_eph, iono_scale, sys_idx, bounds, tow, params, alpha, beta,
               pos, clock, cov, offsets, clock_sys, status, n_used, dops, rms, n_rejected, used, below, robust_code,
               n_down, n_excl, chi2_table, valid_code, excluded):
    """Plain WLS SPP at every epoch (module docstring); outputs filled in place.

    ``params``: elevation mask [rad], sigma_a, sigma_b [m], troposphere, ionosphere (1/0),
    max_iter, tol [m], weights (0 elevation, else RTKLIB's with this code sigma [m]: per row
    ``fact`` its system factor and ``var_eph`` its ephemeris variance [m^2]), robust (1/0), k0, k1 (IGG-III); per epoch
    the robust status code, rows down-weighted and excluded. Per epoch: ``pos`` (k, 3), ``clock`` (k,), ``cov`` (k, 4, 4) position
    and clock, ``offsets`` (k, 5) per system in ``G R E C J`` (0 for the clock's, NaN for
    a system without a used row), ``clock_sys`` (k,) the clock's system (-1 none),
    ``status`` (k,) a CODE_*, ``n_used``, ``dops`` (k, 3) PDOP, HDOP, VDOP, ``rms`` residual
    RMS, ``n_rejected`` rows left out by the mask; per observation ``used`` and ``below``
    (under the mask seen from the final position, as spp._below_mask).

    Validation (``params[11]`` 1; spp's module docstring, "Validation"): ``chi2_table`` the
    chi-square quantiles for 1, 2, ... degrees of freedom, ``params[13]`` the GDOP limit;
    ``params[12]`` 1: FDE. Per epoch ``valid_code`` a VALID_* and ``excluded`` the row (within
    the epoch) FDE left out, -1 none.
    """
    k = tow.shape[0]
    mmax = 0
    for j in range(k):
        mmax = max(mmax, bounds[j + 1] - bounds[j])
    H = np.zeros((mmax, 4 + N_SYSTEMS))
    dz, el, az, iono_d = np.zeros(mmax), np.zeros(mmax), np.zeros(mmax), np.zeros(mmax)
    w = np.zeros(mmax)
    sel = np.zeros(mmax, np.bool_)
    use = np.zeros(mmax, np.bool_)
    act = np.zeros(4 + N_SYSTEMS, np.bool_)
    N = np.zeros((4 + N_SYSTEMS, 4 + N_SYSTEMS))
    L = np.zeros_like(N)
    inv = np.zeros_like(N)
    NG = np.zeros_like(N)
    Q = np.zeros_like(N)
    G = np.zeros((mmax, 4 + N_SYSTEMS))
    b = np.zeros(4 + N_SYSTEMS)
    dx = np.zeros(4 + N_SYSTEMS)
    col = np.full(sat.shape[0], -1, np.int64)
    col_of = np.zeros(N_SYSTEMS, np.int64)
    sys_of_col = np.zeros(N_SYSTEMS, np.int64)
    x0 = np.zeros(4)
    have_x0 = False
    gamma = np.ones(mmax)
    touched = np.zeros(mmax, np.bool_)
    keep = np.zeros(mmax, np.bool_)
    sel2 = np.zeros(mmax, np.bool_)
    usedr = np.zeros(mmax, np.bool_)
    Hc = np.zeros((mmax, 4 + N_SYSTEMS))
    s2, qv, t_all, t_ok = np.zeros(mmax), np.zeros(mmax), np.zeros(mmax), np.zeros(mmax)
    idx = np.zeros(mmax, np.int64)
    Ninv = np.zeros_like(N)
    use0 = np.zeros(mmax, np.bool_)
    cand = np.zeros(mmax, np.bool_)
    xs = np.zeros(4)
    for j in range(k):
        e0, e1 = bounds[j], bounds[j + 1]
        n = e1 - e0
        if n < 4:
            status[j] = CODE_FEW
            continue
        # systems present: the first takes the clock, the others an offset column each
        present = np.zeros(N_SYSTEMS, np.bool_)
        for i in range(e0, e1):
            present[sys_idx[i]] = True
        first = -1
        n_off = 0
        for s in range(N_SYSTEMS):
            if present[s]:
                if first < 0:
                    first = s
                    col_of[s] = -1
                else:
                    col_of[s] = n_off
                    sys_of_col[n_off] = s
                    n_off += 1
        for i in range(e0, e1):
            col[i] = col_of[sys_idx[i]]
        x = np.zeros(4 + n_off)
        if have_x0:
            x[:4] = x0
        for r in range(n):
            use0[r] = True
        st, rcode = _solve_rows(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0, e1, use0, use, params,
                                alpha, beta, tow[j], H, dz, el, az, iono_d, w, sel, act, N, L, b, dx, gamma, touched,
                                keep, sel2, Hc, s2, Ninv, idx, qv, t_all, t_ok)
        if st < 0:
            status[j] = CODE_FEW
            have_x0 = False
            continue
        ok, n_unk, n_use, chi2 = _postfit(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0, e1, params,
                                          alpha, beta, tow[j], H, dz, el, az, iono_d, w, sel, gamma, usedr, act, N, L,
                                          b, inv, G, NG, Q)
        if not ok:
            status[j] = CODE_FEW
            have_x0 = False
            continue
        vcode = VALID_OFF
        excl = -1
        if params[11] > 0 and st == 1:
            vcode = _verdict(chi2, n_use - n_unk, Q, params[13], chi2_table)
            if vcode != VALID_PASSED and params[12] > 0:
                # FDE: each used row left out in turn, from this solution's position and
                # clock; the passing solution of the smallest post-fit residual RMS [m], at most
                # RTKLIB_FDE_MAX_RMS, with at least RTKLIB_FDE_MIN_SATELLITES rows, the later on
                # a tie (RTKLIB raim_fde)
                for r in range(n):
                    cand[r] = usedr[r]
                xs[:] = x[:4]
                best, best_score = -1, RTKLIB_FDE_MAX_RMS
                for c in range(n):
                    if not cand[c]:
                        continue
                    xt = np.zeros(4 + n_off)
                    xt[:4] = xs
                    for r in range(n):
                        use0[r] = r != c
                    st2, _ = _solve_rows(xt, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0, e1, use0, use,
                                         params, alpha, beta, tow[j], H, dz, el, az, iono_d, w, sel, act, N, L, b, dx,
                                         gamma, touched, keep, sel2, Hc, s2, Ninv, idx, qv, t_all, t_ok)
                    if st2 != 1:
                        continue
                    ok2, nu2, nuse2, chi2b = _postfit(xt, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0,
                                                      e1, params, alpha, beta, tow[j], H, dz, el, az, iono_d, w, sel,
                                                      gamma, usedr, act, N, L, b, inv, G, NG, Q)
                    # a candidate with no spare row has nothing to check it by
                    if not ok2 or nuse2 - nu2 < 1:
                        continue
                    if nuse2 < RTKLIB_FDE_MIN_SATELLITES or \
                            _verdict(chi2b, nuse2 - nu2, Q, params[13], chi2_table) != VALID_PASSED:
                        continue
                    ss2 = 0.0
                    for r in range(n):
                        if usedr[r]:
                            ss2 += dz[r] * dz[r]
                    rms2 = math.sqrt(ss2 / nuse2)
                    if rms2 <= best_score:
                        best, best_score = c, rms2
                if best >= 0:      # solved again: its quantities into the buffers
                    x = np.zeros(4 + n_off)
                    x[:4] = xs
                    for r in range(n):
                        use0[r] = r != best
                    st, rcode = _solve_rows(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0, e1, use0,
                                            use, params, alpha, beta, tow[j], H, dz, el, az, iono_d, w, sel, act, N,
                                            L, b, dx, gamma, touched, keep, sel2, Hc, s2, Ninv, idx, qv, t_all, t_ok)
                    ok, n_unk, n_use, chi2 = _postfit(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0,
                                                      e1, params, alpha, beta, tow[j], H, dz, el, az, iono_d, w, sel,
                                                      gamma, usedr, act, N, L, b, inv, G, NG, Q)
                    vcode = VALID_FDE
                    excl = best
                else:
                    # the buffers hold the last candidate's: the epoch's own solution again
                    x = np.zeros(4 + n_off)
                    if have_x0:
                        x[:4] = x0
                    for r in range(n):
                        use0[r] = True
                    st, rcode = _solve_rows(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0, e1, use0,
                                            use, params, alpha, beta, tow[j], H, dz, el, az, iono_d, w, sel, act, N,
                                            L, b, dx, gamma, touched, keep, sel2, Hc, s2, Ninv, idx, qv, t_all, t_ok)
                    ok, n_unk, n_use, chi2 = _postfit(x, sat, rho_corr, col, scale, fact, var_eph, iono_scale, e0,
                                                      e1, params, alpha, beta, tow[j], H, dz, el, az, iono_d, w, sel,
                                                      gamma, usedr, act, N, L, b, inv, G, NG, Q)
        # the rows under the mask seen from the final position (spp._below_mask's count)
        n_sel = 0
        n_use = 0
        nd = 0
        ne = 0
        for r in range(n):
            below[e0 + r] = el[r] < params[0]
            used[e0 + r] = usedr[r]
            if sel[r]:
                n_sel += 1
            if usedr[r]:
                n_use += 1
            if gamma[r] == 0.0:
                ne += 1
            elif gamma[r] < 1.0:
                nd += 1
        n_rejected[j] = n - n_sel - (1 if excl >= 0 else 0)     # the row FDE left out is not the mask's
        robust_code[j] = rcode
        n_down[j] = nd
        n_excl[j] = ne
        valid_code[j] = vcode
        excluded[j] = excl
        if st == 0:
            status[j] = CODE_NOT_CONVERGED
            have_x0 = False
            continue
        if vcode >= VALID_CHI2:
            status[j] = CODE_REJECTED
            have_x0 = False
            continue
        status[j] = CODE_OK
        for q in range(3):
            pos[j, q] = x[q]
        clock[j] = x[3]
        for a in range(4):
            for c in range(4):
                cov[j, a, c] = inv[a, c]
        dops[j, 0] = math.sqrt(Q[0, 0] + Q[1, 1] + Q[2, 2])
        dops[j, 1] = math.sqrt(Q[0, 0] + Q[1, 1])
        dops[j, 2] = math.sqrt(Q[2, 2])
        ss = 0.0
        for r in range(n):
            if usedr[r]:
                ss += dz[r] * dz[r]
        rms[j] = math.sqrt(ss / n_use)
        n_used[j] = n_use
        # the clock's system: the first present with a used row (spp.wls_position's offsets)
        clock_rows = False
        for i in range(e0, e1):
            if usedr[i - e0] and col[i] < 0:
                clock_rows = True
        ref = first if clock_rows else -1
        for c in range(n_off):
            if act[4 + c]:
                offsets[j, sys_of_col[c]] = x[4 + c]
            elif ref < 0:
                for i in range(e0, e1):
                    if usedr[i - e0] and col[i] == c:
                        ref = sys_of_col[c]
                        break
        if ref >= 0:
            offsets[j, ref] = 0.0
        clock_sys[j] = ref
        x0[:] = x[:4]
        have_x0 = True
    return 0
