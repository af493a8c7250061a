"""Matching a frame pair: an object keypoint's brute-force match against its guided one."""
import numpy as np


def _flipped(desc: np.ndarray, bits: int) -> np.ndarray:
    """A copy of one ORB descriptor (32,) uint8 with its first `bits` bits flipped (Hamming distance `bits`)."""
    b = np.unpackbits(desc)
    b[:bits] ^= 1
    return np.packbits(b)


def test_an_ambiguous_object_match_gives_way_to_the_static_one_and_a_mover_keeps_its_own():
    from worker.slam.dynamic.epipolar import Matches
    from worker.slam.dynamic.matching import prefer_static

    cur = np.random.default_rng(0).integers(0, 256, (2, 32), np.uint8)
    prev = np.stack([_flipped(cur[0], 4),    # repeated texture far away: brute force's pick for current 0
                     _flipped(cur[0], 12),   # where the prediction puts current 0 if static: nearly as good
                     _flipped(cur[1], 3),    # current 1's own match after it moved
                     _flipped(cur[1], 40)])  # other texture where current 1 would be if static
    brute_prev, brute_cur = np.array([0, 2]), np.array([0, 1])
    near = Matches(np.array([1, 3]), np.array([0, 1]))  # guided matches, current indices into brute_cur
    p, c = prefer_static(brute_prev, brute_cur, near, prev, cur, within=20)
    assert dict(zip(c.tolist(), p.tolist())) == {0: 1, 1: 2}
    p, c = prefer_static(brute_prev, brute_cur, near, prev, cur, within=5)  # 12 - 4 > 5: no longer ambiguous
    assert dict(zip(c.tolist(), p.tolist())) == {0: 0, 1: 2}
    # two current keypoints whose guided matches are one previous keypoint: it stays with the first
    p, c = prefer_static(brute_prev, brute_cur, Matches(np.array([2, 2]), np.array([0, 1])), prev, cur, within=256)
    assert p.tolist() == [2] and c.tolist() == [0]
