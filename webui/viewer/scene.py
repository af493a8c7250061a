"""Build one run's 3D scene and controls on a viser server."""
from __future__ import annotations

import html
from pathlib import Path
from typing import Any

import numpy as np

from storage.errors import NotFound
from webui.viewer.run_data import Poses, RunData


def error_colors(err: np.ndarray | None, n: int) -> np.ndarray:
    """(n, 3) uint8: green (small ATE) → red (the run's max); blue where the error is unknown."""
    if err is None or not np.isfinite(err).any():
        return np.tile(np.array([[40, 90, 220]], np.uint8), (n, 1))
    e = np.nan_to_num(err, nan=0.0)
    t = np.clip(e / max(float(np.nanmax(err)), 1e-9), 0, 1)[:, None]
    out = (1 - t) * np.array([40, 200, 60]) + t * np.array([230, 40, 30])
    out[~np.isfinite(err)] = (40, 90, 220)
    return out.astype(np.uint8)


def height_colors(points: np.ndarray) -> np.ndarray:
    """(M, 3) uint8 colour ramp over the vertical axis (camera frames: y points down)."""
    h = -points[:, 1]
    t = ((h - np.percentile(h, 2)) / max(np.ptp(np.percentile(h, [2, 98])), 1e-6)).clip(0, 1)[:, None]
    return ((1 - t) * np.array([30, 60, 200]) + t * np.array([250, 220, 40])).astype(np.uint8)


def _frame_camera(server, data: RunData) -> None:
    """Start the view above and behind the run, looking at its centre, camera-frame up (-y) as up."""
    pts = data.trajectory.positions if data.points is None else np.vstack([data.points, data.trajectory.positions])
    lo, hi = np.percentile(pts, 5, axis=0), np.percentile(pts, 95, axis=0)
    centre, extent = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) + 0.5
    server.scene.set_up_direction((0.0, -1.0, 0.0))
    server.initial_camera.look_at = centre
    server.initial_camera.position = centre + np.array([0.0, -0.6, -1.0]) * extent


def _segments(p: Poses, colors: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    seg = np.stack([p.positions[:-1], p.positions[1:]], axis=1).astype(np.float32)
    if colors is None:
        return seg, np.full((len(seg), 2, 3), 150, np.uint8)
    return seg, np.stack([colors[:-1], colors[1:]], axis=1)


def legend_html(entries: list[dict], title: str = "") -> str:
    """HTML naming each class beside a square of its colour (`formats.class_palette.legend` entries); the classes
    that are not potentially dynamic are marked "not masked". Empty without entries."""
    if not entries:
        return ""
    rows = "".join(
        f'<div><span style="display:inline-block;width:0.9em;height:0.9em;margin-right:0.4em;'
        f'background:{html.escape(e["colour"])}"></span>{html.escape(e["name"])}'
        f'{"" if e["dynamic"] else " <small>(not masked)</small>"}</div>' for e in entries)
    head = f"<div><b>{html.escape(title)}</b></div>" if title else ""
    return f'<div style="font-size:0.85em">{head}{rows}</div>'


def _read_image(path: Path, max_w: int = 480) -> np.ndarray:
    """(h, w, 3) uint8 RGB preview, at most ``max_w`` wide."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise NotFound(f"{path.name}: not a readable image")
    img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    if img.shape[1] > max_w:
        img = cv2.resize(img, (max_w, int(img.shape[0] * max_w / img.shape[1])))
    return img


def build_scene(server, data: RunData, title: str, fov_rad: float = 0.9, aspect: float = 4 / 3) -> None:
    """Populate `server` (viser.ViserServer) with the run's layers and its GUI."""
    scene, gui = server.scene, server.gui
    gui.add_markdown(f"**{title}**")
    _frame_camera(server, data)
    layers: dict[str, list] = {"Map": [], "Trajectory": [], "Ground truth": [], "Keyframes": []}
    traj = data.trajectory
    layers["Trajectory"].append(scene.add_line_segments(
        "/trajectory", *_segments(traj, error_colors(data.ate_error, len(traj.positions))),
        thickness=5.0, thickness_units="screen"))
    if data.groundtruth is not None:
        layers["Ground truth"].append(scene.add_line_segments(
            "/groundtruth", *_segments(data.groundtruth), thickness=2.0, thickness_units="screen"))
    if data.points is not None:
        points = data.points
        rgb = data.colors if data.colors is not None else height_colors(data.points)
        cloud = scene.add_point_cloud("/map", data.points, rgb, point_size=0.01)
        layers["Map"].append(cloud)
        size = gui.add_slider("Point size", min=0.002, max=0.05, step=0.001, initial_value=0.01)
        mode = gui.add_dropdown("Colour", ("RGB", "Height"), initial_value="RGB")

        @size.on_update
        def _(_) -> None:
            cloud.point_size = size.value

        @mode.on_update
        def _(_) -> None:
            cloud.colors = height_colors(points) if mode.value == "Height" or data.colors is None else data.colors
    if data.keyframes is not None:
        for i, (p, q) in enumerate(zip(data.keyframes.positions, data.keyframes.wxyz)):
            layers["Keyframes"].append(scene.add_camera_frustum(
                f"/keyframes/{i}", fov=fov_rad, aspect=aspect, scale=0.05, color=(120, 120, 255), wxyz=q,
                position=p))
    with gui.add_folder("Layers"):
        for label, handles in layers.items():
            if not handles:
                continue
            box = gui.add_checkbox(label, initial_value=True)

            @box.on_update
            def _(_, handles=handles, box=box) -> None:
                for handle in handles:
                    handle.visible = box.value
    _frame_slider(server, data, fov_rad, aspect)


def _frame_slider(server, data: RunData, fov_rad: float, aspect: float) -> None:
    traj = data.trajectory
    n = len(traj.positions)
    marker = server.scene.add_camera_frustum("/current", fov=fov_rad, aspect=aspect, scale=0.12,
                                             color=(255, 140, 0), wxyz=traj.wxyz[0], position=traj.positions[0])
    slider = server.gui.add_slider("Frame", min=0, max=max(n - 1, 1), step=1, initial_value=0)
    frames = sorted(data.previews)
    image = None
    kind = None
    if frames:
        kinds = tuple(k for k in ("rgb", "classes", "mask", "restored")
                      if any(k in files for files in data.previews.values()))
        kind = server.gui.add_dropdown("Overlay", kinds or ("rgb",), initial_value=kinds[0] if kinds else "rgb")
        image = server.gui.add_image(_read_image(data.previews[frames[0]].get("rgb")
                                                 or next(iter(data.previews[frames[0]].values()))),
                                     label="Frame")
        if data.legend:
            server.gui.add_html(legend_html(data.legend, "Classes (overlay 'classes'; red outline: moving)"))

    def refresh(_: Any = None) -> None:
        i = int(slider.value)
        marker.position, marker.wxyz = traj.positions[i], traj.wxyz[i]
        if image is not None and kind is not None and frames:
            # pose i is frame i only when no frame was lost: the frame stats say which frame it is
            at = int(data.frame_index[i]) if data.frame_index is not None and data.frame_index[i] >= 0 else i
            nearest = min(frames, key=lambda f: abs(f - at))
            files = data.previews[nearest]
            path = files.get(kind.value) or files.get("rgb") or next(iter(files.values()))
            image.image = _read_image(path)

    slider.on_update(refresh)
    if kind is not None:
        kind.on_update(refresh)
