"""Helpers the non-INS motion models share: moving the nominal position by NED metres,
the clock block's transition, a covariance step."""

from __future__ import annotations

import math

import numpy as np

from ..geodesy.earth import radii


def move_position(nav: np.ndarray, d_n: float, d_e: float, d_d: float) -> None:
    """Move ``nav[7:10]`` (lat, lon [rad], h [m]) by NED metres, in place (the INS feedback's
    convention: ``lat += dN / (R_M + h)``, ``lon += dE / ((R_N + h) cos lat)``, ``h -= dD``)."""
    lat, h = nav[7], nav[9]
    rm, rn = radii(lat)
    nav[7] = lat + d_n / (rm + h)
    nav[8] += d_e / ((rn + h) * math.cos(lat))
    nav[9] = h - d_d


def clock_blocks(layout, clock_model, T: float, Phi: np.ndarray, Qd: np.ndarray) -> None:
    """The two-state receiver clock's transition and noise over ``T`` [s] into ``Phi``,
    ``Qd`` (bias [m] driven by drift [m/s]; white frequency ``q_bias`` [m^2/s] and
    random-walk frequency ``q_drift`` [m^2/s^3]); the auxiliary random walks too."""
    c = layout.clk
    if c >= 0:
        qb, qd = clock_model.q_bias, clock_model.q_drift
        Phi[c, c + 1] = T
        Qd[c, c] += qb * T + qd * T ** 3 / 3.0
        Qd[c, c + 1] += qd * T ** 2 / 2.0
        Qd[c + 1, c] += qd * T ** 2 / 2.0
        Qd[c + 1, c + 1] += qd * T
    for name, sl in layout.aux:
        w = layout.block(name).walk
        for i in range(sl.start, sl.stop):
            Qd[i, i] += w * w * T


def initial_diagonal(layout, sigmas: dict) -> np.ndarray:
    """P0 (n, n) diagonal from block name -> 1-sigma (scalar or per state); auxiliary
    blocks default to their ``sigma0``."""
    s = np.zeros(layout.n)
    for name, sl in layout.aux:
        s[sl] = layout.block(name).sigma0
    for name, v in sigmas.items():
        if layout.has(name):
            s[layout.slice(name)] = v
    return np.diag(s ** 2)


def propagate_covariance(P: np.ndarray, Phi: np.ndarray, Qd: np.ndarray) -> None:
    """``P <- Phi P Phi^T + Qd`` in place, kept symmetric."""
    Pn = Phi @ P @ Phi.T + Qd
    P[:] = 0.5 * (Pn + Pn.T)


# --- the ensemble seam's helpers, vectorised over members ------------------------------------
def move_positions(navs: np.ndarray, d_n, d_e, d_d) -> None:
    """:func:`move_position` on every row of ``navs`` (N, 10) (NED metres (N,) each)."""
    lat, h = navs[:, 7].copy(), navs[:, 9].copy()
    rm, rn = radii(lat)
    navs[:, 7] = lat + d_n / (rm + h)
    navs[:, 8] += d_e / ((rn + h) * np.cos(lat))
    navs[:, 9] = h - d_d


def position_difference(navs: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """NED metres (N, 3) of the positions of ``navs`` (N, 10) about ``ref`` (10,): the inverse
    of :func:`move_position` from ``ref`` (radii and height at ``ref``)."""
    lat, h = ref[7], ref[9]
    rm, rn = radii(lat)
    out = np.empty((navs.shape[0], 3))
    out[:, 0] = (navs[:, 7] - lat) * (rm + h)
    out[:, 1] = (navs[:, 8] - ref[8]) * ((rn + h) * math.cos(lat))
    out[:, 2] = h - navs[:, 9]
    return out


def pass_clock_and_aux(layout, D: np.ndarray, Dn: np.ndarray, T: float) -> None:
    """The additive blocks of members over a step of ``T`` [s]: the clock bias deviation moves
    by its drift deviation times ``T``, the drift and the auxiliary deviations are kept."""
    c = layout.clk
    if c >= 0:
        Dn[:, c] = D[:, c] + D[:, c + 1] * T
        Dn[:, c + 1] = D[:, c + 1]
    for _, sl in layout.aux:
        Dn[:, sl] = D[:, sl]
