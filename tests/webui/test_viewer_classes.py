"""The viewer's class colours: the run's legend from metrics.json, the `classes` overlay, the live frame's legend."""
from __future__ import annotations

import json
from pathlib import Path
from unittest.mock import MagicMock

import cv2
import numpy as np

from formats import artifacts
from tests.webui.test_viewer import write_run
from webui.viewer.live_scene import LiveScene, frame_legend
from webui.viewer.run_data import load_run
from webui.viewer.scene import build_scene, legend_html

LEGEND = [{"name": "person", "colour": "#c08080", "dynamic": True},
          {"name": "sofa", "colour": "#00c000", "dynamic": False}]


def _with_classes(d: Path) -> None:
    cv2.imwrite(str(d / "frame_000010_classes.jpg"), np.full((48, 64, 3), 90, np.uint8))
    bad = [{"name": "x", "colour": "red"}, {"name": 3, "colour": "#000000"}, "junk"]
    (d / artifacts.METRICS).write_text(json.dumps({"segmentation": {"source": "network", "legend": LEGEND + bad}}))


def test_the_run_legend_comes_from_metrics_and_only_well_formed_entries(tmp_path: Path) -> None:
    write_run(tmp_path / "r")
    assert load_run(tmp_path / "r").legend == []  # a run without segmentation figures
    _with_classes(tmp_path / "r")
    data = load_run(tmp_path / "r")
    assert data.legend == LEGEND and set(data.previews[10]) == {"rgb", "classes", "mask", "restored"}


def test_legend_html_names_each_class_in_its_colour_escaped() -> None:
    html = legend_html([*LEGEND, {"name": "<b>x</b>", "colour": "#010203", "dynamic": True}], "Classes")
    assert "background:#c08080" in html and "person" in html and "sofa <small>(not masked)</small>" in html
    assert "&lt;b&gt;x&lt;/b&gt;" in html and "<b>x</b>" not in html
    assert legend_html([]) == ""


def test_the_scene_offers_the_classes_overlay_and_shows_the_legend(tmp_path: Path) -> None:
    write_run(tmp_path / "r")
    _with_classes(tmp_path / "r")
    server = MagicMock()
    build_scene(server, load_run(tmp_path / "r"), "run")
    dropdowns = {c.args[0]: c.args[1] for c in server.gui.add_dropdown.call_args_list}
    assert dropdowns["Overlay"] == ("rgb", "classes", "mask", "restored")
    assert "background:#c08080" in server.gui.add_html.call_args.args[0]


def test_the_live_frame_gets_the_legend_of_its_classes(tmp_path: Path) -> None:
    d = tmp_path / "job"
    d.mkdir()
    (d / artifacts.PARTIAL_STATE).write_text(json.dumps({"frames": 3, "frame_legend": LEGEND[:1]}))
    cv2.imwrite(str(d / artifacts.PARTIAL_FRAME_MASK), np.full((48, 64, 3), 90, np.uint8))
    assert frame_legend(d) == LEGEND[:1]
    server = MagicMock()
    live = LiveScene(server, d, "job")
    live._redraw()
    assert "coloured by class" in server.gui.add_image.call_args.kwargs["label"]
    html = server.gui.add_html.call_args.args[0]
    assert "person" in html and "sofa" not in html  # only the classes in that frame
    (d / artifacts.PARTIAL_STATE).write_text("{broken")
    assert frame_legend(d) == []
