import numpy as np
import pytest

from tests.worker.slam.inpainting.scene import H, K, W, person_hole, pose, psnr, render, texture
from worker.slam.inpainting.align import hole_ring, ring_shift
from worker.slam.inpainting.refine import PoseRefinementConfig
from worker.slam.inpainting.restore import ReferenceView, RestorationConfig, restore_frame
from worker.slam.inpainting.warp import relative_pose


def _misregistered(dy: int, dx: int):
    """Target and a moved reference of the textured wall; the reference's colours are moved by (dy, dx) pixels
    against its depth and pose, as a few pixels of pose error or colour/depth misregistration do."""
    tex = texture(7)
    rgb, depth = render(pose(0.0), tex)
    r_rgb, r_depth = render(pose(0.06, 0.01, 1.0), tex)
    moved = np.roll(r_rgb, (dy, dx), axis=(0, 1))
    return rgb, depth, ReferenceView(moved, r_depth, pose(0.06, 0.01, 1.0), np.zeros((H, W), bool))


@pytest.mark.parametrize("dy,dx", [(0, 3), (-2, 4), (5, -1), (0, 0)])
def test_ring_shift_finds_how_far_the_reference_colours_are_off(dy, dx):
    rgb, depth, ref = _misregistered(dy, dx)
    hole = person_hole()
    ys, xs = np.nonzero(hole)
    ring = hole_ring(rgb, depth, hole, (ys.min(), ys.max() + 1, xs.min(), xs.max() + 1), 15)
    assert not hole[ring.ys, ring.xs].any() and len(ring.ys) > 200
    grey = ref.rgb.mean(-1).astype(np.float32)
    T_rt = np.linalg.inv(relative_pose(ref.T_WC, pose(0.0)))
    assert ring_shift(ring, grey, ~ref.dynamic, T_rt, K, 6) == (dy, dx)


def test_aligned_references_restore_misregistered_colours():
    """Off by (2, -3) pixels: aligned, the hole is restored as if the reference were exact; without alignment (the
    default) it is not. Exact references are left exactly as they were. (Pose refinement off: a shift of the
    colours alone is no pose error, and this is about the shift.)"""
    hole = person_hole()
    rgb, depth, ref = _misregistered(2, -3)
    unrefined = PoseRefinementConfig(enabled=False)
    on = restore_frame(rgb, depth, hole, pose(0.0), [ref], K, RestorationConfig(align_px=6, refine=unrefined))
    off = restore_frame(rgb, depth, hole, pose(0.0), [ref], K, RestorationConfig(refine=unrefined))
    assert psnr(on.rgb, rgb, hole) >= 30 and psnr(off.rgb, rgb, hole) < psnr(on.rgb, rgb, hole) - 8
    rgb, depth, exact = _misregistered(0, 0)
    on = restore_frame(rgb, depth, hole, pose(0.0), [exact], K, RestorationConfig(align_px=6))
    off = restore_frame(rgb, depth, hole, pose(0.0), [exact], K)
    assert np.array_equal(on.rgb, off.rgb) and np.array_equal(on.depth, off.depth)


def test_a_ring_the_reference_cannot_see_gives_no_shift():
    rgb, depth, ref = _misregistered(0, 3)
    hole = person_hole()
    ys, xs = np.nonzero(hole)
    ring = hole_ring(rgb, depth, hole, (ys.min(), ys.max() + 1, xs.min(), xs.max() + 1), 15)
    grey = ref.rgb.mean(-1).astype(np.float32)
    T_rt = np.linalg.inv(relative_pose(ref.T_WC, pose(0.0)))
    assert ring_shift(ring, grey, np.zeros((H, W), bool), T_rt, K, 6) == (0, 0)  # every pixel is moving
