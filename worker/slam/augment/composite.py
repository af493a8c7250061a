"""Pasting a cut-out person into a real RGB-D frame as a vertical billboard standing on the floor.

A mover's billboard turns to face the camera; a static instance's keeps the orientation it was given (a rigid
object: a billboard that turned would swim against the scene and rightly look dynamic). Its silhouette edge is
blended over the pixels it covers (only pixels inside the mask change, so the truth stays exact); its depth is
the plane's depth, rounded by up to `bulge_m` towards the camera inside the silhouette (a body is not flat).
The person is drawn only where it is nearer than the real depth (or the real depth is unknown), and there its
depth replaces the real one.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from worker.slam.augment.floor import Floor
from worker.slam.augment.sprites import Sprite
from worker.slam.camera import Camera

NEAR = 0.2  # m: a billboard corner nearer than this (or behind the camera) is not drawn


@dataclass(frozen=True)
class Billboard:
    """A person of `height` metres whose feet are at floor point `foot` (3,), world frame; `facing` (3,) a fixed
    horizontal unit normal in the world (None: it turns towards the camera)."""

    sprite: Sprite
    foot: np.ndarray
    height: float
    bulge_m: float = 0.12
    facing: np.ndarray | None = None


def _light_gain(frame_rgb: np.ndarray, region: tuple[slice, slice], sprite: Sprite) -> float:
    """Brightness gain that moves the person halfway to the scene's brightness around it (clipped)."""
    scene = float(frame_rgb[region].mean()) + 1.0
    person = float(sprite.rgb[sprite.mask > 0].mean()) + 1.0
    return float(np.clip(np.sqrt(scene / person), 0.7, 1.3))


def composite(rgb: np.ndarray, depth_u16: np.ndarray, ids: np.ndarray, camera: Camera, T_WC: np.ndarray,
              floor: Floor, person: Billboard, instance: int) -> int:
    """Draw `person` into RGB uint8 (H,W,3), uint16 depth (value / camera.depth_scale = m) and uint8 instance
    ids (H,W), all in place. Returns the number of pixels where the person is visible."""
    C = T_WC[:3, 3]
    to_cam = C - person.foot
    to_cam -= (to_cam @ floor.up) * floor.up
    n = to_cam / max(np.linalg.norm(to_cam), 1e-9)  # billboard normal, horizontal, towards the camera
    if person.facing is not None:
        n = person.facing  # rigid: seen from behind, the same plane shows its mirror image
    right = np.cross(floor.up, n)  # image right of the sprite as seen from the camera
    w = person.height * person.sprite.aspect
    top = person.foot + person.height * floor.up
    corners_w = np.stack([top - right * w / 2, top + right * w / 2,
                          person.foot + right * w / 2, person.foot - right * w / 2])
    R = T_WC[:3, :3]
    pc = (corners_w - C) @ R
    if np.any(pc[:, 2] < NEAR):
        return 0
    uv = np.stack([camera.fx * pc[:, 0] / pc[:, 2] + camera.cx, camera.fy * pc[:, 1] / pc[:, 2] + camera.cy], 1)
    h_img, w_img = ids.shape
    c0, r0 = max(int(np.floor(uv[:, 0].min())), 0), max(int(np.floor(uv[:, 1].min())), 0)
    c1, r1 = min(int(np.ceil(uv[:, 0].max())) + 1, w_img), min(int(np.ceil(uv[:, 1].max())) + 1, h_img)
    if c0 >= c1 or r0 >= r1:
        return 0
    sh, sw = person.sprite.mask.shape
    src = np.array([[0, 0], [sw, 0], [sw, sh], [0, sh]], np.float32)
    H = cv2.getPerspectiveTransform(src, (uv - [c0, r0]).astype(np.float32))
    size = (c1 - c0, r1 - r0)
    # Fractional coverage of the warped silhouette: > 0.5 is the person (mask), below 1 its edge is blended.
    alpha = cv2.warpPerspective(person.sprite.mask.astype(np.float32), H, size, flags=cv2.INTER_LINEAR)
    mask = alpha > 0.5
    if not mask.any():
        return 0
    # Premultiplied warp, so the COCO photo's own background never bleeds into the person's edge.
    premult = person.sprite.rgb.astype(np.float32) * person.sprite.mask[..., None]
    colour = cv2.warpPerspective(premult, H, size, flags=cv2.INTER_LINEAR) / np.maximum(alpha, 1e-3)[..., None]
    bulge = cv2.warpPerspective(person.sprite.bulge, H, size, flags=cv2.INTER_LINEAR)
    # Plane depth per pixel: z = (n_c . p_c) / (n_c . (x_n, y_n, 1)) with the plane through the foot point.
    n_c = R.T @ n
    p_c = R.T @ (person.foot - C)
    xs = (np.arange(c0, c1, dtype=np.float32) - camera.cx) / camera.fx
    ys = (np.arange(r0, r1, dtype=np.float32) - camera.cy) / camera.fy
    denom = n_c[0] * xs[None, :] + n_c[1] * ys[:, None] + n_c[2]
    with np.errstate(divide="ignore"):
        z = np.float32(n_c @ p_c) / denom - np.float32(person.bulge_m) * bulge
    z_u16 = np.clip(np.rint(z * camera.depth_scale), 1, 65535).astype(np.uint16)
    win = (slice(r0, r1), slice(c0, c1))
    real = depth_u16[win]
    visible = mask & (z > NEAR) & ((real == 0) | (z_u16 < real))
    if not visible.any():
        return 0
    gain = _light_gain(rgb, win, person.sprite)
    a = np.clip((alpha[visible] - 0.5) * 2.0 + 0.5, 0.0, 1.0)[:, None]  # edge pixels ~0.5-0.75, inside 1
    under = rgb[win][visible].astype(np.float32)
    rgb[win][visible] = np.clip(a * colour[visible] * gain + (1 - a) * under, 0, 255).astype(np.uint8)
    real[visible] = z_u16[visible]
    ids[win][visible] = instance
    return int(visible.sum())
