"""SE(3) helpers. Tangent vectors are (rho, phi): translation part first, then rotation (radians)."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def hat(w: np.ndarray) -> np.ndarray:
    """(..., 3) -> (..., 3, 3) skew-symmetric matrices."""
    z = np.zeros(w.shape[:-1])
    return np.stack([np.stack([z, -w[..., 2], w[..., 1]], -1),
                     np.stack([w[..., 2], z, -w[..., 0]], -1),
                     np.stack([-w[..., 1], w[..., 0], z], -1)], -2)


def exp_se3(xi: np.ndarray) -> np.ndarray:
    """(6,) twist (rho, phi) -> 4x4 transform."""
    rho, phi = xi[:3], xi[3:]
    theta = np.linalg.norm(phi)
    # `hat` of one vector, written out: the same matrix without `hat`'s batched stacking (motion-only BA
    # calls this once per Gauss-Newton step, and the stacking was most of its cost)
    W = np.array([[0.0, -phi[2], phi[1]], [phi[2], 0.0, -phi[0]], [-phi[1], phi[0], 0.0]])
    if theta < 1e-8:
        R = np.eye(3) + W
        V = np.eye(3) + 0.5 * W
    else:
        a = np.sin(theta) / theta
        b = (1 - np.cos(theta)) / theta**2
        c = (1 - a) / theta**2
        R = np.eye(3) + a * W + b * W @ W
        V = np.eye(3) + b * W + c * W @ W
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = V @ rho
    return T


def log_se3(T: np.ndarray) -> np.ndarray:
    """4x4 transform -> (6,) twist (rho, phi)."""
    phi = Rotation.from_matrix(T[:3, :3]).as_rotvec()
    theta = np.linalg.norm(phi)
    W = hat(phi)
    if theta < 1e-8:
        Vinv = np.eye(3) - 0.5 * W
    else:
        half = theta / 2
        Vinv = np.eye(3) - 0.5 * W + (1 - half / np.tan(half)) / theta**2 * W @ W
    return np.concatenate([Vinv @ T[:3, 3], phi])


def inv(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform (or a stack (..., 4, 4))."""
    Ti = np.zeros_like(T)
    R = np.swapaxes(T[..., :3, :3], -1, -2)
    Ti[..., :3, :3] = R
    Ti[..., :3, 3] = -(R @ T[..., :3, 3, None])[..., 0]
    Ti[..., 3, 3] = 1.0
    return Ti


def transform(T: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Apply 4x4 `T` to (N,3) points."""
    return X @ T[:3, :3].T + T[:3, 3]


def pose_distance(T_a: np.ndarray, T_b: np.ndarray) -> tuple[float, float]:
    """(translation metres, rotation radians) between two poses."""
    D = inv(T_a) @ T_b
    return float(np.linalg.norm(D[:3, 3])), float(np.linalg.norm(Rotation.from_matrix(D[:3, :3]).as_rotvec()))


def orthonormalize(T: np.ndarray) -> np.ndarray:
    """Project the rotation block(s) of (...,4,4) transforms back onto SO(3) (products drift numerically)."""
    U, _, Vt = np.linalg.svd(T[..., :3, :3])
    R = U @ Vt
    d = np.linalg.det(R)
    U[..., :, 2] *= np.sign(d)[..., None]
    out = T.copy()
    out[..., :3, :3] = U @ Vt
    return out
