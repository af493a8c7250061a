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


def local_bundle_adjust(slam_map: Map, local: list[int], K: np.ndarray, bf: float, inv_sigma2: np.ndarray,
                        iterations: int = 6, huber_px: float = 2.45, max_fixed: int = 20) -> BAStats | None:
    """Optimise the poses of keyframes `local` and all points they see, in place in `slam_map`."""
    kfs = slam_map.keyframes
    pts = slam_map.points
    point_set = np.unique(np.concatenate([slam_map.alive_ids(kfs[i]) for i in local]))
    if len(point_set) < 10:
        return None
    lookup = np.full(len(pts), -1, np.int64)
    lookup[point_set] = np.arange(len(point_set))
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
    cams = list(local) + fixed
    n_var = len(local)
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
    obs, has = rp.observations(uv, z, bf)
    roww = rp.residual_weights(has)
    T_CW = inv(np.stack([kfs[k].T_WC for k in cams]))
    X = pts.pos[point_set].copy()
    P = len(X)

    def residuals(T_CW: np.ndarray, X: np.ndarray):
        Pc = np.einsum("nij,nj->ni", T_CW[c, :3, :3], X[p]) + T_CW[c, :3, 3]
        front = Pc[:, 2] > 1e-3
        e = (obs - rp.project(np.where(front[:, None], Pc, 1.0), K, bf)) * roww
        chi2 = np.where(front, info * (e**2).sum(1), 1e6)
        return Pc, e, chi2, front

    def robust_cost(chi2: np.ndarray) -> float:
        s = np.sqrt(chi2)
        return float(np.where(s <= huber_px, chi2, 2 * huber_px * s - huber_px**2).sum())

    Pc, e, chi2, front = residuals(T_CW, X)
    cost0 = cost = robust_cost(chi2)
    lam = 1e-3
    for _ in range(iterations):
        w = info * rp.huber_weights(chi2, huber_px) * front
        Jp = rp.jacobian_point(np.where(front[:, None], Pc, 1.0), K, bf) * roww[:, :, None]
        JX = Jp @ T_CW[c, :3, :3]
        var = c < n_var
        cv, pv = c[var], p[var]
        Hcc, bc, Hpp, bp, Hcp = _normal_blocks(Pc, Jp, JX, w, e, c, p, n_var, P)  # Hcp: (nv, 6, 3)
        for _try in range(4):
            Hcc_d = Hcc + lam * np.einsum("nii->ni", Hcc)[:, :, None] * np.eye(6) + 1e-9 * np.eye(6)
            Hpp_d = Hpp + lam * np.einsum("nii->ni", Hpp)[:, :, None] * np.eye(3) + 1e-9 * np.eye(3)
            Hpp_inv = np.linalg.inv(Hpp_d)
            rows = (6 * cv[:, None, None] + np.arange(6)[None, :, None]) * np.ones((1, 1, 3), int)
            cols = (3 * pv[:, None, None] + np.arange(3)[None, None, :]) * np.ones((1, 6, 1), int)
            W = sp.csr_matrix((Hcp.ravel(), (rows.ravel(), cols.ravel())), shape=(6 * n_var, 3 * P))
            br = np.repeat(np.arange(P), 9) * 3 + np.tile(np.repeat(np.arange(3), 3), P)
            bcl = np.repeat(np.arange(P), 9) * 3 + np.tile(np.tile(np.arange(3), 3), P)
            Vinv = sp.csr_matrix((Hpp_inv.ravel(), (br, bcl)), shape=(3 * P, 3 * P))
            Y = W @ Vinv
            S = _block_diag(Hcc_d) - (Y @ W.T).toarray()
            rhs = bc.ravel() - Y @ bp.ravel()
            try:
                dxc = np.linalg.solve(S, rhs).reshape(n_var, 6)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            dxp = np.einsum("pij,pj->pi", Hpp_inv, bp - (W.T @ dxc.ravel()).reshape(P, 3))
            T_new = T_CW.copy()
            for i in range(n_var):
                T_new[i] = exp_se3(dxc[i]) @ T_CW[i]
            X_new = X + dxp
            Pc_n, e_n, chi2_n, front_n = residuals(T_new, X_new)
            cost_n = robust_cost(chi2_n)
            if cost_n < cost:
                T_CW, X, Pc, e, chi2, front, cost = T_new, X_new, Pc_n, e_n, chi2_n, front_n, cost_n
                lam = max(lam / 10, 1e-7)
                break
            lam *= 10
        else:
            break
    for i, k in enumerate(cams[:n_var]):
        kfs[k].T_WC = orthonormalize(inv(T_CW[i]))
    pts.pos[point_set] = X
    # drop observations that stayed outliers (ORB-SLAM2 erases them from keyframe and point)
    bad = chi2 > np.where(has, CHI2_STEREO, CHI2_MONO)
    for ci in np.unique(c[bad]):
        sel = bad & (c == ci)
        kfs[cams[ci]].point_ids[kpi[sel]] = -1
    np.subtract.at(pts.n_obs, point_set[p[bad]], 1)
    return BAStats(n_var, len(fixed), P, len(c), cost0, cost, int(bad.sum()))


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
