"""Local bundle adjustment: Levenberg-Marquardt over local keyframe poses and their points (Schur complement).

The point blocks are 3x3 and independent given the poses, so they are eliminated (Schur complement) and
only the small dense 6C x 6C pose system is solved (the classic BA structure, numpy + scipy.sparse).
Chosen by measurement over scipy.optimize.least_squares: on a redkitchen map (8 local + 3 fixed keyframes,
5.5k points, 7.5k observations) 6 iterations took 0.37 s here against 9.9 s for least_squares with a sparse
2-point Jacobian and 6 evaluations (same machine, same load); gtsam was not needed.
Keyframes that see the points but are not local are included as fixed poses (they anchor the gauge).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit

from worker.slam.geometry import reprojection as rp
from worker.slam.geometry.pose_optimizer import CHI2_MONO, CHI2_STEREO
from worker.slam.geometry.se3 import exp_se3, inv, orthonormalize
from worker.slam.map.map import Map


@dataclass
class BAStats:
    keyframes: int
    fixed: int
    points: int
    observations: int
    cost_before: float
    cost_after: float
    outliers_removed: int


@dataclass(frozen=True)
class _Problem:
    """What one local BA optimises: the keyframes `cams` (ids; the first `n_var` variable, the rest fixed),
    the map points `point_set` (P,) int64 ids, and the N observations of them, camera by camera in keypoint order.
    Per observation: `c` (N,) index into `cams`, `p` (N,) index into `point_set`, `kpi` (N,) keypoint index in
    its keyframe, `obs` (N,3) measured (u, v, u_r) in pixels, `has` (N,) bool 'has depth', `roww` (N,3) row
    weights (u_r counts only with depth), `info` (N,) the octave's inverse variance."""
    cams: list[int]
    n_var: int
    point_set: np.ndarray
    c: np.ndarray
    p: np.ndarray
    kpi: np.ndarray
    obs: np.ndarray
    has: np.ndarray
    roww: np.ndarray
    info: np.ndarray
    ur_u: float = 1.0
    """The depth row's u coefficient (`reprojection`): 0 (disparity alone) when depths carry their own weights."""


@dataclass(frozen=True)
class _Estimate:
    """Camera poses `T_CW` (C,4,4) (world -> camera, in `cams` order), points `X` (P,3) in the world frame, and
    per observation: the point in its camera's frame `Pc` (N,3), the weighted residual `e` (N,3) in pixels,
    `chi2` (N,) (1e6 behind the camera), `front` (N,) bool in front of the camera; `cost` the robust total."""
    T_CW: np.ndarray
    X: np.ndarray
    Pc: np.ndarray
    e: np.ndarray
    chi2: np.ndarray
    front: np.ndarray
    cost: float


@dataclass(frozen=True)
class _NormalBlocks:
    """The Gauss-Newton normal equations in blocks (see `_normal_blocks`): `Hcc` (n_var,6,6), `bc` (n_var,6),
    `Hpp` (P,3,3), `bp` (P,3), `Hcp` (nv,6,3) per observation of a variable camera, whose camera and point
    indices are `cv` and `pv` (nv,)."""
    Hcc: np.ndarray
    bc: np.ndarray
    Hpp: np.ndarray
    bp: np.ndarray
    Hcp: np.ndarray
    cv: np.ndarray
    pv: np.ndarray


def local_bundle_adjust(slam_map: Map, local: list[int], K: np.ndarray, bf: float, inv_sigma2: np.ndarray,
                        iterations: int = 6, huber_px: float = 2.45, max_fixed: int = 20) -> BAStats | None:
    """Optimise the poses of keyframes `local` and all points they see, in place in `slam_map`."""
    point_set = np.unique(np.concatenate([slam_map.alive_ids(slam_map.keyframes[i]) for i in local]))
    if len(point_set) < 10:
        return None
    local, fixed = _variable_and_fixed(slam_map, local, max_fixed)
    prob = _build_problem(slam_map, local, fixed, point_set, bf, inv_sigma2)
    T_CW = inv(np.stack([slam_map.keyframes[k].T_WC for k in prob.cams]))
    first = _evaluate(prob, T_CW, slam_map.points.pos[point_set].copy(), K, bf, huber_px)
    est = _levenberg_marquardt(prob, first, K, bf, iterations, huber_px)
    removed = _write_back(slam_map, prob, est)
    return BAStats(prob.n_var, len(fixed), len(est.X), len(prob.c), first.cost, est.cost, removed)


def _variable_and_fixed(slam_map: Map, local: list[int], max_fixed: int) -> tuple[list[int], list[int]]:
    """The variable keyframes and the fixed ones: the `max_fixed` non-local keyframes most covisible with
    `local`, or, when there are none, the oldest local keyframe (taken out of the variable ones)."""
    fixed_w: dict[int, int] = {}
    for i in local:
        for j, w in slam_map.covis[i].items():
            if j not in local:
                fixed_w[j] = fixed_w.get(j, 0) + w
    fixed = [j for j, _ in sorted(fixed_w.items(), key=lambda x: -x[1])[:max_fixed]]
    if not fixed and len(local) > 1:
        # the oldest holds the gauge: keyframe 0, or a new map's first keyframe (it shares no points)
        anchor = min(local)
        local = [i for i in local if i != anchor]
        fixed = [anchor]
    return local, fixed


def _build_problem(slam_map: Map, local: list[int], fixed: list[int], point_set: np.ndarray, bf: float,
                   inv_sigma2: np.ndarray) -> _Problem:
    """Every observation by keyframes `local` + `fixed` of the points `point_set`, with its measurement."""
    kfs = slam_map.keyframes
    lookup = np.full(len(slam_map.points), -1, np.int64)
    lookup[point_set] = np.arange(len(point_set))
    cams = list(local) + fixed
    c_idx, p_idx, kp_idx = [], [], []
    for ci, k in enumerate(cams):
        pid = kfs[k].point_ids
        has = pid >= 0
        loc = np.where(has, lookup[np.where(has, pid, 0)], -1)
        sel = np.flatnonzero(loc >= 0)
        c_idx.append(np.full(len(sel), ci))
        p_idx.append(loc[sel])
        kp_idx.append(sel)
    c = np.concatenate(c_idx)
    p = np.concatenate(p_idx)
    kpi = np.concatenate(kp_idx)
    uv = np.concatenate([kfs[cams[ci]].feats.uv[kp_idx[ci]] for ci in range(len(cams))])
    z = np.concatenate([kfs[cams[ci]].feats.depth[kp_idx[ci]] for ci in range(len(cams))])
    octv = np.concatenate([kfs[cams[ci]].feats.octave[kp_idx[ci]] for ci in range(len(cams))])
    info = inv_sigma2[octv]
    dws = [kfs[k].feats.depth_w for k in cams]
    dw = None if all(d is None for d in dws) else np.concatenate(
        [np.ones(len(kp), np.float32) if d is None else d[kp] for d, kp in zip(dws, kp_idx)])
    ur_u = 1.0 if dw is None else 0.0
    obs, has = rp.observations(uv, z, bf, ur_u)
    roww = rp.residual_weights(has, dw)
    return _Problem(cams, len(local), point_set, c, p, kpi, obs, has, roww, info, ur_u)


def _evaluate(prob: _Problem, T_CW: np.ndarray, X: np.ndarray, K: np.ndarray, bf: float,
              huber_px: float) -> _Estimate:
    """The residuals and robust (Huber) cost of poses `T_CW` (C,4,4) and points `X` (P,3)."""
    c, p = prob.c, prob.p
    Pc = np.einsum("nij,nj->ni", T_CW[c, :3, :3], X[p]) + T_CW[c, :3, 3]
    front = Pc[:, 2] > 1e-3
    e = (prob.obs - rp.project(np.where(front[:, None], Pc, 1.0), K, bf, prob.ur_u)) * prob.roww
    chi2 = np.where(front, prob.info * (e**2).sum(1), 1e6)
    s = np.sqrt(chi2)
    cost = float(np.where(s <= huber_px, chi2, 2 * huber_px * s - huber_px**2).sum())
    return _Estimate(T_CW, X, Pc, e, chi2, front, cost)


def _levenberg_marquardt(prob: _Problem, est: _Estimate, K: np.ndarray, bf: float, iterations: int,
                         huber_px: float) -> _Estimate:
    """Up to `iterations` LM iterations from `est`; stops early when an iteration finds no lower cost."""
    lam = 1e-3
    for _ in range(iterations):
        better, lam = _lm_iteration(prob, est, lam, K, bf, huber_px)
        if better is None:
            break
        est = better
    return est


def _lm_iteration(prob: _Problem, est: _Estimate, lam: float, K: np.ndarray, bf: float,
                  huber_px: float) -> tuple[_Estimate | None, float]:
    """Linearise at `est`, then up to 4 damped steps (damping x10 after each failure): the first estimate of
    lower cost and the damping for the next iteration, or None when all 4 failed."""
    blocks = _linearise(prob, est, K, bf, huber_px)
    for _try in range(4):
        step = _solve_damped(prob, blocks, lam)
        if step is None:
            lam *= 10
            continue
        dxc, dxp = step
        T_new = est.T_CW.copy()
        for i in range(prob.n_var):
            T_new[i] = exp_se3(dxc[i]) @ est.T_CW[i]
        cand = _evaluate(prob, T_new, est.X + dxp, K, bf, huber_px)
        if cand.cost < est.cost:
            return cand, max(lam / 10, 1e-7)
        lam *= 10
    return None, lam


def _linearise(prob: _Problem, est: _Estimate, K: np.ndarray, bf: float, huber_px: float) -> _NormalBlocks:
    """The normal equations' blocks at `est`, with IRLS Huber weights."""
    c, p, front = prob.c, prob.p, est.front
    w = prob.info * rp.huber_weights(est.chi2, huber_px) * front
    Jp = rp.jacobian_point(np.where(front[:, None], est.Pc, 1.0), K, bf, prob.ur_u) * prob.roww[:, :, None]
    JX = Jp @ est.T_CW[c, :3, :3]
    var = c < prob.n_var
    cv, pv = c[var], p[var]
    Hcc, bc, Hpp, bp, Hcp = _normal_blocks(est.Pc, Jp, JX, w, est.e, c, p, prob.n_var, len(est.X))
    return _NormalBlocks(Hcc, bc, Hpp, bp, Hcp, cv, pv)


def _solve_damped(prob: _Problem, b: _NormalBlocks, lam: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The LM step at damping `lam`: pose updates (n_var,6) (twists, left-multiplied onto T_CW) and point
    updates (P,3), by eliminating the points (Schur complement); None when the reduced system is singular."""
    n_var, P, cv, pv = prob.n_var, len(b.Hpp), b.cv, b.pv
    Hcc_d = b.Hcc + lam * np.einsum("nii->ni", b.Hcc)[:, :, None] * np.eye(6) + 1e-9 * np.eye(6)
    Hpp_d = b.Hpp + lam * np.einsum("nii->ni", b.Hpp)[:, :, None] * np.eye(3) + 1e-9 * np.eye(3)
    Hpp_inv = np.linalg.inv(Hpp_d)
    rows = (6 * cv[:, None, None] + np.arange(6)[None, :, None]) * np.ones((1, 1, 3), int)
    cols = (3 * pv[:, None, None] + np.arange(3)[None, None, :]) * np.ones((1, 6, 1), int)
    W = sp.csr_matrix((b.Hcp.ravel(), (rows.ravel(), cols.ravel())), shape=(6 * n_var, 3 * P))
    br = np.repeat(np.arange(P), 9) * 3 + np.tile(np.repeat(np.arange(3), 3), P)
    bcl = np.repeat(np.arange(P), 9) * 3 + np.tile(np.tile(np.arange(3), 3), P)
    Vinv = sp.csr_matrix((Hpp_inv.ravel(), (br, bcl)), shape=(3 * P, 3 * P))
    Y = W @ Vinv
    S = _block_diag(Hcc_d) - (Y @ W.T).toarray()
    rhs = b.bc.ravel() - Y @ b.bp.ravel()
    try:
        dxc = np.linalg.solve(S, rhs).reshape(n_var, 6)
    except np.linalg.LinAlgError:
        return None
    dxp = np.einsum("pij,pj->pi", Hpp_inv, b.bp - (W.T @ dxc.ravel()).reshape(P, 3))
    return dxc, dxp


def _write_back(slam_map: Map, prob: _Problem, est: _Estimate) -> int:
    """Store the variable poses and the points in `slam_map`; returns how many outlier observations it erased."""
    kfs, pts = slam_map.keyframes, slam_map.points
    for i, k in enumerate(prob.cams[:prob.n_var]):
        kfs[k].T_WC = orthonormalize(inv(est.T_CW[i]))
    pts.pos[prob.point_set] = est.X
    # drop observations that stayed outliers (ORB-SLAM2 erases them from keyframe and point)
    bad = est.chi2 > np.where(prob.has, CHI2_STEREO, CHI2_MONO)
    for ci in np.unique(prob.c[bad]):
        sel = bad & (prob.c == ci)
        kfs[prob.cams[ci]].point_ids[prob.kpi[sel]] = -1
    np.subtract.at(pts.n_obs, prob.point_set[prob.p[bad]], 1)
    return int(bad.sum())


def _block_diag(blocks: np.ndarray) -> np.ndarray:
    n = len(blocks)
    out = np.zeros((6 * n, 6 * n))
    for i in range(n):
        out[6 * i:6 * i + 6, 6 * i:6 * i + 6] = blocks[i]
    return out


@njit(cache=True, nogil=True)
def _normal_blocks(Pc, Jp, JX, w, e, c, p, n_var, P):
    """The normal equations' blocks from the observations (N,) of camera `c` and point `p`: camera-camera
    `Hcc` (n_var,6,6) and `bc` (n_var,6), point-point `Hpp` (P,3,3) and `bp` (P,3), and per observation of a
    variable camera (in order) `Hcp` (nv,6,3), from the point Jacobians `Jp` (N,3,3) (d residual / d Pc),
    `JX` (N,3,3) (d residual / d X, = Jp R) and the pose Jacobian [I, -hat(Pc)] formed here, weights `w` and
    residuals `e` (N,3). One compiled pass with the operations and the order of the numpy expressions it
    replaces (`jacobian_pose`, `einsum("nik,n,nil->nkl")` and `np.add.at` in observation order): the same bits,
    ~7x faster (a local BA step on 5000 observations: 6.1 -> 0.8 ms)."""
    n = Pc.shape[0]
    Hcc, bc = np.zeros((n_var, 6, 6)), np.zeros((n_var, 6))
    Hpp, bp = np.zeros((P, 3, 3)), np.zeros((P, 3))
    nv = 0
    for i in range(n):
        nv += c[i] < n_var
    Hcp = np.zeros((nv, 6, 3))
    jc = np.zeros((3, 6))
    v = 0
    for i in range(n):
        wi, pi = w[i], p[i]
        for k in range(3):
            for m in range(3):
                acc = 0.0
                for r in range(3):
                    acc += JX[i, r, k] * wi * JX[i, r, m]
                Hpp[pi, k, m] += acc
            acc = 0.0
            for r in range(3):
                acc += JX[i, r, k] * wi * e[i, r]
            bp[pi, k] += acc
        ci = c[i]
        if ci >= n_var:
            continue
        rp.pose_jacobian_rows(Pc[i, 0], Pc[i, 1], Pc[i, 2], Jp[i], jc)
        for k in range(6):
            for m in range(6):
                acc = 0.0
                for r in range(3):
                    acc += jc[r, k] * wi * jc[r, m]
                Hcc[ci, k, m] += acc
            acc = 0.0
            for r in range(3):
                acc += jc[r, k] * wi * e[i, r]
            bc[ci, k] += acc
            for m in range(3):
                acc = 0.0
                for r in range(3):
                    acc += jc[r, k] * wi * JX[i, r, m]
                Hcp[v, k, m] = acc
        v += 1
    return Hcc, bc, Hpp, bp, Hcp
