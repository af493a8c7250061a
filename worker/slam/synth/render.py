"""Vectorised analytic ray casting of the room, its boxes and the walkers' ellipsoids, in numpy.

Rays are parametrised with unit camera-frame depth (d_C = (x_n, y_n, 1)), so the ray parameter at a hit *is* the
pixel's depth. Boxes and ellipsoids are only cast inside the image rectangle their bounds project to, which
keeps a 640x480 frame well under 50 ms on one core.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from worker.slam.camera import Camera
from worker.slam.synth.people import Ellipsoid
from worker.slam.synth.scene import StaticScene

NEAR = 0.05  # m; nothing closer is rendered


@dataclass(frozen=True)
class RenderOutput:
    """One rendered view. `rgb`/`static_rgb` RGB uint8 (H, W, 3); `depth`/`static_depth` float32 metres (H, W),
    noise-free; `ids` uint8 (H, W) 0 = static, k = walker k; `static_face` uint8 (H, W) face id of the room."""

    rgb: np.ndarray
    depth: np.ndarray
    ids: np.ndarray
    static_rgb: np.ndarray
    static_depth: np.ndarray
    static_face: np.ndarray


class Renderer:
    """Renders a `StaticScene` plus walkers from camera poses T_RC (camera-to-room, 4x4 float64)."""

    def __init__(self, camera: Camera, scene: StaticScene) -> None:
        self.camera, self.scene = camera, scene
        u = np.arange(camera.width, dtype=np.float32)
        v = np.arange(camera.height, dtype=np.float32)
        self.xn = np.broadcast_to((u - camera.cx) / camera.fx, (camera.height, camera.width))
        self.yn = np.broadcast_to(((v - camera.cy) / camera.fy)[:, None], (camera.height, camera.width))
        n_faces = len(scene.face_shade)
        if n_faces > 256:
            raise ValueError(f"at most 256 faces (uint8 ids), got {n_faces}")
        # Per-face tables as 256-entry LUTs: cv2.LUT on uint8 face ids beats numpy gathers several times over.
        table = np.zeros((6, 256), np.float32)
        table[:5, :n_faces] = scene.face_cell.T
        table[5, :n_faces] = scene.face_shade
        self._lut = [np.ascontiguousarray(row) for row in table]

    # -- helpers ---------------------------------------------------------------------------------------------
    def _window(self, T_RC: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[slice, slice] | None:
        """Image rows/cols covered by the axis-aligned room-frame box lo..hi; None if it is behind the camera."""
        corners = np.array(np.meshgrid(*zip(lo, hi), indexing="ij")).reshape(3, -1).T
        pc = (corners - T_RC[:3, 3]) @ T_RC[:3, :3]
        c = self.camera
        if np.all(pc[:, 2] <= NEAR):
            return None
        if np.any(pc[:, 2] <= NEAR):
            return slice(0, c.height), slice(0, c.width)
        u = c.fx * pc[:, 0] / pc[:, 2] + c.cx
        v = c.fy * pc[:, 1] / pc[:, 2] + c.cy
        c0, c1 = max(int(np.floor(u.min())), 0), min(int(np.ceil(u.max())) + 1, c.width)
        r0, r1 = max(int(np.floor(v.min())), 0), min(int(np.ceil(v.max())) + 1, c.height)
        if c0 >= c1 or r0 >= r1:
            return None
        return slice(r0, r1), slice(c0, c1)

    def _dirs(self, M: np.ndarray, win: tuple[slice, slice]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Ray directions M @ (x_n, y_n, 1) over a window, one float32 array per component."""
        xn, yn = self.xn[win], self.yn[win]
        M = M.astype(np.float32)
        return M[0, 0] * xn + M[0, 1] * yn + M[0, 2], M[1, 0] * xn + M[1, 1] * yn + M[1, 2], \
            M[2, 0] * xn + M[2, 1] * yn + M[2, 2]

    # -- static scene ----------------------------------------------------------------------------------------
    def render_static(self, T_RC: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rgb uint8 (H,W,3), depth float32 (H,W), face id uint8 (H,W)) of the room without walkers."""
        s, o = self.scene, T_RC[:3, 3]
        full = (slice(None), slice(None))
        d = [np.where(di == 0, np.float32(1e-12), di) for di in self._dirs(T_RC[:3, :3], full)]
        inv = [np.float32(1.0) / di for di in d]
        # Inside the room every ray leaves through the nearest of the three planes it is heading to.
        t = [(np.where(d[a] > 0, np.float32(s.room_hi[a]), np.float32(s.room_lo[a])) - np.float32(o[a])) * inv[a]
             for a in range(3)]
        depth = np.minimum(np.minimum(t[0], t[1]), t[2])
        face = np.where((t[0] <= t[1]) & (t[0] <= t[2]), (d[0] > 0).astype(np.uint8),
                        np.where(t[1] <= t[2], 2 + (d[1] > 0), 4 + (d[2] > 0))).astype(np.uint8)
        for b, box in enumerate(s.boxes):
            win = self._window(T_RC, box.lo, box.hi)
            if win is None:
                continue
            tn, tf = [], []
            for a in range(3):
                t1 = (np.float32(box.lo[a] - o[a])) * inv[a][win]
                t2 = (np.float32(box.hi[a] - o[a])) * inv[a][win]
                tn.append(np.minimum(t1, t2))
                tf.append(np.maximum(t1, t2))
            near = np.maximum(np.maximum(tn[0], tn[1]), tn[2])
            far = np.minimum(np.minimum(tf[0], tf[1]), tf[2])
            dw = depth[win]
            hit = (near <= far) & (near > NEAR) & (near < dw)
            if not hit.any():
                continue
            axis = np.where((tn[0] >= tn[1]) & (tn[0] >= tn[2]), 0, np.where(tn[1] >= tn[2], 1, 2))
            d_ax = np.where(axis == 0, d[0][win], np.where(axis == 1, d[1][win], d[2][win]))
            fid = (6 + 6 * b + 2 * axis + (d_ax < 0)).astype(np.uint8)  # a ray heading -axis enters through the hi face
            depth[win] = np.where(hit, near, dw)
            face[win] = np.where(hit, fid, face[win])
        rgb = self._shade(o, d, depth, face)
        return rgb, depth, face

    def _shade(self, o: np.ndarray, d: list[np.ndarray], depth: np.ndarray, face: np.ndarray) -> np.ndarray:
        s = self.scene
        p = [np.float32(o[a]) + depth * d[a] for a in range(3)]
        axis = (face % 6) // 2
        # Texture (u, v) = (y, z) on x-facing, (x, z) on y-facing, (x, y) on z-facing faces: z stays "up".
        u = np.where(axis == 0, p[1], p[0])
        v = np.where(axis == 2, p[1], p[2])
        x0, y0, w, h, k = (cv2.LUT(face, self._lut[i]) for i in range(5))
        tu, tv = u * k, -v * k  # texture rows grow downwards, world z upwards
        mapx = x0 + (tu - np.floor(tu / w) * w)
        mapy = y0 + (tv - np.floor(tv / h) * h)
        tex = cv2.remap(s.atlas.image, mapx, mapy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        shade = cv2.LUT(face, self._lut[5])
        # Soft fall-off away from a ceiling light above the room centre: real rooms are not evenly lit.
        c = (s.room_lo + s.room_hi) / 2
        r2 = (p[0] - np.float32(c[0])) ** 2 + (p[1] - np.float32(c[1])) ** 2
        shade = shade * (np.float32(0.8) + np.float32(0.35) / (np.float32(1.0) + np.float32(0.08) * r2))
        return cv2.multiply(tex, cv2.merge([shade, shade, shade]), dtype=cv2.CV_8U)

    # -- movers ----------------------------------------------------------------------------------------------
    def render(self, T_RC: np.ndarray, movers: list[list[Ellipsoid]]) -> RenderOutput:
        """Static scene plus `movers` (walker k+1's ellipsoids at index k), composited by depth."""
        s_rgb, s_depth, s_face = self.render_static(T_RC)
        h, w = s_depth.shape
        t_dyn = np.full((h, w), np.inf, np.float32)
        ids = np.zeros((h, w), np.uint8)
        dyn_rgb = np.empty((h, w, 3), np.float32)  # read only where a part was hit
        box = [h, 0, w, 0]  # union of the parts' windows: compositing is done only there
        o = T_RC[:3, 3]
        for k, parts in enumerate(movers, start=1):
            for e in parts:
                # Tight axis-aligned bounds of the rotated ellipsoid: half-extent_i = |row_i of axes * radii|.
                ext = np.sqrt(((e.axes * e.radii) ** 2).sum(axis=1))
                win = self._window(T_RC, e.center - ext, e.center + ext)
                if win is None:
                    continue
                box = [min(box[0], win[0].start), max(box[1], win[0].stop),
                       min(box[2], win[1].start), max(box[3], win[1].stop)]
                M = (e.axes / e.radii).T  # room -> unit-sphere coordinates
                oq = M @ (o - e.center)
                dq = self._dirs(M @ T_RC[:3, :3], win)
                a = dq[0] * dq[0] + dq[1] * dq[1] + dq[2] * dq[2]
                b = np.float32(oq[0]) * dq[0] + np.float32(oq[1]) * dq[1] + np.float32(oq[2]) * dq[2]
                disc = b * b - a * np.float32(oq @ oq - 1.0)
                hit = disc > 0
                if not hit.any():
                    continue
                a, b, disc = a[hit], b[hit], disc[hit]
                root = np.sqrt(disc)
                t = (-b - root) / a
                tw = t_dyn[win]
                closer = (t > NEAR) & (t < tw[hit])
                if not closer.any():
                    continue
                hit[hit] = closer  # hit now marks the pixels this part wins
                t, root, a = t[closer], root[closer], a[closer]
                lam = np.float32(0.35) + np.float32(0.65) * root / np.sqrt(a)  # cos(incidence), unit-sphere space
                col = np.broadcast_to(e.material.a, t.shape + (3,))
                if e.material.stripes > 0:
                    qz = np.float32(oq[2]) + t * dq[2][hit]
                    band = (np.floor((qz + 1) * np.float32(e.material.stripes)).astype(np.int32) & 1).astype(bool)
                    col = np.where(band[:, None], e.material.b, e.material.a)
                tw[hit] = t
                ids[win][hit] = k
                dyn_rgb[win][hit] = col * lam[:, None]
        rgb, depth = s_rgb.copy(), s_depth.copy()
        if box[0] < box[1] and box[2] < box[3]:
            u = (slice(box[0], box[1]), slice(box[2], box[3]))
            vis = t_dyn[u] < s_depth[u]
            ids[u][~vis] = 0
            rgb[u][vis] = np.clip(dyn_rgb[u][vis], 0, 255).astype(np.uint8)
            depth[u][vis] = t_dyn[u][vis]
        return RenderOutput(rgb, depth, ids, s_rgb, s_depth, s_face)
