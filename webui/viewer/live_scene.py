"""A running job's scene: its partial results (``formats.artifacts.PARTIALS``, written by ``worker.snapshots``)
redrawn as they change, until its final artifacts replace them; then the ordinary scene (``scene.build_scene``).

:func:`partial_state` says what a run folder holds now; :class:`LiveScene` owns the live nodes of one viser
server and :meth:`LiveScene.refresh` (called by the hub's refresher thread) redraws what changed.
"""
from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from formats import artifacts
from storage.errors import NotFound
from webui.viewer.run_data import load_run, read_tum, valid_legend
from webui.viewer.scene import _read_image, build_scene, height_colors, legend_html

log = logging.getLogger(__name__)

FINAL, PARTIAL, NOTHING = "final", "partial", "nothing"


def partial_state(run_dir: Path) -> str:
    """FINAL (the finished run's artifacts), PARTIAL (a running job's snapshots) or NOTHING yet."""
    if (run_dir / artifacts.PARTIAL_STATE).is_file() or (run_dir / artifacts.PARTIAL_TRAJECTORY).is_file():
        return PARTIAL
    return FINAL if (run_dir / artifacts.TRAJECTORY).is_file() else NOTHING


def frame_legend(run_dir: Path) -> list[dict]:
    """partial.json's `frame_legend` (the classes of the current frame image, `worker.snapshots`); [] without."""
    import json

    try:
        state = json.loads((run_dir / artifacts.PARTIAL_STATE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return []
    return valid_legend(state.get("frame_legend")) if isinstance(state, dict) else []


def _mtime(path: Path) -> float:
    try:
        return os.stat(path).st_mtime
    except OSError:
        return 0.0


class LiveScene:
    """The live layers of ``server``: trajectory so far, keyframes, the map so far, the latest pose, the frame
    with its masks. ``refresh()`` redraws what changed and returns False once the run is final (then the
    scene is the ordinary one of the finished run)."""

    def __init__(self, server: Any, run_dir: Path, title: str) -> None:
        self.server, self.run_dir, self.title = server, run_dir, title
        self.seen: dict[str, float] = {}
        self.shown: dict[str, int] = {"poses": 0, "keyframes": 0, "map": 0}
        """What the scene shows now (poses, keyframes, map points)."""
        self.image: Any = None
        self.legend: Any = None
        self.legend_text = ""
        server.gui.add_markdown(f"**{title}** (running: the map and trajectory so far, updated as it goes)")
        self.status = server.gui.add_markdown("waiting for the first snapshot…")
        server.scene.set_up_direction((0.0, -1.0, 0.0))
        self.framed = False

    def _changed(self, name: str) -> bool:
        m = _mtime(self.run_dir / name)
        if m and m != self.seen.get(name):
            self.seen[name] = m
            return True
        return False

    def refresh(self) -> bool:
        state = partial_state(self.run_dir)
        if state == FINAL:
            self.server.scene.reset()
            self.server.gui.reset()
            build_scene(self.server, load_run(self.run_dir), self.title)
            return False
        try:
            self._redraw()
        except (NotFound, OSError, ValueError) as exc:  # a file replaced while read: the next round reads it
            log.debug("live scene %s: %s", self.run_dir.name, exc)
        return True

    def _redraw(self) -> None:
        scene, d = self.server.scene, self.run_dir
        if self._changed(artifacts.PARTIAL_TRAJECTORY):
            traj = read_tum(d / artifacts.PARTIAL_TRAJECTORY)
            p = traj.positions
            if len(p) >= 2:
                seg = np.stack([p[:-1], p[1:]], axis=1).astype(np.float32)
                scene.add_line_segments("/trajectory", seg, np.full((len(seg), 2, 3), (40, 90, 220), np.uint8),
                                        thickness=5.0, thickness_units="screen")
                scene.add_camera_frustum("/current", fov=0.9, aspect=4 / 3, scale=0.12, color=(255, 140, 0),
                                         wxyz=traj.wxyz[-1], position=p[-1])
                self._frame(p)
            self.shown["poses"] = len(p)
            self.status.content = f"{len(p)} poses so far"
        if self._changed(artifacts.PARTIAL_KEYFRAMES):
            try:
                kf = read_tum(d / artifacts.PARTIAL_KEYFRAMES).positions.astype(np.float32)
                scene.add_point_cloud("/keyframes", kf, np.tile(np.array([[120, 120, 255]], np.uint8), (len(kf), 1)),
                                      point_size=0.04)
                self.shown["keyframes"] = len(kf)
            except NotFound:  # no keyframe yet
                pass
        if self._changed(artifacts.PARTIAL_MAP):
            from formats.ply import read_ply

            pts, cols = read_ply(d / artifacts.PARTIAL_MAP)
            if len(pts):
                scene.add_point_cloud("/map", pts, cols if cols is not None else height_colors(pts), point_size=0.01)
            self.shown["map"] = len(pts)
        if self._changed(artifacts.PARTIAL_FRAME_MASK):
            img = _read_image(d / artifacts.PARTIAL_FRAME_MASK)
            entries = frame_legend(d)
            if self.image is None:
                label = ("Current frame (coloured by class; red outline: moving)" if entries else
                         "Current frame (red: moving, yellow: potentially dynamic)")
                self.image = self.server.gui.add_image(img, label=label)
            else:
                self.image.image = img
            self._show_legend(entries)

    def _show_legend(self, entries: list[dict]) -> None:
        """The current frame's classes in their colours, under the image (only the classes in that frame)."""
        text = legend_html(entries)
        if not text or text == self.legend_text:
            return
        self.legend_text = text
        if self.legend is None:
            self.legend = self.server.gui.add_html(text)
        else:
            self.legend.content = text

    def _frame(self, positions: np.ndarray) -> None:
        """Point the initial camera at the run once it has moved a little."""
        if self.framed or len(positions) < 10:
            return
        self.framed = True
        centre = positions.mean(axis=0)
        self.server.initial_camera.look_at = centre
        self.server.initial_camera.position = centre + np.array([0.0, -1.5, -2.5])
