import numpy as np
import pytest

from tests.worker.slam.inpainting.scene import H, K, W, person_hole, pose, psnr, render, texture
from worker.slam.inpainting.align import hole_ring
from worker.slam.inpainting.refine import PoseRefinementConfig, PoseRefiner
from worker.slam.inpainting.restore import ReferenceView, RestorationConfig, restore_frame
from worker.slam.inpainting.warp import project_into_reference, relative_pose

TRUE_REF = pose(0.06, 0.01, 1.0)
"""Where the reference camera really is; the target is at pose(0)."""
FULL = PoseRefinementConfig(enabled=True, scale=1.0)
"""The scene is 320 x 240: at full scale the alignment sees what the default half scale sees of 640 x 480."""


def _scene():
    tex = texture(3)
    rgb, depth = render(pose(0.0), tex)
    r_rgb, r_depth = render(TRUE_REF, tex)
    return rgb, depth, r_rgb, r_depth


def _hole_pixel_error(T_tr: np.ndarray, depth: np.ndarray, hole: np.ndarray) -> float:
    """Mean distance (px) between where the hole's wall points land in the reference through T_tr and where
    they really are: what a pose error costs the copied colours."""
    ys, xs = np.nonzero(hole)
    yx, z = np.stack([ys, xs], 1), depth[ys, xs].astype(np.float64)
    truth = project_into_reference(yx, z, np.linalg.inv(relative_pose(TRUE_REF, pose(0.0))), K)
    est = project_into_reference(yx, z, np.linalg.inv(T_tr), K)
    return float(np.mean(np.hypot(est[0] - truth[0], est[1] - truth[1])))


def _refiner(rgb, depth, hole, config=FULL):
    ys, xs = np.nonzero(hole)
    ring = hole_ring(rgb, depth, hole, (ys.min(), ys.max() + 1, xs.min(), xs.max() + 1), config.check_ring_px)
    return PoseRefiner(rgb, depth, ~hole, K, ring, config)


@pytest.mark.parametrize("error", [pose(0.01, 0.0, 0.0), pose(0.0, -0.008, 0.5), pose(0.0, 0.0, -0.8)])
def test_a_pose_a_few_pixels_off_is_pulled_back(error):
    rgb, depth, r_rgb, r_depth = _scene()
    hole = person_hole()
    given = relative_pose(TRUE_REF @ error, pose(0.0))
    refined, accepted = _refiner(rgb, depth, hole).refine(r_rgb, r_depth, np.ones((H, W), bool), given)
    before, after = _hole_pixel_error(given, depth, hole), _hole_pixel_error(refined, depth, hole)
    assert accepted and before > 1.5 and after < 0.35 * before


def test_an_exact_pose_is_left_alone():
    rgb, depth, r_rgb, r_depth = _scene()
    hole = person_hole()
    exact = relative_pose(TRUE_REF, pose(0.0))
    refined, accepted = _refiner(rgb, depth, hole).refine(r_rgb, r_depth, np.ones((H, W), bool), exact)
    assert not accepted and np.array_equal(refined, exact)


def test_a_target_with_too_little_static_view_keeps_the_pose():
    rgb, depth, r_rgb, r_depth = _scene()
    hole = person_hole(frac_w=0.5, frac_h=0.5)
    hole[:, 8:-8] = True  # all but two thin strips
    given = relative_pose(TRUE_REF @ pose(0.01), pose(0.0))
    refined, accepted = _refiner(rgb, depth, hole).refine(r_rgb, r_depth, np.ones((H, W), bool), given)
    assert not accepted and np.array_equal(refined, given)


def test_restoration_with_a_pose_error_recovers_with_refinement():
    """The reference's pose is 1 cm and 0.5 degrees off: refined first, the hole is restored nearly as with the
    true pose; as given, it is not."""
    rgb, depth, r_rgb, r_depth = _scene()
    hole = person_hole()
    ref = ReferenceView(r_rgb, r_depth, TRUE_REF @ pose(0.01, 0.0, 0.5), np.zeros((H, W), bool))
    on = restore_frame(rgb, depth, hole, pose(0.0), [ref], K, RestorationConfig(refine=FULL))
    off = restore_frame(rgb, depth, hole, pose(0.0), [ref], K,
                        RestorationConfig(refine=PoseRefinementConfig(enabled=False)))
    exact = restore_frame(rgb, depth, hole, pose(0.0), [ReferenceView(r_rgb, r_depth, TRUE_REF, ref.dynamic)], K,
                          RestorationConfig(refine=FULL))
    assert on.poses_refined == 1 and off.poses_refined == 0 and exact.poses_refined == 0
    assert psnr(on.rgb, rgb, hole) > psnr(off.rgb, rgb, hole) + 6
    assert psnr(on.rgb, rgb, hole) > psnr(exact.rgb, rgb, hole) - 4
