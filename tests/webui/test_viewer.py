import json
import socket
import threading
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.api.pages import include_dashboard
from backend.app import create_app
from storage.artifacts import ArtifactStore
from storage.errors import NotFound
from storage.settings import get_settings
from tests.backend.api.data import tar_gz, write_sequence
from webui.viewer.hub import KEY_HEADER, HubConfig, ViewerHub, serve_hub
from webui.viewer.run_data import load_run
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


def test_a_run_with_lost_frames_maps_poses_to_frames_by_timestamp(tmp_path):
    """trajectory.txt holds only tracked frames: pose k is not frame k; an empty keyframes.txt is no error."""
    write_run(tmp_path / "r")
    d = tmp_path / "r"
    rows = np.loadtxt(d / "trajectory.txt")
    np.savetxt(d / "trajectory.txt", np.delete(rows, [3, 4], axis=0))  # frames 3 and 4 were lost
    (d / "keyframes.txt").write_text("# VTD-SLAM keyframes T_WC\n")
    data = load_run(d)
    assert len(data.trajectory.positions) == 48 and data.keyframes is None
    assert data.frame_index is not None and data.frame_index[:4].tolist() == [0, 1, 2, 5]
    assert data.ate_error[3] == pytest.approx(0.005)  # frame 5's, by timestamp


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
        run = hub.open_run("a" * 32)
        assert hub.open_run("a" * 32) == run
        page = urllib.request.urlopen(f"http://127.0.0.1:{run.port}/", timeout=10).read()
        assert b"<html" in page.lower()
        hub.open_run("b" * 32)  # capacity 1: the idle server of run a is stopped
        assert hub.runs() == ["b" * 32]
        with pytest.raises(NotFound):
            hub.open_run("c" * 32)
    finally:
        hub.stop()


def _refused(host: str, port: int) -> bool:
    try:
        socket.create_connection((host, port), timeout=2).close()
    except ConnectionRefusedError:
        return True
    return False


def test_run_servers_bind_the_hubs_host(tmp_path):
    """One host setting for every server: a run server on 127.0.0.2 is not on 127.0.0.1 (and vice versa)."""
    store = ArtifactStore(tmp_path)
    write_run(store.job_dir("a" * 32), with_extras=False)
    hub = ViewerHub(store, HubConfig(host="127.0.0.2", port=0))
    try:
        run = hub.open_run("a" * 32)
        assert run.host == "127.0.0.2"
        assert b"<html" in urllib.request.urlopen(f"http://127.0.0.2:{run.port}/", timeout=10).read().lower()
        assert _refused("127.0.0.1", run.port)
    finally:
        hub.stop()


def test_with_a_key_run_servers_bind_loopback_only(tmp_path):
    """viser has no auth: with a token set its servers are reachable only through the api's proxy."""
    store = ArtifactStore(tmp_path)
    write_run(store.job_dir("a" * 32), with_extras=False)
    hub = ViewerHub(store, HubConfig(host="127.0.0.2", port=0, key="secret"))
    try:
        run = hub.open_run("a" * 32)
        assert run.host == "127.0.0.1"
        assert _refused("127.0.0.2", run.port)
    finally:
        hub.stop()


@contextmanager
def running_hub(store: ArtifactStore, key: str | None = None, client_timeout_s: float = 10.0) -> Iterator[int]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    hub = ViewerHub(store, HubConfig(port=port, key=key, client_timeout_s=client_timeout_s))
    stop = threading.Event()
    thread = threading.Thread(target=serve_hub, args=(hub, stop), daemon=True)
    thread.start()
    try:
        for _ in range(50):
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}/health", timeout=2).close()
                break
            except OSError:
                threading.Event().wait(0.1)
        yield port
    finally:
        stop.set()
        thread.join(5)


def _get(url: str, headers: dict[str, str] | None = None) -> tuple[int, dict, dict]:
    try:
        with urllib.request.urlopen(urllib.request.Request(url, headers=headers or {}), timeout=10) as resp:
            return resp.status, dict(resp.headers), json.loads(resp.read())
    except urllib.error.HTTPError as exc:
        return exc.code, dict(exc.headers), json.loads(exc.read())


def test_hub_control_api(tmp_path):
    store = ArtifactStore(tmp_path)
    write_run(store.job_dir("a" * 32))
    with running_hub(store) as port:
        status, headers, run = _get(f"http://127.0.0.1:{port}/runs/{'a' * 32}")
        assert status == 200 and run["port"] > 0 and run["host"] == "127.0.0.1"
        status, headers, health = _get(f"http://127.0.0.1:{port}/health")
        # no run ids for anyone who asks, and no CORS header: browsers never call the hub
        assert status == 200 and health == {"status": "ok"}
        assert "access-control-allow-origin" not in {k.lower() for k in headers}
        status, _, body = _get(f"http://127.0.0.1:{port}/runs/{'c' * 32}")
        assert status == 404 and body["error"]["code"] == "not_found"


def test_hub_with_a_key_opens_runs_for_the_key_only(tmp_path):
    store = ArtifactStore(tmp_path)
    write_run(store.job_dir("a" * 32), with_extras=False)
    with running_hub(store, key="k" * 64) as port:
        url = f"http://127.0.0.1:{port}/runs/{'a' * 32}"
        assert _get(url)[0] == 403
        assert _get(url, {KEY_HEADER: "wrong"})[0] == 403
        status, _, run = _get(url, {KEY_HEADER: "k" * 64})
        assert status == 200 and run["port"] > 0


def test_hub_drops_silent_clients_and_refuses_huge_headers(tmp_path):
    with running_hub(ArtifactStore(tmp_path), client_timeout_s=0.5) as port:
        with socket.create_connection(("127.0.0.1", port), timeout=10) as silent:
            silent.sendall(b"GET /health HTTP/1.1\r\n")  # ...and never finishes its headers
            assert silent.recv(1024) == b""  # closed by the hub, not by our 10 s timeout
        with socket.create_connection(("127.0.0.1", port), timeout=10) as greedy:
            greedy.sendall(b"GET /health HTTP/1.1\r\nX-Big: " + b"a" * 70_000 + b"\r\n\r\n")
            assert greedy.recv(1024).startswith(b"HTTP/1.0 431")


# ---------- the api's same-origin proxy, against a real hub and viser ----------

@pytest.fixture
def seq_tgz(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    folder = write_sequence(tmp_path_factory.mktemp("seq") / "rgbd_dataset_view", n=3)
    return tar_gz(folder, tmp_path_factory.mktemp("arch") / "seq.tgz", top="rgbd_dataset_view").read_bytes()


@contextmanager
def proxied_run(tmp_path, seq_tgz: bytes, token: str | None = None) -> Iterator[tuple[TestClient, str]]:
    """An api (TestClient) in front of a real hub, with one job whose run artifacts exist."""
    settings = get_settings(data_dir=tmp_path / "data", api_token=token)
    store = ArtifactStore(settings.data_dir)
    with running_hub(store, settings.viewer_hub_key) as hub_port:
        app = create_app(settings.model_copy(update={"viewer_port": hub_port}), enqueue=lambda job_id: None)
        include_dashboard(app)
        auth = {"Authorization": f"Bearer {token}"} if token else {}
        with TestClient(app) as client:
            r = client.post("/api/v1/sequences", files={"file": ("s.tgz", seq_tgz, "application/gzip")},
                            data={"camera": "tum1"}, headers=auth)
            assert r.status_code == 201, r.text
            r = client.post("/api/v1/jobs", json={"sequence_id": r.json()["id"], "preset": "orb-only"}, headers=auth)
            assert r.status_code == 201, r.text
            job_id = r.json()["id"]
            write_run(store.job_dir(job_id))
            yield client, job_id


@pytest.mark.parametrize("token", [None, "t0ken"])
def test_the_api_serves_the_runs_viewer_on_its_own_origin(tmp_path, seq_tgz, token):
    import viser

    with proxied_run(tmp_path, seq_tgz, token) as (client, job_id):
        r = client.get(f"/api/v1/jobs/{job_id}/viewer")
        assert r.status_code == 200 and r.json() == {"url": f"/viewer/{job_id}/"}
        page = client.get(f"/viewer/{job_id}/")
        assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
        assert b"<html" in page.content.lower()
        assert client.get(f"/viewer/{job_id}/no-such-asset.js").status_code == 404  # viser's own answer
        r = client.get(f"/viewer/{job_id}", follow_redirects=False)
        assert r.status_code == 307 and r.headers["location"] == f"/viewer/{job_id}/"
        # the scene's socket is on the page's URL without the slash, as viser's client opens it
        protocol = f"viser-v{viser.__version__}"
        with client.websocket_connect(f"/viewer/{job_id}", subprotocols=[protocol]) as ws:
            assert ws.accepted_subprotocol == protocol
            assert len(ws.receive_bytes()) > 16  # viser's framed, compressed scene messages


def test_viewer_socket_from_another_site_is_refused(tmp_path, seq_tgz):
    import viser
    from starlette.websockets import WebSocketDisconnect

    protocol = [f"viser-v{viser.__version__}"]
    with proxied_run(tmp_path, seq_tgz) as (client, job_id):
        with pytest.raises(WebSocketDisconnect) as closed:
            with client.websocket_connect(f"/viewer/{job_id}", subprotocols=protocol,
                                          headers={"origin": "http://evil.example"}) as ws:
                ws.receive_bytes()
        assert closed.value.code == 1008
        with client.websocket_connect(f"/viewer/{job_id}", subprotocols=protocol,
                                      headers={"origin": "http://testserver"}) as ws:
            assert len(ws.receive_bytes()) > 16


def test_viewer_of_an_unknown_job_is_404_through_the_proxy(tmp_path, seq_tgz):
    with proxied_run(tmp_path, seq_tgz) as (client, _):
        r = client.get(f"/viewer/{'f' * 32}/")
        assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"
