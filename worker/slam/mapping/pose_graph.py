"""SE(3) pose-graph optimisation of keyframe poses (scipy sparse least squares).

Nodes are T_WC poses, parametrised as T_i = exp(x_i) T_i0 (left, world-frame perturbation); an edge (i, j, Z)
says T_i^-1 T_j should equal Z; its residual is (translation, rotation vector) of Z^-1 T_i^-1 T_j, with the
rotation part scaled by `rot_weight` (metres per radian).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from worker.slam.geometry.se3 import inv


def _exp_batch(x: np.ndarray) -> np.ndarray:
    """(N,6) -> (N,4,4), first-order translation (small steps)."""
    T = np.tile(np.eye(4), (len(x), 1, 1))
    T[:, :3, :3] = Rotation.from_rotvec(x[:, 3:]).as_matrix()
    T[:, :3, 3] = x[:, :3]
    return T


def optimize_pose_graph(poses: np.ndarray, edges: list[tuple[int, int, np.ndarray, float]], fixed: int = 0,
                        rot_weight: float = 1.0, max_nfev: int = 50,
                        trans_weights: np.ndarray | None = None) -> np.ndarray:
    """Optimised (N,4,4) T_WC from initial `poses` and edges (i, j, Z_ij 4x4, weight). Node `fixed` is held.
    `trans_weights` (E,), default 1, scales each edge's translation residual (0: the edge constrains rotation
    only)."""
    n = len(poses)
    ii = np.array([e[0] for e in edges])
    jj = np.array([e[1] for e in edges])
    Zinv = inv(np.stack([e[2] for e in edges]))
    w = np.sqrt(np.array([e[3] for e in edges]))[:, None]
    wt = np.ones((len(edges), 1)) if trans_weights is None else np.asarray(trans_weights, float)[:, None]
    free = np.array([k for k in range(n) if k != fixed])
    slot = np.full(n, -1)
    slot[free] = np.arange(len(free))

    def current(x: np.ndarray) -> np.ndarray:
        T = poses.copy()
        T[free] = _exp_batch(x.reshape(-1, 6)) @ poses[free]
        return T

    def residual(x: np.ndarray) -> np.ndarray:
        T = current(x)
        E = Zinv @ inv(T[ii]) @ T[jj]
        r = np.hstack([wt * E[:, :3, 3], rot_weight * Rotation.from_matrix(E[:, :3, :3]).as_rotvec()])
        return (w * r).ravel()

    rows, cols = [], []
    for e, (i, j) in enumerate(zip(ii, jj)):
        for node in (i, j):
            if slot[node] >= 0:
                rr, cc = np.meshgrid(np.arange(6 * e, 6 * e + 6), np.arange(6 * slot[node], 6 * slot[node] + 6))
                rows.append(rr.ravel())
                cols.append(cc.ravel())
    pattern = sp.csr_matrix((np.ones(sum(len(r) for r in rows)), (np.concatenate(rows), np.concatenate(cols))),
                            shape=(6 * len(edges), 6 * len(free)))
    pattern.data[:] = 1
    sol = least_squares(residual, np.zeros(6 * len(free)), jac_sparsity=pattern, method="trf",
                        tr_solver="lsmr", max_nfev=max_nfev, x_scale=1.0)
    return current(sol.x)
