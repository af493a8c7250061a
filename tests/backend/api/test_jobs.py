"""Jobs: create, list with filters and paging, get, cancel, retry, delete, artifacts (types, ranges), SSE."""
from __future__ import annotations

import json

import pytest

from formats import catalog
from storage.artifacts import ArtifactStore
from storage.db import make_engine, make_session_factory
from storage.live import STREAMING_STAGE
from storage.models import Job, JobStatus
from storage.presets import CAMERA_PRESETS, PIPELINE_PRESETS
from storage.repositories import jobs, metrics
from tests.backend.api.conftest import upload

METRICS = {"frames": 6, "fps": 30.0, "tracked": 6, "lost": 0,
           "ate": {"rmse": 0.01, "mean": 0.01, "median": 0.01, "std": 0.0, "max": 0.02},
           "rpe": {"trans": {"rmse": 0.005}, "rot": {"rmse": 0.2}}}


@pytest.fixture
def db(settings):
    engine = make_engine(settings)
    yield make_session_factory(engine)
    engine.dispose()


@pytest.fixture
def seq_id(client, seq_tgz) -> str:
    return upload(client, seq_tgz).json()["id"]


def new_job(client, seq_id, preset="orb-only", **kw):
    r = client.post("/api/v1/jobs", json={"sequence_id": seq_id, "preset": preset, **kw})
    assert r.status_code == 201, r.text
    return r.json()


def complete(db, settings, job_id, status=JobStatus.SUCCEEDED):
    """What a worker does, through the repositories."""
    store = ArtifactStore(settings.data_dir)
    with db() as s:
        assert jobs.claim(s, job_id, "test-worker")
        jobs.update_progress(s, job_id, frames_done=3, frames_total=6, stage="tracking", progress=0.5)
        if status == JobStatus.RUNNING:
            return
        store.write_text(job_id, "trajectory.txt", "# t tx ty tz qx qy qz qw\n100.0 0 0 0 0 0 0 1\n")
        store.write_bytes(job_id, "map.ply", b"ply\n" + bytes(range(256)) * 40)
        store.write_text(job_id, "metrics.json", json.dumps(METRICS))
        store.write_text(job_id, "frames.csv", "frame_index,timestamp\n0,100.0\n")
        metrics.save_run_metrics(s, job_id, METRICS)
        metrics.add_frame_stats(s, job_id, [{"frame_index": i, "timestamp": 100 + i, "tracked": i != 1}
                                            for i in range(6)])
        jobs.finish(s, job_id, status, error=None if status == JobStatus.SUCCEEDED else "boom")


def test_create_get_and_enqueue(client, queue, seq_id):
    job = new_job(client, seq_id, config={"tracking.min_matches": 20})
    assert job["status"] == "queued" and job["config"] == {"tracking.min_matches": 20}
    assert queue.ids == [job["id"]]
    got = client.get(f"/api/v1/jobs/{job['id']}").json()
    assert got["id"] == job["id"] and got["metrics"] is None and got["eta_s"] is None


def test_preset_defaults_to_full(client, queue, seq_id):
    r = client.post("/api/v1/jobs", json={"sequence_id": seq_id})
    assert r.status_code == 201, r.text
    assert r.json()["preset"] == "full" and queue.ids == [r.json()["id"]]


@pytest.mark.parametrize("body, status, code", [
    ({"sequence_id": "nope", "preset": "orb-only"}, 404, "not_found"),
    ({"sequence_id": "SEQ", "preset": "warp-drive"}, 422, "invalid_input"),
    ({"sequence_id": "SEQ", "preset": ""}, 422, "invalid_input"),
    ({"sequence_id": "SEQ", "preset": "orb-only", "config": [1, 2]}, 422, "invalid_input"),
    ({"sequence_id": "SEQ", "preset": "orb-only", "extra": 1}, 422, "invalid_input"),
    ({"sequence_id": "SEQ", "preset": "orb-only", "config": {"x": "y" * 70000}}, 422, "invalid_input"),
])
def test_bad_job_requests_leave_no_job(client, queue, seq_id, body, status, code):
    body = {k: (seq_id if v == "SEQ" else v) for k, v in body.items()}
    r = client.post("/api/v1/jobs", json=body)
    assert r.status_code == status, r.text
    assert r.json()["error"]["code"] == code
    assert client.get("/api/v1/jobs").json()["total"] == 0 and queue.ids == []


@pytest.mark.parametrize("config, fields", [
    ({"features": {"min_depth_m": 7.0}}, ("features.min_depth_m", "features.max_depth_m")),
    ({"tracking.keyframe_min_frames": 30, "tracking.keyframe_max_frames": 20},
     ("tracking.keyframe_min_frames", "tracking.keyframe_max_frames")),
    ({"culling": {"culling": {"threshold": {"d_min": 5.0, "d_max": 4.0}}}},
     ("culling.culling.threshold.d_min", "culling.culling.threshold.d_max")),
    ({"restoration.selection.max_refs": 1}, ("restoration.selection.min_refs", "restoration.selection.max_refs")),
])
def test_a_config_whose_ranges_contradict_each_other_is_422_naming_both(client, queue, seq_id, config, fields):
    for path, body in (("/api/v1/jobs", {"sequence_id": seq_id, "preset": "full", "config": config}),
                       ("/api/v1/batches", {"sequence_ids": [seq_id], "presets": ["full"], "config": config})):
        r = client.post(path, json=body)
        assert r.status_code == 422, r.text
        err = r.json()["error"]
        assert err["code"] == "invalid_input" and all(f in err["message"] for f in fields), err
        assert err["detail"]["fields"] == list(fields)
    assert client.get("/api/v1/jobs").json()["total"] == 0 and queue.ids == []


@pytest.mark.parametrize("stages, match", [
    (["restoration"], "'restoration' needs dynamic_mask, which no earlier stage provides"),
    (["segmentation", "restoration", "culling"], "'restoration' needs dynamic_mask, which 'culling' provides only"),
    (["culling", "segmentation"], "'culling' uses potentially_dynamic, which 'segmentation' provides only after"),
    (["culling", "culling"], "'culling' is listed twice"),
    (["warp"], "unknown pipeline stage 'warp'"),
    ("culling", "stages must be a list of stage names"),
])
def test_a_stage_order_the_pipeline_cannot_run_is_422(client, queue, seq_id, stages, match):
    config = {"stages": stages}
    for path, body in (("/api/v1/jobs", {"sequence_id": seq_id, "preset": "full", "config": config}),
                       ("/api/v1/batches", {"sequence_ids": [seq_id], "presets": ["full"], "config": config})):
        r = client.post(path, json=body)
        assert r.status_code == 422, r.text
        err = r.json()["error"]
        assert err["code"] == "invalid_input" and match in err["message"] and err["detail"], err
    assert client.get("/api/v1/jobs").json()["total"] == 0 and queue.ids == []


def test_every_preset_stage_list_is_accepted(client, queue, seq_id):
    for preset in catalog.PIPELINE_PRESETS:
        r = client.post("/api/v1/jobs", json={"sequence_id": seq_id, "preset": "orb-only",
                                              "config": {"stages": list(preset.stages)}})
        assert r.status_code == 201, r.text
    assert len(queue.ids) == len(catalog.PIPELINE_PRESETS) == 4


def test_queue_down_is_503_and_the_job_is_failed_not_stuck(client, queue, seq_id):
    queue.fail = True
    r = client.post("/api/v1/jobs", json={"sequence_id": seq_id, "preset": "orb-only"})
    assert r.status_code == 503 and r.json()["error"]["code"] == "queue_unavailable"
    job_id = r.json()["error"]["detail"]["job_ids"][0]
    job = client.get(f"/api/v1/jobs/{job_id}").json()
    assert job["status"] == "failed" and "enqueue" in job["error"]


def test_list_filters_and_paging(client, db, settings, seq_id, seq_tgz):
    other = upload(client, seq_tgz, allow_duplicate=True).json()["id"]
    a, b, c = new_job(client, seq_id), new_job(client, seq_id), new_job(client, other)
    complete(db, settings, a["id"])
    assert client.get("/api/v1/jobs").json()["total"] == 3
    assert [j["id"] for j in client.get("/api/v1/jobs?status=succeeded").json()["items"]] == [a["id"]]
    assert client.get(f"/api/v1/jobs?sequence_id={seq_id}").json()["total"] == 2
    page = client.get("/api/v1/jobs?limit=1&offset=1").json()
    assert page["total"] == 3 and [j["id"] for j in page["items"]] == [b["id"]]
    assert client.get("/api/v1/jobs?status=exploded").status_code == 422
    assert client.get("/api/v1/jobs?limit=0").status_code == 422
    assert c["sequence_id"] == other


def test_a_live_job_with_its_stream_open_has_no_eta(client, db, settings, seq_id):
    job = new_job(client, seq_id)
    complete(db, settings, job["id"], JobStatus.RUNNING)  # 3 of 6 frames tracked: an estimate
    assert client.get(f"/api/v1/jobs/{job['id']}").json()["eta_s"] is not None
    with db() as s:  # 3 of the 6 frames received so far: the stream's end, so its time left, is unknown
        jobs.update_progress(s, job["id"], frames_done=3, frames_total=6, stage=STREAMING_STAGE)
    got = client.get(f"/api/v1/jobs/{job['id']}").json()
    assert got["stage"] == "live" and got["eta_s"] is None


def test_running_job_has_progress_and_eta_then_metrics(client, db, settings, seq_id):
    job = new_job(client, seq_id)
    complete(db, settings, job["id"], JobStatus.RUNNING)
    got = client.get(f"/api/v1/jobs/{job['id']}").json()
    assert got["status"] == "running" and got["frames_done"] == 3 and got["stage"] == "tracking"
    assert got["eta_s"] is not None and got["eta_s"] >= 0 and got["run_s"] is None
    with db() as s:  # every frame tracked, the run finishing (dense map, evaluation, saving): no "0 s left"
        jobs.update_progress(s, job["id"], frames_done=6, frames_total=6, stage="saving", progress=0.98)
    got = client.get(f"/api/v1/jobs/{job['id']}").json()
    assert got["status"] == "running" and got["stage"] == "saving" and got["eta_s"] is None
    with db() as s:
        metrics.save_run_metrics(s, job["id"], METRICS)
        jobs.finish(s, job["id"], JobStatus.SUCCEEDED, timings={"tracking": 3.0, "run_ms": 2500.0})
    got = client.get(f"/api/v1/jobs/{job['id']}").json()
    assert got["status"] == "succeeded" and got["metrics"]["ate"]["rmse"] == 0.01 and got["progress"] == 1.0
    assert got["stage"] == "done" and got["eta_s"] is None
    assert got["timings"] == {"tracking": 3.0, "run_ms": 2500.0} and got["run_s"] == 2.5
    rpe = got["metrics"]["rpe"]  # an old spelling (rot) is served as stored, and under today's name (rot_deg) too
    assert rpe["rot"] == {"rmse": 0.2} and rpe["rot_deg"]["rmse"] == 0.2 and rpe["trans"] == {"rmse": 0.005}


def test_cancel_queued_running_and_finished(client, db, settings, seq_id):
    queued = new_job(client, seq_id)
    r = client.post(f"/api/v1/jobs/{queued['id']}/cancel")
    assert r.status_code == 200 and r.json()["status"] == "cancelled"
    running = new_job(client, seq_id)
    complete(db, settings, running["id"], JobStatus.RUNNING)
    r = client.post(f"/api/v1/jobs/{running['id']}/cancel")
    assert r.json()["status"] == "running" and r.json()["cancel_requested"] is True
    done = new_job(client, seq_id)
    complete(db, settings, done["id"])
    r = client.post(f"/api/v1/jobs/{done['id']}/cancel")
    assert r.status_code == 409 and r.json()["error"]["code"] == "conflict"
    assert client.post("/api/v1/jobs/nope/cancel").status_code == 404


def test_retry_requeues_and_drops_old_results(client, db, settings, queue, seq_id):
    job = new_job(client, seq_id)
    assert client.post(f"/api/v1/jobs/{job['id']}/retry").status_code == 409  # still queued
    complete(db, settings, job["id"], JobStatus.FAILED)
    assert client.get(f"/api/v1/jobs/{job['id']}").json()["stage"] == "tracking"  # where it failed, not "done"
    assert client.get(f"/api/v1/jobs/{job['id']}/artifacts").json()
    r = client.post(f"/api/v1/jobs/{job['id']}/retry")
    assert r.status_code == 200, r.text
    assert r.json()["status"] == "queued" and r.json()["attempts"] == 2 and r.json()["metrics"] is None
    assert client.get(f"/api/v1/jobs/{job['id']}/artifacts").json() == []
    assert queue.ids == [job["id"], job["id"]]


def test_delete_removes_row_and_artifacts(client, db, settings, seq_id):
    job = new_job(client, seq_id)
    complete(db, settings, job["id"])
    assert client.delete(f"/api/v1/jobs/{job['id']}").status_code == 204
    assert client.get(f"/api/v1/jobs/{job['id']}").status_code == 404
    assert not (settings.data_dir / "artifacts" / job["id"]).exists()
    assert client.delete(f"/api/v1/jobs/{job['id']}").status_code == 404


def test_artifacts_list_types_and_ranges(client, db, settings, seq_id):
    job = new_job(client, seq_id)
    complete(db, settings, job["id"])
    arts = {a["name"]: a for a in client.get(f"/api/v1/jobs/{job['id']}/artifacts").json()}
    assert set(arts) == {"trajectory.txt", "map.ply", "metrics.json", "frames.csv"}
    assert arts["map.ply"]["content_type"] == "application/x-ply"
    base = f"/api/v1/jobs/{job['id']}/artifacts"
    r = client.get(f"{base}/trajectory.txt")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/plain") and "100.0" in r.text
    assert client.get(f"{base}/metrics.json").json() == METRICS
    assert client.get(f"{base}/frames.csv").headers["content-type"].startswith("text/csv")
    full = client.get(f"{base}/map.ply")
    assert full.headers["accept-ranges"] == "bytes" and "attachment" in full.headers["content-disposition"]
    part = client.get(f"{base}/map.ply", headers={"Range": "bytes=4-19"})
    assert part.status_code == 206 and part.content == full.content[4:20]
    assert part.headers["content-range"] == f"bytes 4-19/{len(full.content)}"
    bad = client.get(f"{base}/map.ply", headers={"Range": f"bytes={10**9}-"})
    assert bad.status_code == 416
    assert client.get(f"{base}/nope.txt").status_code == 404
    assert client.get(f"{base}/.hidden").status_code == 422
    assert client.get(f"{base}/..%2F..%2Fvtdslam.db").status_code in (404, 422)
    assert client.get("/api/v1/jobs/nope/artifacts").status_code == 404
    assert client.get("/api/v1/jobs/nope/artifacts/map.ply").status_code == 404


def _events(client, job_id):
    with client.stream("GET", f"/api/v1/jobs/{job_id}/events?interval=0.1") as r:
        assert r.headers["content-type"].startswith("text/event-stream")
        text = r.read().decode()
    return [block for block in text.split("\n\n") if block.startswith("id:")]


def test_events_stream_progress_then_end(client, db, settings, seq_id):
    job = new_job(client, seq_id)
    complete(db, settings, job["id"])
    events = _events(client, job["id"])
    assert [e.split("\n")[1] for e in events] == ["event: progress", "event: end"]
    data = json.loads(events[0].split("data: ", 1)[1])
    assert data["status"] == "succeeded" and data["metrics"]["fps"] == 30.0
    assert json.loads(events[1].split("data: ", 1)[1]) == {"id": job["id"], "status": "succeeded"}
    r = client.get("/api/v1/jobs/nope/events")
    assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"


def test_events_follow_a_running_job_until_it_ends(client, db, settings, seq_id):
    import threading
    import time

    job = new_job(client, seq_id)
    complete(db, settings, job["id"], JobStatus.RUNNING)

    def finish_later():
        time.sleep(0.4)
        with db() as s:
            jobs.update_progress(s, job["id"], frames_done=6, progress=0.9)
            time.sleep(0.3)
            jobs.finish(s, job["id"], JobStatus.SUCCEEDED)

    t = threading.Thread(target=finish_later)
    t.start()
    events = _events(client, job["id"])
    t.join()
    statuses = [json.loads(e.split("data: ", 1)[1]).get("status") for e in events]
    assert statuses[0] == "running" and statuses[-2:] == ["succeeded", "succeeded"] and len(events) >= 3


def test_frames_and_presets(client, db, settings, seq_id):
    job = new_job(client, seq_id)
    assert client.get(f"/api/v1/jobs/{job['id']}/frames").json()["items"] == []
    complete(db, settings, job["id"])
    page = client.get(f"/api/v1/jobs/{job['id']}/frames?offset=1&limit=2").json()
    assert [(f["frame_index"], f["tracked"]) for f in page["items"]] == [(1, False), (2, True)]
    assert client.get("/api/v1/jobs/nope/frames").status_code == 404
    presets = client.get("/api/v1/presets").json()
    assert presets == {"pipeline": list(PIPELINE_PRESETS), "camera": list(CAMERA_PRESETS)}
    assert "tum1" in presets["camera"]


def test_an_older_jobs_run_s_is_served_in_milliseconds_and_at_the_top(client, db, settings, seq_id):
    job = new_job(client, seq_id)
    complete(db, settings, job["id"])
    with db() as s:  # what workers stored before timings became all milliseconds
        s.get(Job, job["id"]).timings = {"tracking": 3.0, "run_s": 1.25}
        s.commit()
    got = client.get(f"/api/v1/jobs/{job['id']}").json()
    assert got["timings"] == {"tracking": 3.0, "run_ms": 1250.0} and got["run_s"] == 1.25
