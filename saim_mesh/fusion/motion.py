"""The Kalman tracker's filter arithmetic (tracker.py), batched: each function works on
every track of a scan (or of one prediction interval) at once, since a node's tracks
are few and numpy's per-call overhead on 5 x 5 matrices, not the arithmetic, is what a
per-track loop costs. States are [x, y, vx, vy, turn rate]; per track, three motion
models (axis 1 of the arrays) mixed by an IMM."""
from __future__ import annotations

import math

import numpy as np

W0 = 1e-6   # the constant-velocity models' turn-rate variance (rad^2/s^2): they do not turn
I3 = np.eye(3)


def q4(q: float, dt: float) -> np.ndarray:
    """White-acceleration process noise (spectral density q) on position and velocity, 5 x 5."""
    d3, d2, d1 = q * dt ** 3 / 3, q * dt ** 2 / 2, q * dt
    Q = np.zeros((5, 5))
    Q[0, 0] = Q[1, 1] = d3
    Q[0, 2] = Q[2, 0] = Q[1, 3] = Q[3, 1] = d2
    Q[2, 2] = Q[3, 3] = d1
    return Q


def cv_matrix(dt: float) -> np.ndarray:
    """Constant velocity over dt; the turn rate is reset to 0 (the model does not turn)."""
    F = np.eye(5)
    F[0, 2] = F[1, 3] = dt
    F[4, 4] = 0.0
    return F


def mixing(rates: np.ndarray, dt: float) -> np.ndarray:
    """P(model j at t + dt | model i at t) = expm(rates x dt), by scaling and squaring."""
    A = rates * dt
    k = max(0, int(math.ceil(math.log2(max(np.abs(A).sum(axis=1).max(), 1e-12)))) + 1)
    A = A / 2.0 ** k
    E, term = I3.copy(), I3.copy()
    for i in range(1, 8):
        term = term @ A / i
        E = E + term
    for _ in range(k):
        E = E @ E
    return E


def imm_mix(mu: np.ndarray, Pi: np.ndarray, xs: np.ndarray, Ps: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The IMM's mixing step for tracks x models: (predicted model probabilities, each
    model's mixed state and covariance), each model's start the others' blend by the
    chance the track came from them."""
    c = mu @ Pi                                               # tracks x models
    w = mu[:, :, None] * Pi[None] / c[:, None, :]             # w[., i, j]: P(was i | is j)
    wT = w.transpose(0, 2, 1)
    x0 = wT @ xs
    dx = xs[:, :, None, :] - x0[:, None, :, :]                # t, i, j, k
    n = len(mu)
    P0 = (wT @ Ps.reshape(n, 3, 25)).reshape(n, 3, 5, 5)
    P0 += (w[..., None] * dx).transpose(0, 2, 3, 1) @ dx.transpose(0, 2, 1, 3)
    return c, x0, P0


def mixture(mu: np.ndarray, xs: np.ndarray, Ps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The models' moment-matched mixture per track (for gating by the whole track and reports)."""
    X = (mu[:, None, :] @ xs)[:, 0]
    dx = xs - X[:, None, :]
    n = len(mu)
    P = (mu[:, None, :] @ Ps.reshape(n, 3, 25)).reshape(n, 5, 5)
    P += (mu[:, :, None] * dx).transpose(0, 2, 1) @ dx
    return X, P


def ct(x: np.ndarray, P: np.ndarray, q: np.ndarray, q_turn: float, max_turn: float, dt: float
       ) -> tuple[np.ndarray, np.ndarray]:
    """Coordinated turn at each state's estimated rate w (extended Kalman filter), w a
    random walk: n x 5 states, n x 5 x 5 covariances, n process noises. The few turning
    models of a scan get their Jacobians in plain floats, then one batched product."""
    rows, Fs = [], []
    for px, py, vx, vy, w in x.tolist():
        w = min(max(w, -max_turn), max_turn)
        wt = w * dt
        sn, cs = math.sin(wt), math.cos(wt)
        if abs(wt) < 1e-4:   # the limit w -> 0, to second order
            s_w, c_w = dt - w * w * dt ** 3 / 6.0, w * dt * dt / 2.0
            ds, dc = -w * dt ** 3 / 3.0, dt * dt / 2.0
        else:
            s_w, c_w = sn / w, (1.0 - cs) / w
            ds, dc = (wt * cs - sn) / (w * w), (wt * sn - 1.0 + cs) / (w * w)
        nvx, nvy = cs * vx - sn * vy, sn * vx + cs * vy
        rows.append((px + s_w * vx - c_w * vy, py + c_w * vx + s_w * vy, nvx, nvy, w))
        Fs.append(((1.0, 0.0, s_w, -c_w, ds * vx - dc * vy), (0.0, 1.0, c_w, s_w, dc * vx + ds * vy),
                   (0.0, 0.0, cs, -sn, -dt * nvy), (0.0, 0.0, sn, cs, dt * nvx), (0.0, 0.0, 0.0, 0.0, 1.0)))
    F = np.array(Fs)
    Q = q[:, None, None] * q4(1.0, dt)
    Q[:, 4, 4] = q_turn * dt
    return np.array(rows), F @ P @ F.transpose(0, 2, 1) + Q


def arc(px: float, py: float, vx: float, vy: float, w: float, dt: float) -> tuple[float, float]:
    """Where a mover at (px, py) with velocity (vx, vy), turning at w rad/s, is dt later
    (no covariance: for looking ahead, in plain floats)."""
    wt = w * dt
    if abs(wt) < 1e-4:
        s_w, c_w = dt - w * w * dt ** 3 / 6.0, w * dt * dt / 2.0
    else:
        s_w, c_w = math.sin(wt) / w, (1.0 - math.cos(wt)) / w
    return px + s_w * vx - c_w * vy, py + c_w * vx + s_w * vy


def kf_update(xs: np.ndarray, Ps: np.ndarray, z: np.ndarray, R: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each track's models updated by its position measurement z (tracks x 2, noise R per
    track, isotropic): (states, covariances, each model's log-likelihood of z). The
    innovation covariance is 2 x 2: its inverse is written out."""
    r = R[:, None]
    a, b, d = Ps[:, :, 0, 0] + r, Ps[:, :, 0, 1], Ps[:, :, 1, 1] + r
    det = a * d - b * b
    nu = z[:, None, :] - xs[:, :, :2]                           # tracks x models x 2
    Si = np.stack([d, -b, -b, a], axis=-1).reshape(*det.shape, 2, 2) / det[..., None, None]
    K = Ps[..., :2] @ Si                                        # tracks x models x 5 x 2
    xs = xs + (K @ nu[..., None])[..., 0]
    P = Ps - K @ Ps[..., :2, :]
    P = (P + P.swapaxes(-1, -2)) / 2.0
    s = (Si @ nu[..., None])[..., 0]
    ll = -0.5 * (nu * s).sum(axis=-1) - 0.5 * np.log(det)
    return xs, P, ll
