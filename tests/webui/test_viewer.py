import json
import threading
import urllib.request

import cv2
import numpy as np
import pytest

from storage.artifacts import ArtifactStore
from storage.errors import NotFound
from webui.viewer.hub import HubConfig, ViewerHub, serve_hub
from webui.viewer.run_data import load_run, read_ply
from webui.viewer.scene import error_colors


def write_run(d, n=50, with_extras=True):
    d.mkdir(parents=True)
    t = np.arange(n) / 30
    pos = np.stack([np.cos(t), np.zeros(n), np.sin(t)], 1)
    rows = np.hstack([t[:, None], pos, np.tile([0, 0, 0, 1.0], (n, 1))])
    np.savetxt(d / "trajectory.txt", rows, header="t tx ty tz qx qy qz qw")
    if not with_extras:
        return
    np.savetxt(d / "groundtruth_aligned.txt", rows + [0, 0.01, 0, 0, 0, 0, 0, 0])
    np.savetxt(d / "keyframes.txt", rows[::10])
    pts = np.random.default_rng(0).normal(size=(1000, 3)).astype(np.float32)
    vert = np.zeros(1000, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"),
                                 ("blue", "u1")])
    vert["x"], vert["y"], vert["z"] = pts.T
    vert["red"] = 200
    header = ("ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\nproperty float y\n"
              "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    (d / "map.ply").write_bytes(header.encode() + vert.tobytes())
    (d / "frame_stats.csv").write_text("frame_index,timestamp,ate_error\n" +
                                       "".join(f"{i},{t[i]:.6f},{0.001 * i}\n" for i in range(n)))
    for kind in ("rgb", "mask", "restored"):
        cv2.imwrite(str(d / f"frame_000010_{kind}.jpg"), np.full((48, 64, 3), 100, np.uint8))


def test_load_run_reads_every_artifact(tmp_path):
    write_run(tmp_path / "r")
    data = load_run(tmp_path / "r")
    assert len(data.trajectory.positions) == 50 and data.groundtruth is not None
    assert data.points.shape == (1000, 3) and data.colors[0].tolist() == [200, 0, 0]
    assert data.ate_error[10] == pytest.approx(0.01) and set(data.previews[10]) == {"rgb", "mask", "restored"}
    assert np.allclose(data.trajectory.wxyz[0], [1, 0, 0, 0])  # TUM qx qy qz qw -> viser wxyz


def test_missing_run_is_not_found(tmp_path):
    with pytest.raises(NotFound):
        load_run(tmp_path / "nothing")


def test_error_colours_go_green_to_red():
    c = error_colors(np.array([0.0, 0.5, 1.0, np.nan]), 4)
    assert c[0, 1] > c[0, 0] and c[2, 0] > c[2, 1] and c[3].tolist() == [40, 90, 220]


def test_hub_serves_a_run_and_reuses_its_server(tmp_path):
    store = ArtifactStore(tmp_path)
    write_run(store.job_dir("a" * 32))
    write_run(store.job_dir("b" * 32), with_extras=False)
    hub = ViewerHub(store, HubConfig(port=0, max_servers=1))
    try:
        port = hub.open_run("a" * 32)
        assert hub.open_run("a" * 32) == port
        page = urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10).read()
        assert b"<html" in page.lower()
        hub.open_run("b" * 32)  # capacity 1: the idle server of run a is stopped
        assert hub.runs() == ["b" * 32]
        with pytest.raises(NotFound):
            hub.open_run("c" * 32)
    finally:
        hub.stop()


def test_hub_control_api(tmp_path):
    import socket

    store = ArtifactStore(tmp_path)
    write_run(store.job_dir("a" * 32))
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    hub = ViewerHub(store, HubConfig(port=port))
    stop = threading.Event()
    thread = threading.Thread(target=serve_hub, args=(hub, stop), daemon=True)
    thread.start()
    try:
        for _ in range(50):
            try:
                health = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/health", timeout=2).read())
                break
            except OSError:
                threading.Event().wait(0.1)
        assert health["status"] == "ok"
        run = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/runs/{'a' * 32}", timeout=10).read())
        assert run["port"] > 0
        with pytest.raises(urllib.error.HTTPError) as err:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/runs/{'c' * 32}", timeout=10)
        assert err.value.code == 404
    finally:
        stop.set()
        thread.join(5)
