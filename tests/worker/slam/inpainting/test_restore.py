from dataclasses import replace

import cv2
import numpy as np
import pytest

from tests.worker.slam.inpainting.scene import H, K, W, person_hole, pose, psnr, render, texture
from worker.slam.inpainting.patchmatch import patchmatch_fill
from worker.slam.inpainting.references import Candidate, ReferenceSelectionConfig, select_references
from worker.slam.inpainting.restore import ReferenceView, RestorationConfig, restore_frame
from worker.slam.inpainting.stage import RestorationStageConfig
from worker.slam.inpainting.warp import depth_in_target, forward_warp, relative_pose


def test_forward_warp_is_exact_for_pure_translation():
    tex = texture()
    T_ref, T_tgt = pose(0.1), pose(0.0)
    _, d_ref = render(T_ref, tex)
    out = forward_warp(d_ref, np.ones((H, W), bool), relative_pose(T_ref, T_tgt), K, (0, H, 0, W))
    # the wall is at 2 m and the camera moved 0.1 m: a shift of fx * 0.1 / 2 = 15 px
    assert out[100, 100].tolist() == [100, 85]
    z = depth_in_target(d_ref, out[100:101, 100], relative_pose(T_ref, T_tgt), K)
    assert z[0] == pytest.approx(2.0, abs=1e-4)


def test_patchmatch_recovers_shifted_texture_from_random_init():
    tex = texture(1)
    tgt, ref = tex[10:250, 15:335].copy(), tex[20:260, 5:325].copy()
    hole = person_hole()
    res = patchmatch_fill(tgt, hole, ref[None], np.ones((1, H, W), bool))
    assert psnr(res.rgb, tgt, hole) > 30
    assert np.array_equal(res.rgb[~hole], tgt[~hole])  # known pixels untouched


def test_restore_rgb_and_depth_from_moved_references():
    tex = texture(2)
    T_tgt = pose(0.0)
    rgb, depth = render(T_tgt, tex)
    refs = []
    for tx, yaw in ((-0.15, 2.0), (0.12, -1.5)):
        r_rgb, r_depth = render(pose(tx, 0.02, yaw), tex)
        refs.append(ReferenceView(r_rgb, r_depth, pose(tx, 0.02, yaw), np.zeros((H, W), bool)))
    hole = person_hole()
    garbage = rgb.copy()
    garbage[hole] = 0
    out = restore_frame(garbage, np.where(hole, 0, depth), hole, T_tgt, refs, K)
    assert psnr(out.rgb, rgb, hole) >= 30
    ok = hole & (out.depth > 0)
    assert ok.sum() / hole.sum() > 0.9
    assert np.median(np.abs(out.depth[ok] - depth[ok])) < 0.01
    assert out.from_geometry > 0.9
    assert np.all(out.depth_confidence[~hole] == 0)


def test_subpixel_sampling_beats_the_nearest_splatted_pixel():
    tex = texture(2)
    T_tgt = pose(0.0)
    rgb, depth = render(T_tgt, tex)
    T_ref = pose(0.0123, 0.0071, 0.37)  # a motion that lands reference pixels between target pixels
    r_rgb, r_depth = render(T_ref, tex)
    ref = ReferenceView(r_rgb, r_depth, T_ref, np.zeros((H, W), bool))
    hole = person_hole()
    near = restore_frame(rgb, depth, hole, T_tgt, [ref], K, RestorationConfig(subpixel=False))
    sub = restore_frame(rgb, depth, hole, T_tgt, [ref], K)
    assert psnr(sub.rgb, rgb, hole) > psnr(near.rgb, rgb, hole) + 1.0


def test_reference_dynamic_pixels_are_never_copied():
    tex = texture(3)
    T_tgt = pose(0.0)
    rgb, depth = render(T_tgt, tex)
    r_rgb, r_depth = render(pose(0.05), tex)
    dyn = person_hole()
    r_rgb = r_rgb.copy()
    r_rgb[dyn] = (255, 0, 255)  # the reference's own "person" in magenta
    hole = person_hole()
    out = restore_frame(rgb, depth, hole, T_tgt, [ReferenceView(r_rgb, r_depth, pose(0.05), dyn)], K)
    magenta = np.all(out.rgb[hole] == (255, 0, 255), axis=1)
    assert magenta.mean() < 0.01


def test_no_references_falls_back_to_target_itself():
    tex = texture(4)
    rgb, depth = render(pose(0.0), tex)
    hole = person_hole(frac_w=0.05, frac_h=0.1)
    out = restore_frame(rgb, depth, hole, pose(0.0), [], K)
    assert out.from_self == 1.0 and out.from_geometry == 0.0
    none = restore_frame(rgb, depth, hole, pose(0.0), [], K, RestorationConfig(unseen_depth="none"))
    assert np.all(none.depth[hole] == 0) and np.all(none.depth_confidence[hole] == 0)


def test_depth_no_reference_sees_continues_the_surfaces_around_the_hole():
    """A tilted plane (depth varies across the hole) is continued into it; the guess is marked as such."""
    tex = texture(4)
    T = pose(0.0, 0.0, 25.0)  # the wall seen at 25 degrees: depth changes by decimetres across the hole
    rgb, depth = render(T, tex)
    hole = person_hole()
    person = np.where(hole, np.float32(1.0), depth)  # the occluder's own depth inside the hole
    out = restore_frame(rgb, person, hole, T, [], K)
    assert np.ptp(depth[hole]) > 0.2
    assert np.all(out.depth[hole] > 0)
    assert np.median(np.abs(out.depth[hole] - depth[hole])) < 0.01
    assert np.percentile(np.abs(out.depth[hole] - depth[hole]), 95) < 0.03
    cfg = RestorationConfig()
    assert np.allclose(out.depth_confidence[hole], cfg.border_depth_confidence)
    assert cfg.border_depth_confidence < RestorationStageConfig().min_depth_confidence  # no restored features
    assert np.array_equal(out.depth[~hole], person[~hole])


@pytest.mark.parametrize("smooth", ["harmonic", "telea"])
def test_unseen_pixels_by_diffusion_keep_geometry_and_invent_no_corners(smooth):
    tex = texture(2)
    rgb, depth = render(pose(0.0), tex)
    r_rgb, r_depth = render(pose(0.05), tex)
    hole = person_hole()
    # the reference saw only the left half of what the hole hides
    r_dyn = np.zeros((H, W), bool)
    r_dyn[:, W // 2 - 15:] = True
    ref = ReferenceView(r_rgb, r_depth, pose(0.05), r_dyn)
    diffused = restore_frame(rgb, depth, hole, pose(0.0), [ref], K, RestorationConfig(unseen_fill=smooth))
    pm = restore_frame(rgb, depth, hole, pose(0.0), [ref], K, RestorationConfig(unseen_fill="patchmatch"))
    seen = diffused.seen_by_reference
    assert 0.2 < seen.sum() / hole.sum() < 0.8
    assert np.array_equal(diffused.rgb[seen], pm.rgb[seen])  # geometry decides where a reference sees
    unseen = hole & ~seen
    assert np.all(diffused.depth_confidence[unseen] < diffused.depth_confidence[seen].min())  # guessed, not seen
    assert np.array_equal(diffused.rgb[~hole], rgb[~hole])
    inner = cv2.erode(unseen.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0

    def corners_inside(img):
        kps = cv2.ORB_create(3000, fastThreshold=10).detect(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), None)
        return sum(inner[int(k.pt[1]), int(k.pt[0])] for k in kps)
    # a smooth fill invents (almost) no corners where copied texture does
    assert corners_inside(diffused.rgb) < 0.3 * corners_inside(pm.rgb)
    with pytest.raises(ValueError, match="unseen_fill"):
        restore_frame(rgb, depth, hole, pose(0.0), [], K, RestorationConfig(unseen_fill="magic"))


@pytest.mark.parametrize("frac_w", [0.05, 0.25])  # the large hole is solved on a coarser grid
def test_harmonic_fill_continues_smooth_shading_exactly(frac_w):
    """Colours that vary linearly across the image (a lit wall) are continued into a hole without error (a
    harmonic interpolant reproduces affine functions, on the coarse grid too), where Telea's fill is off."""
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    truth = np.stack([40 + 0.5 * x, 200 - 0.4 * y, 90 + 0.2 * x + 0.25 * y], -1)
    rgb = np.round(truth).astype(np.uint8)
    hole = person_hole(frac_w=frac_w)
    painted = rgb.copy()
    painted[hole] = (255, 0, 255)  # the person, which no fill may show through
    depth = np.full((H, W), 2.0, np.float32)
    out = restore_frame(painted, depth, hole, pose(0.0), [], K, RestorationConfig(unseen_fill="harmonic"))
    telea = restore_frame(painted, depth, hole, pose(0.0), [], K, RestorationConfig(unseen_fill="telea"))
    err = np.abs(out.rgb[hole].astype(float) - truth[hole])
    assert err.max() <= 1.0
    assert np.abs(telea.rgb[hole].astype(float) - truth[hole]).mean() > 2 * err.mean() + 0.5
    assert np.array_equal(out.rgb[~hole], rgb[~hole])
    assert out.from_self == 1.0 and np.allclose(out.depth[hole], 2.0, atol=1e-4)


def test_reference_selection_prefers_informative_moved_frames():
    orb = cv2.ORB_create(500)
    tex = texture(5)
    frames = {i: pose(0.004 * i) for i in range(20)}
    desc = {}
    for i, T in frames.items():
        g = cv2.cvtColor(render(T, tex)[0], cv2.COLOR_RGB2GRAY)
        desc[i] = orb.detectAndCompute(g, None)[1]
    target = Candidate(19, frames[19], desc[19])
    cands = [Candidate(i, frames[i], desc[i]) for i in range(19)]
    cfg = ReferenceSelectionConfig(min_translation_m=0.01, min_rotation_deg=0.0, far_refs=0)  # near ones only
    sel = select_references(target, cands, cfg)
    assert 2 <= len(sel.indices) <= 4 and not sel.relaxed
    assert all(4 <= i <= 16 for i in sel.indices)  # inside the 15-frame window, at least 1 cm away
    assert all(sel.match_ratio[i] >= 0.15 for i in sel.indices)
    gaps = np.diff(sorted(sel.indices))
    assert np.all(gaps >= ReferenceSelectionConfig().min_gap_frames)  # spread out, not neighbours


def test_far_references_are_second_chances_from_beyond_the_window():
    """Near references are chosen as without far ones; up to `far_refs` more come from 16-30 frames away, after
    them, by the same tests; both-sided, from either side; none with `far_refs` 0."""
    orb = cv2.ORB_create(500)
    tex = texture(5)
    frames = {i: pose(0.004 * (i - 40)) for i in range(81)}
    desc = {i: orb.detectAndCompute(cv2.cvtColor(render(T, tex)[0], cv2.COLOR_RGB2GRAY), None)[1]
            for i, T in frames.items()}
    target = Candidate(40, frames[40], desc[40])
    cands = [Candidate(i, frames[i], desc[i]) for i in frames if i != 40]
    cfg = ReferenceSelectionConfig(min_translation_m=0.01, min_rotation_deg=0.0)
    near = select_references(target, cands, replace(cfg, far_refs=0), both_sided=True)
    both = select_references(target, cands, cfg, both_sided=True)
    assert near.far == () and all(abs(i - 40) <= 15 for i in near.indices)
    assert both.indices[:len(near.indices)] == near.indices and both.relaxed == near.relaxed
    assert len(both.far) == cfg.far_refs and both.indices[len(near.indices):] == list(both.far)
    assert all(15 < abs(i - 40) <= 30 for i in both.far)
    assert {i < 40 for i in both.far} == {True, False}  # alternating sides, as the near ones
    causal = select_references(target, cands, cfg)
    assert all(i < 40 for i in causal.indices) and len(causal.far) == cfg.far_refs


def test_a_hole_pixel_takes_the_first_reference_that_sees_it():
    """Without blending, a later (second-chance) reference fills only what the earlier ones leave unseen: here
    the first sees everything, so the second, whose colours are all wrong, changes nothing."""
    tex = texture(3)
    rgb, depth = render(pose(0.0), tex)
    r_rgb, r_depth = render(pose(0.05), tex)
    near = ReferenceView(r_rgb, r_depth, pose(0.05), np.zeros((H, W), bool))
    wrong = ReferenceView(255 - r_rgb, r_depth, pose(-0.05), np.zeros((H, W), bool))
    hole = person_hole()
    cfg = RestorationConfig(colour_gain=False, blend_refs=1)
    one = restore_frame(rgb, depth, hole, pose(0.0), [near], K, cfg)
    two = restore_frame(rgb, depth, hole, pose(0.0), [near, wrong], K, cfg)
    assert one.seen_by_reference.sum() > 0.98 * hole.sum()
    seen = one.seen_by_reference
    assert np.array_equal(two.rgb[seen], one.rgb[seen])
    assert psnr(two.rgb, rgb, hole) >= 30


def _noisy_reference(tex: np.ndarray, T: np.ndarray, seed: int, depth_scale: float = 1.0) -> ReferenceView:
    r_rgb, r_depth = render(T, tex)
    noise = np.random.default_rng(seed).normal(0, 10, r_rgb.shape)
    return ReferenceView(np.clip(r_rgb + noise, 0, 255).astype(np.uint8), r_depth * np.float32(depth_scale), T,
                         np.zeros((H, W), bool))


def test_blending_two_references_averages_their_independent_errors():
    """Two references with independent noise: their average is closer to the truth than either (about 3 dB
    for equal noise; bilinear sampling already averages some of it), in colour and, with noisy depth, in depth."""
    tex = texture(4)
    rgb, depth = render(pose(0.0), tex)
    refs = [_noisy_reference(tex, pose(0.04), 1), _noisy_reference(tex, pose(-0.03, 0.01), 2)]
    hole = person_hole()
    rng = np.random.default_rng(3)
    for r in refs:  # depth noise of 1 % per pixel, independent between the references
        r.depth[:] *= 1 + 0.01 * rng.standard_normal(r.depth.shape).astype(np.float32)
    cfg = RestorationConfig(colour_gain=False)
    one = restore_frame(rgb, depth, hole, pose(0.0), refs, K, replace(cfg, blend_refs=1))
    two = restore_frame(rgb, depth, hole, pose(0.0), refs, K, replace(cfg, blend_refs=2))
    assert cfg.blend_refs == 2  # the default
    assert psnr(two.rgb, rgb, hole) > psnr(one.rgb, rgb, hole) + 1.2  # 28.4 -> 30.2 dB
    err_one, err_two = (np.median(np.abs(r.depth[hole] - depth[hole])) for r in (one, two))
    assert err_two < 0.85 * err_one


def test_a_reference_that_sees_another_surface_is_not_blended():
    """The second reference's depth puts its pixels 20 % farther than the first's (another surface): it is left
    out of the average, so its wrong colours change nothing the first reference sees."""
    tex = texture(3)
    rgb, depth = render(pose(0.0), tex)
    r_rgb, r_depth = render(pose(0.05), tex)
    near = ReferenceView(r_rgb, r_depth, pose(0.05), np.zeros((H, W), bool))
    other = ReferenceView(255 - r_rgb, r_depth * np.float32(1.2), pose(0.05), np.zeros((H, W), bool))
    hole = person_hole()
    cfg = RestorationConfig(colour_gain=False)
    one = restore_frame(rgb, depth, hole, pose(0.0), [near], K, cfg)
    two = restore_frame(rgb, depth, hole, pose(0.0), [near, other], K, cfg)
    seen = one.seen_by_reference
    assert seen.sum() > 0.98 * hole.sum()
    assert np.array_equal(two.rgb[seen], one.rgb[seen])
    assert np.array_equal(two.depth[seen], one.depth[seen])


def test_restoration_on_real_7scenes_beats_telea(redkitchen):
    """Static real scene: the true background behind an artificial hole is the frame itself."""
    from worker.slam.camera import camera_from_preset
    from worker.slam.io.sequence import Sequence

    seq = Sequence(redkitchen, camera_from_preset("7scenes"))
    _, gt = seq.groundtruth_for_frames()
    f = seq[700]
    hole = person_hole(480, 640, 0.11, 0.42)
    refs = [ReferenceView(seq[i].rgb, seq[i].depth, gt[i], np.zeros((480, 640), bool)) for i in (685, 690, 695)]
    out = restore_frame(f.rgb, f.depth, hole, gt[700], refs, seq.camera.K)
    telea = cv2.inpaint(f.rgb, hole.astype(np.uint8), 3, cv2.INPAINT_TELEA)
    assert psnr(out.rgb, f.rgb, hole) > psnr(telea, f.rgb, hole) + 2
    ok = hole & (out.depth > 0) & (f.depth > 0)
    assert ok.sum() > 0.8 * (hole & (f.depth > 0)).sum()
    assert np.median(np.abs(out.depth[ok] - f.depth[ok])) < 0.02


def test_a_bad_unseen_fill_is_a_config_error():
    from worker.slam.errors import ConfigError
    from worker.slam.presets import get_preset
    with pytest.raises(ConfigError, match="unseen_fill"):
        get_preset("full", {"restoration.restoration.unseen_fill": "magic"})
    assert get_preset("full", {"restoration.restoration.unseen_fill": "patchmatch"}) \
        .section("restoration").restoration.unseen_fill == "patchmatch"


def test_reference_exposure_is_matched_to_the_target():
    """A reference taken at a different exposure (all colours x 0.8) is scaled back on the hole's surroundings."""
    tex = texture(6)
    rgb, depth = render(pose(0.0), tex)
    r_rgb, r_depth = render(pose(0.05), tex)
    dark = (r_rgb * 0.8).astype(np.uint8)
    hole = person_hole()
    ref = ReferenceView(dark, r_depth, pose(0.05), np.zeros((H, W), bool))
    matched = restore_frame(rgb, depth, hole, pose(0.0), [ref], K)
    raw = restore_frame(rgb, depth, hole, pose(0.0), [ref], K, RestorationConfig(colour_gain=False))
    assert psnr(matched.rgb, rgb, hole) > psnr(raw.rgb, rgb, hole) + 6
    assert psnr(matched.rgb, rgb, hole) > 28
