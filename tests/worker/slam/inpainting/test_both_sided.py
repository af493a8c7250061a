"""Both-sided restoration in the pipeline stage: frames after the target, posed and masked by geometry."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from tests.worker.slam.inpainting.scene import H, K, W, pose, render, texture
from worker.slam.camera import Camera
from worker.slam.errors import ConfigError
from worker.slam.features.orb import OrbExtractor
from worker.slam.history import FrameHistory, PastFrame
from worker.slam.inpainting.lookahead import LookaheadConfig, moving_pixels, relative_pose_pnp
from worker.slam.inpainting.stage import RestorationStage
from worker.slam.io.sequence import Frame
from worker.slam.presets import get_preset
from worker.slam.stages import FrameInputs, StageContext, TrackedPose

TARGET = 10
MAGENTA = (255, 0, 255)


def person(index: int) -> np.ndarray:
    """bool (H, W): a magenta 'person' 1.2 m away, wide before the target (the past never sees behind what it
    hides in the target), then walked to the image's left edge."""
    m = np.zeros((H, W), bool)
    if index == TARGET:
        m[40:220, 130:200] = True
    elif index < TARGET:
        m[30:230, 80:250] = True
    else:
        m[40:220, 10:60] = True
    return m


def camera_pose(index: int) -> np.ndarray:
    return pose(0.01 * index, 0.0, 0.3 * index)


class WallSequence:
    """20 frames of a textured wall with the moving person drawn in (what `ctx.sequence` offers a stage)."""

    def __init__(self) -> None:
        self.tex = texture(7)

    def __len__(self) -> int:
        return 21

    def __getitem__(self, index: int) -> Frame:
        rgb, depth = render(camera_pose(index), self.tex)
        m = person(index)
        rgb, depth = rgb.copy(), depth.copy()
        rgb[m], depth[m] = MAGENTA, 1.2
        return Frame(index, index / 30.0, rgb, depth)


def run_stage(references: str, seq: WallSequence | None = None, mask=person,
              overrides: dict | None = None) -> tuple[FrameInputs, RestorationStage, np.ndarray]:
    """The stage over frames 0..TARGET of `seq` with `mask(i)` as each frame's dynamic mask; returns the target's
    inputs, the stage and the target's true background."""
    # every frame restored in `process` (not deferred to keyframes and previews): the target's result is read here
    config = get_preset("full", {"restoration.references": references, "restoration.on_demand": False,
                                 **(overrides or {})})
    camera = Camera(fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2], width=W, height=H)
    extractor = OrbExtractor(config.features)
    seq = seq if seq is not None else WallSequence()
    stage = RestorationStage(config, camera)
    history = FrameHistory(stage.history_frames)  # what the run keeps for the stages, as `PipelineRun` does
    last: TrackedPose | None = None
    inputs = FrameInputs()
    for i in range(TARGET + 1):
        f = seq[i]
        gray = cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY)
        inputs = FrameInputs(features=extractor.extract(gray, f.depth, mask(i)), dynamic_mask=mask(i))
        if last is not None:
            history.set_pose(last.index, last.T_WC)
        ctx = StageContext(camera, config, seq, None,  # type: ignore[arg-type]  # duck-typed
                           T_WC_pred=camera_pose(i), last=last, history=history.view())
        inputs = stage.process(f, inputs, ctx)
        history.append(PastFrame(i, f.timestamp, f.rgb, f.depth, features=inputs.features,
                                 dynamic=inputs.dynamic_mask))
        last = TrackedPose(i, camera_pose(i), None)
    truth, _ = render(camera_pose(TARGET), seq.tex)
    return inputs, stage, truth


def psnr(a: np.ndarray, b: np.ndarray, m: np.ndarray) -> float:
    mse = np.mean((a[m].astype(float) - b[m].astype(float)) ** 2)
    return float(10 * np.log10(255**2 / max(mse, 1e-9)))


def test_both_sided_references_see_what_the_past_never_did():
    hole = person(TARGET)
    causal, causal_stage, truth = run_stage("causal")
    both, both_stage, _ = run_stage("both-sided")
    assert causal.info["hole_seen_fraction"] < 0.1  # the person stood there all along
    assert both.info["hole_seen_fraction"] > 0.9
    assert both_stage.summary()["references"] == "both-sided" and both_stage.summary()["future_references"] > 0
    assert causal_stage.summary()["references"] == "causal" and causal_stage.summary()["future_references"] == 0
    assert both.restored_rgb is not None and causal.restored_rgb is not None
    assert psnr(both.restored_rgb, truth, hole) > psnr(causal.restored_rgb, truth, hole) + 5
    magenta = np.all(both.restored_rgb[hole] == MAGENTA, axis=1)
    assert magenta.mean() < 0.01  # the future frames' person (elsewhere) is never copied


def passer_by(index: int) -> np.ndarray:
    """bool (H, W): the mask segmentation gives of a person walking right to left past the target's hole."""
    m = np.zeros((H, W), bool)
    x = 230 - 10 * index  # frame 10: columns 130-200
    m[40:220, x:x + 70] = True
    return m


class FringeSequence(WallSequence):
    """The passer-by drawn 6 px wider than its mask: the outline segmentation misses."""

    def __getitem__(self, index: int) -> Frame:
        rgb, depth = render(camera_pose(index), self.tex)
        m = cv2.dilate(passer_by(index).astype(np.uint8), np.ones((13, 13), np.uint8)) > 0
        rgb, depth = rgb.copy(), depth.copy()
        rgb[m], depth[m] = MAGENTA, 1.2
        return Frame(index, index / 30.0, rgb, depth)


def test_a_references_unmasked_fringe_is_not_copied():
    """Past frames see the wall behind the target's hole, but their own passer-by's fringe, outside its mask,
    lands in the hole too: widening the references' masks (`reference_margin_px`, default 8) keeps it out."""
    hole = passer_by(TARGET)
    widened, _, truth = run_stage("causal", FringeSequence(), passer_by)
    raw, _, _ = run_stage("causal", FringeSequence(), passer_by, {"restoration.reference_margin_px": 0})
    assert widened.restored_rgb is not None and raw.restored_rgb is not None

    def magenta(rgb: np.ndarray) -> float:
        return float(np.all(rgb[hole] == MAGENTA, axis=1).mean())

    assert magenta(raw.restored_rgb) > 0.01  # the fringe, copied
    assert magenta(widened.restored_rgb) == 0.0
    assert psnr(widened.restored_rgb, truth, hole) > psnr(raw.restored_rgb, truth, hole) + 3


def test_future_pose_and_moving_pixels_from_geometry():
    seq, cfg = WallSequence(), LookaheadConfig()
    extractor = OrbExtractor(get_preset("full").features)
    tgt, fut = seq[TARGET], seq[TARGET + 4]
    feats = [extractor.extract(cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY), f.depth) for f in (tgt, fut)]
    est = relative_pose_pnp(feats[0], ~person(TARGET), feats[1], K, cfg)
    assert est is not None
    T_ft, inliers = est
    true = np.linalg.inv(camera_pose(TARGET + 4)) @ camera_pose(TARGET)
    assert inliers >= cfg.min_pnp_inliers
    # what restoration needs: the target's pixels land where the true motion puts them (on a plane, a small
    # translation error traded against rotation is invisible)
    ys, xs = np.mgrid[0:H:8, 0:W:8]
    z = tgt.depth[ys, xs].ravel()
    P = np.stack([(xs.ravel() - K[0, 2]) / K[0, 0] * z, (ys.ravel() - K[1, 2]) / K[1, 1] * z, z], 1)

    def project(T: np.ndarray) -> np.ndarray:
        Q = P @ T[:3, :3].T + T[:3, 3]
        return (Q[:, :2] / Q[:, 2:]) * K[0, 0]

    assert np.median(np.linalg.norm(project(T_ft) - project(true), axis=1)) < 0.5
    assert np.percentile(np.linalg.norm(project(T_ft) - project(true), axis=1), 95) < 2.5
    dyn = moving_pixels(fut.depth, T_ft, tgt.depth, person(TARGET), K, cfg)
    assert dyn[person(TARGET + 4)].mean() > 0.99  # in front of the wall the target sees
    static = ~person(TARGET + 4) & ~(cv2.dilate(person(TARGET + 4).astype(np.uint8), np.ones((25, 25))) > 0)
    assert dyn[static].mean() < 0.01


def test_references_setting_is_checked():
    with pytest.raises(ConfigError, match="references"):
        get_preset("full", {"restoration.references": "sideways"})
    assert get_preset("full").section("restoration").references == "both-sided"



def test_a_pnp_that_opencv_refuses_gives_no_pose_not_an_error(monkeypatch):
    """SQPnP asserts (point_coordinate_variance) on some real samples (seen on an augmented 7-Scenes
    sequence, deterministic for those inputs): that future frame gives no pose; the job goes on."""
    import worker.slam.inpainting.lookahead as lookahead

    seq, cfg = WallSequence(), LookaheadConfig()
    extractor = OrbExtractor(get_preset("full").features)
    tgt, fut = seq[TARGET], seq[TARGET + 4]
    feats = [extractor.extract(cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY), f.depth) for f in (tgt, fut)]

    def refuse(*_args, **_kwargs):
        raise cv2.error("point_coordinate_variance >= POINT_VARIANCE_THRESHOLD")

    monkeypatch.setattr(lookahead.cv2, "solvePnPRansac", refuse)
    assert relative_pose_pnp(feats[0], ~person(TARGET), feats[1], K, cfg) is None
