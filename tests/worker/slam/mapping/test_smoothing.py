"""The frame smoother: per-frame noise along each frame's ill-determined direction is removed, what each frame
measures well is kept, and lost frames, jumps and outliers stay local."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from worker.slam.geometry.se3 import exp_se3, inv
from worker.slam.mapping.smoothing import SmootherSettings, smooth_poses, world_information

S = SmootherSettings(accel_sigma=0.5, angular_sigma=0.5)


def _path(n: int = 120, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A smooth hand-held-like path T_WC (n,4,4) at uneven 30/40 ms stamps (as TUM's motion capture gives)."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.choice([0.03, 0.04], n))
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, 3] = np.stack([0.3 * np.sin(t), 0.2 * np.cos(0.7 * t), 0.1 * t], 1)
    T[:, :3, :3] = Rotation.from_rotvec(np.stack([0.3 * np.sin(0.5 * t), 0.2 * t, 0.1 * np.cos(t)], 1)).as_matrix()
    return t, T


def _info(sigma_weak: float, sigma_strong: float, direction: np.ndarray) -> np.ndarray:
    """Information (position, rotation) weak along the unit 3-vector `direction` of position, strong elsewhere."""
    cov = np.eye(6) * sigma_strong**2
    cov[:3, :3] += (sigma_weak**2 - sigma_strong**2) * np.outer(direction, direction)
    return np.linalg.inv(cov)


def _pos_err(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.linalg.norm(a[:, :3, 3] - b[:, :3, 3], axis=1)


def test_noise_along_each_frames_weak_direction_is_removed_and_strong_directions_kept():
    t, T = _path()
    rng = np.random.default_rng(1)
    d = np.array([1.0, 0.0, 0.0])
    noisy = T.copy()
    noisy[:, :3, 3] += rng.normal(0, 0.006, (len(T), 1)) * d  # 6 mm along x, where each frame is weak
    info = [_info(0.006, 0.0005, d)] * len(T)
    out = smooth_poses(noisy, t, info, S)
    before, after = _pos_err(noisy, T), _pos_err(out, T)
    assert np.sqrt((after**2).mean()) < 0.4 * np.sqrt((before**2).mean())
    step = lambda P: np.linalg.norm(np.diff(P[:, :3, 3] - T[:, :3, 3], axis=0), axis=1)  # noqa: E731
    assert np.sqrt((step(out) ** 2).mean()) < 0.25 * np.sqrt((step(noisy) ** 2).mean())  # frame-to-frame error
    assert np.abs(out[:, 1:3, 3] - T[:, 1:3, 3]).max() < 0.001  # y and z were measured well: they stay


def test_rotation_noise_is_smoothed_too():
    t, T = _path(seed=2)
    rng = np.random.default_rng(3)
    noisy = T.copy()
    noisy[:, :3, :3] = (Rotation.from_rotvec(rng.normal(0, 0.003, (len(T), 3)))
                        * Rotation.from_matrix(T[:, :3, :3])).as_matrix()
    info = [np.diag([1 / 0.001**2] * 3 + [1 / 0.003**2] * 3)] * len(T)
    out = smooth_poses(noisy, t, info, S)
    ang = lambda P: (Rotation.from_matrix(P[:, :3, :3]) * Rotation.from_matrix(T[:, :3, :3]).inv()).magnitude()  # noqa: E731
    assert np.sqrt((ang(out) ** 2).mean()) < 0.6 * np.sqrt((ang(noisy) ** 2).mean())


def test_unmeasured_frames_keep_their_poses_and_break_the_prior():
    t, T = _path(60)
    noisy = T.copy()
    noisy[:, :3, 3] += np.random.default_rng(4).normal(0, 0.004, (60, 3))
    noisy[31:, :3, 3] += [0.2, 0.0, 0.0]  # a new map after a loss: a jump no motion prior should spread
    info: list[np.ndarray | None] = [np.eye(6) / 0.004**2] * 60
    info[30] = None
    out = smooth_poses(noisy, t, info, S)
    assert np.array_equal(out[30], noisy[30])
    shifted = T.copy()
    shifted[31:, :3, 3] += [0.2, 0.0, 0.0]
    assert _pos_err(out, shifted).max() < 0.01  # neither side is dragged towards the other


def test_a_mistracked_frame_does_not_drag_its_neighbours():
    t, T = _path(80, seed=5)
    noisy = T.copy()
    noisy[40, :3, 3] += [0.0, 0.08, 0.0]  # one frame 8 cm off, confident in its solve
    info = [np.eye(6) / 0.001**2] * 80
    out = smooth_poses(noisy, t, info, S)
    assert _pos_err(out, T)[[38, 39, 41, 42]].max() < 0.003


def test_world_information_matches_a_numeric_change_of_coordinates():
    T_WC = exp_se3(np.array([0.3, -0.1, 0.2, 0.4, -0.3, 0.2]))
    cov_cw = np.diag([1e-6, 2e-6, 4e-6, 1e-6, 3e-6, 2e-6])
    cov_cw[0, 4] = cov_cw[4, 0] = 1e-6
    delta = np.random.default_rng(6).multivariate_normal(np.zeros(6), cov_cw, 20_000)
    # sampled T_CW <- exp(d) T_CW, read back as (position, world rotation vector) of T_WC
    T_CW = inv(T_WC)
    xs = []
    for d in delta[:2000]:
        Tw = inv(exp_se3(d) @ T_CW)
        xs.append(np.concatenate([Tw[:3, 3] - T_WC[:3, 3],
                                  Rotation.from_matrix(Tw[:3, :3] @ T_WC[:3, :3].T).as_rotvec()]))
    emp = np.cov(np.array(xs).T)
    pred = np.linalg.inv(world_information(T_WC, np.linalg.inv(cov_cw)))
    assert np.allclose(emp, pred, atol=0.15 * np.abs(pred).max())
