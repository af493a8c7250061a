"""Potentially dynamic masks split into segments at depth jumps, and a segment grown along its surface."""
import cv2
import numpy as np

from worker.slam.dynamic.segments import split_segments


def test_segments_split_at_depth_jumps():
    mask = np.zeros((100, 100), bool)
    mask[20:80, 10:90] = True
    depth = np.full((100, 100), 3.0, np.float32)
    depth[:, 50:] = 1.5  # two objects touching in the image, 1.5 m apart in depth
    labels = split_segments(mask, depth, min_area=50)
    assert labels.max() == 2 and np.all((labels > 0) == mask)
    assert len(np.unique(labels[20:80, 10:48])) == 1 and len(np.unique(labels[20:80, 52:90])) == 1


def _plain_split(mask, depth, min_area, rel_jump=0.05):
    """split_segments written plainly: components of the mask minus its depth edges, the small ones dropped,
    then three rounds in which the mask's unlabelled pixels take the largest label within 2 px."""
    from worker.slam.dynamic.segments import depth_edges
    inner = mask & ~depth_edges(depth, rel_jump)
    n, comp = cv2.connectedComponents(inner.astype(np.uint8), connectivity=4)
    area = np.bincount(comp.ravel(), minlength=n)
    keep = np.zeros(n, np.int32)
    big = np.flatnonzero(area[1:] >= min_area) + 1
    keep[big] = np.arange(1, len(big) + 1)
    out = keep[comp]
    h, w = mask.shape
    for _ in range(3):
        before = out.copy()
        for y, x in zip(*np.nonzero(mask & (before == 0))):
            out[y, x] = before[max(y - 2, 0):y + 3, max(x - 2, 0):x + 3].max()
    return out


def test_segments_are_the_plain_rules_on_ragged_masks_with_holes_and_jumps():
    """The compiled split (fused edge test, counting by runs, in-place refill) against the rules written
    plainly, on random blobs over depth with holes, steps and ramps."""
    rng = np.random.default_rng(7)
    for t in range(60):
        h, w = (int(v) for v in rng.integers(8, 90, 2))
        # blocks of one depth (steps between them), holes, and on odd rounds ramps near the 5 % threshold
        blocks = rng.choice([1.0, 1.5, 3.0], size=(h // 6 + 1, w // 6 + 1)).astype(np.float32)
        depth = cv2.resize(blocks, (w, h), interpolation=cv2.INTER_NEAREST)
        if t % 2:
            depth = cv2.blur(depth, (9, 9))
        depth[rng.random((h, w)) < 0.03] = 0.0
        seeds = (rng.random((h, w)) < 0.02).astype(np.uint8)
        mask = cv2.dilate(seeds, np.ones((9, 9), np.uint8)) > 0
        # a threshold equal to one component's area: a miscount by one pixel changes the labels
        from worker.slam.dynamic.segments import depth_edges
        inner = (mask & ~depth_edges(depth, 0.05)).astype(np.uint8)
        areas = np.bincount(cv2.connectedComponents(inner, connectivity=4)[1].ravel())[1:]
        min_area = int(rng.choice(areas[areas > 1])) if (areas > 1).any() else 2
        got = split_segments(mask, depth, min_area)
        assert got.dtype == np.int32 and np.array_equal(got, _plain_split(mask, depth, min_area)), t


def test_segments_on_every_second_pixel_are_the_coarse_split_spread_back_over_the_mask():
    """step 2: the plain rules on `mask[::2, ::2]` (min_area / 4), each mask pixel taking the label of its 2x2
    block's top-left sample; blobs anywhere in odd-sized images, so the working box meets the border."""
    rng = np.random.default_rng(11)
    for t in range(40):
        h, w = (int(v) for v in rng.integers(9, 91, 2))
        blocks = rng.choice([1.0, 1.5, 3.0], size=(h // 6 + 1, w // 6 + 1)).astype(np.float32)
        depth = cv2.resize(blocks, (w, h), interpolation=cv2.INTER_NEAREST)
        depth[rng.random((h, w)) < 0.03] = 0.0
        mask = cv2.dilate((rng.random((h, w)) < 0.02).astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
        coarse = _plain_split(mask[::2, ::2], depth[::2, ::2], 5)
        want = np.where(mask, np.repeat(np.repeat(coarse, 2, 0), 2, 1)[:h, :w], 0)
        got = split_segments(mask, depth, 18, step=2)  # ceil(18 / 4) = 5
        assert got.dtype == np.int32 and np.array_equal(got, want), t


def test_pixels_of_chosen_segments_are_numpys_lookup():
    from worker.slam.dynamic.segments import pixels_of
    labels = np.random.default_rng(1).integers(0, 7, (31, 45)).astype(np.int32)
    chosen = np.array([False, True, False, True, True, False, True])
    assert np.array_equal(pixels_of(labels, chosen), chosen[labels])


def test_renumbering_keeps_more_labels_than_uint16_holds():
    from worker.slam.dynamic.segments import _renumber
    labels = np.arange(70_000, dtype=np.int32).reshape(1, -1)  # one pixel each: every one kept at min_area 1
    out = _renumber(labels, 70_000, 1, np.float32(0))
    assert out.dtype == np.float32 and out[0, 0] == 0 and out[0, -1] == 69_999


def test_depth_edges_are_the_relative_jumps_between_4_neighbours_and_the_holes():
    from worker.slam.dynamic.segments import depth_edges

    rng = np.random.default_rng(3)
    depth = rng.uniform(0.5, 4.0, (60, 80)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.9] = 2.0  # mostly flat, so the jumps are sparse
    depth[rng.random(depth.shape) < 0.05] = 0.0  # holes
    depth[8:23, 8:14] = 2.0  # a flat patch around two bumps
    depth[10, 11] = 2.0 * 1.049  # a bump just under a 5 % jump to its four neighbours
    depth[20, 11] = 2.0 * 1.051  # and one just over
    expected = depth <= 0
    for axis in (0, 1):
        a, b = np.moveaxis(depth, axis, 0)[:-1], np.moveaxis(depth, axis, 0)[1:]
        jump = np.abs(b - a) > 0.05 * np.maximum(np.minimum(a, b), 1e-3)
        e = np.moveaxis(expected, axis, 0)
        e[:-1] |= jump
        e[1:] |= jump
    edges = depth_edges(depth, 0.05)
    assert np.array_equal(edges, expected)
    assert not edges[9:12, 10:13].any() and edges[20, 10:13].all() and edges[19:22, 11].all()


def test_growth_completes_an_object_along_its_surface_and_stops_at_depth_edges():
    from worker.slam.dynamic.segments import grow_by_depth
    depth = np.full((240, 320), 3.0, np.float32)
    depth[60:200, 100:160] = 1.5  # a person-sized object in front of a wall
    obj = depth < 2
    seen = np.zeros_like(obj)
    seen[60:120, 100:160] = True  # segmentation found only its upper half
    grown = grow_by_depth(seen, depth, grow_px=100)
    assert np.array_equal(grown, obj)  # the whole object, nothing of the wall behind it
    short = grow_by_depth(seen, depth, grow_px=10)
    assert short[:130].sum() == obj[:130].sum() and not short[135:].any()  # bounded by grow_px
    assert np.array_equal(grow_by_depth(seen, depth, grow_px=0), seen)
