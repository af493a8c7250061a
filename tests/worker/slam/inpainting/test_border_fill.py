"""The harmonic fill's compiled parts against the rules written plainly with numpy, OpenCV and scipy."""
import cv2
import numpy as np
import scipy.sparse as sp

from worker.slam.inpainting.border_fill import _block_means, _laplace_system, _reachable


def _random_known(rng, h, w):
    """Known pixels with unknown blobs (some touching the window's edge, some enclosed in unknowns)."""
    blobs = cv2.dilate((rng.random((h, w)) < 0.03).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    known = ~blobs
    known[rng.random((h, w)) < 0.05] = False
    return known


def _plain_system(val, known, solvable):
    """The system built per direction with numpy and scipy's COO -> CSC (the canonical form)."""
    h, w = known.shape
    ys, xs = np.nonzero(solvable)
    n = len(ys)
    idx = np.full((h, w), -1, np.int64)
    idx[ys, xs] = np.arange(n)
    diag, b, rows, cols = np.zeros(n), np.zeros((n, val.shape[2])), [], []
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        ny, nx = ys + dy, xs + dx
        inside = (ny >= 0) & (ny < h) & (nx >= 0) & (nx < w)
        nyc, nxc = np.clip(ny, 0, h - 1), np.clip(nx, 0, w - 1)
        unk, fixed = inside & (idx[nyc, nxc] >= 0), inside & known[nyc, nxc]
        diag += unk | fixed
        b += np.where(fixed[:, None], val[nyc, nxc], 0.0)
        rows.append(np.flatnonzero(unk))
        cols.append(idx[nyc, nxc][unk])
    r, c = np.concatenate(rows), np.concatenate(cols)
    A = sp.csc_matrix((np.r_[diag, -np.ones(len(r))], (np.r_[np.arange(n), r], np.r_[np.arange(n), c])), shape=(n, n))
    return A, b, ys, xs


def test_reachable_unknowns_are_the_components_that_touch_a_known_pixel():
    rng = np.random.default_rng(4)
    for _ in range(20):
        h, w = (int(v) for v in rng.integers(5, 70, 2))
        known = _random_known(rng, h, w)
        known[: h // 3, : w // 3] = False  # a large unknown corner, connected or not
        _, lab = cv2.connectedComponents((~known).astype(np.uint8), connectivity=4)
        cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
        touching = np.unique(lab[cv2.dilate(known.astype(np.uint8), cross) > 0])
        want = ~known & np.isin(lab, touching[touching > 0])
        assert np.array_equal(_reachable(known), want)
    assert not _reachable(np.zeros((4, 5), bool)).any()  # nothing known: nothing to continue from


def test_the_laplace_system_is_the_canonical_csc_matrix_and_right_hand_side():
    rng = np.random.default_rng(8)
    for _ in range(20):
        h, w = (int(v) for v in rng.integers(5, 60, 2))
        known = _random_known(rng, h, w)
        val = rng.normal(size=(h, w, 3))
        solvable = _reachable(known)
        indptr, indices, data, b, ys, xs = _laplace_system(val, known, solvable)
        A, b_want, ys_want, xs_want = _plain_system(val, known, solvable)
        A.sort_indices()
        assert np.array_equal(indptr, A.indptr) and np.array_equal(indices, A.indices)
        assert np.array_equal(data, A.data) and np.array_equal(b, b_want)
        assert np.array_equal(ys, ys_want) and np.array_equal(xs, xs_want)


def test_block_means_are_the_means_of_wholly_known_blocks_inside_the_window():
    rng = np.random.default_rng(9)
    for scale in (2, 4):
        h, w = 37, 50  # not multiples of the scale: the last blocks run past the window
        known = rng.random((h, w)) > 0.02
        values = rng.uniform(0, 255, (h, w, 3)).astype(np.float32)
        ch, cw = -(-h // scale), -(-w // scale)
        pad = ((0, ch * scale - h), (0, cw * scale - w))
        kb = np.pad(known, pad).reshape(ch, scale, cw, scale).all(axis=(1, 3))
        vb = np.pad(values.astype(np.float64), pad + ((0, 0),)).reshape(ch, scale, cw, scale, 3).mean(axis=(1, 3))
        known_c, val_c = _block_means(values, known, scale)
        assert np.array_equal(known_c, kb) and kb.sum() > 10
        assert np.allclose(val_c[kb], vb[kb], rtol=0, atol=1e-9) and not val_c[~kb].any()
