"""Batches: sequences x presets in one request, status, comparison table as JSON and CSV."""
from __future__ import annotations

import csv
import io

import pytest

from tests.backend.api.conftest import finish_with_metrics, upload
from tests.backend.api.data import tar_gz, write_sequence


@pytest.fixture
def seqs(client, seq_tgz):
    return [upload(client, seq_tgz, name=f"s{i}", allow_duplicate=True).json()["id"] for i in range(2)]


def test_create_get_and_table(client, settings, queue, seqs):
    r = client.post("/api/v1/batches", json={"sequence_ids": seqs, "presets": ["orb-only"], "name": "ablation"})
    assert r.status_code == 201, r.text
    batch = r.json()
    assert batch["status"] == "queued" and batch["counts"] == {"queued": 2} and len(batch["jobs"]) == 2
    assert sorted(queue.ids) == sorted(j["id"] for j in batch["jobs"])
    first = batch["jobs"][0]["id"]
    finish_with_metrics(settings, {first: {"ate": {"rmse": 0.012}, "rpe": {"trans": {"rmse": 0.004},
                                                                         "rot": {"rmse": 0.25}}, "fps": 22.5}})
    got = client.get(f"/api/v1/batches/{batch['id']}").json()
    assert got["status"] == "running" and got["counts"] == {"succeeded": 1, "queued": 1}
    table = client.get(f"/api/v1/batches/{batch['id']}/table").json()
    assert [(row["sequence_name"], row["preset"], row["ate_rmse"]) for row in table] == [
        ("s0", "orb-only", 0.012), ("s1", "orb-only", None)]
    r = client.get(f"/api/v1/batches/{batch['id']}/table?format=csv")
    assert r.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(r.text)))
    assert rows[0]["rpe_rot_rmse_deg"] == "0.25" and rows[0]["fps"] == "22.5" and rows[1]["ate_rmse_m"] == ""
    assert list(rows[0])[5:8] == ["ate_rmse_m", "rpe_trans_rmse_m", "rpe_rot_rmse_deg"]  # units in the header
    assert "ate_rmse" in client.get(f"/api/v1/batches/{batch['id']}/table").json()[0]  # the JSON keeps its keys
    listed = client.get("/api/v1/batches").json()
    assert [b["id"] for b in listed["items"]] == [batch["id"]]


@pytest.mark.parametrize("body, status", [
    ({"sequence_ids": ["nope"], "presets": ["orb-only"]}, 404),
    ({"sequence_ids": "SEQS", "presets": ["orb-only", "hyperdrive"]}, 422),
    ({"sequence_ids": [], "presets": ["orb-only"]}, 422),
    ({"sequence_ids": "SEQS", "presets": []}, 422),
    ({"sequence_ids": "SEQS"}, 422),
    ({"sequence_ids": "SEQS", "presets": ["orb-only"], "bogus": True}, 422),
])
def test_bad_batches_leave_nothing(client, queue, seqs, body, status):
    body = {k: (seqs if v == "SEQS" else v) for k, v in body.items()}
    r = client.post("/api/v1/batches", json=body)
    assert r.status_code == status, r.text
    assert "error" in r.json()
    assert client.get("/api/v1/batches").json()["items"] == []
    assert client.get("/api/v1/jobs").json()["total"] == 0 and queue.ids == []


def test_unknown_batch_and_bad_format(client, seqs):
    assert client.get("/api/v1/batches/nope").status_code == 404
    assert client.get("/api/v1/batches/nope/table").status_code == 404
    batch = client.post("/api/v1/batches", json={"sequence_ids": seqs, "presets": ["orb-only"]}).json()
    r = client.get(f"/api/v1/batches/{batch['id']}/table?format=xlsx")
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_input"


def test_named_batch_and_truth_scores_in_the_table(client, settings, seqs):
    batch = client.post("/api/v1/batches", json={"sequence_ids": seqs[:1], "presets": ["full", "orb-only"],
                                                 "name": "truth check"}).json()
    assert batch["name"] == "truth check"
    assert [b["name"] for b in client.get("/api/v1/batches").json()["items"]] == ["truth check"]
    full, orb = (j["id"] for j in batch["jobs"])
    finish_with_metrics(settings, {
        full: {"ate": {"rmse": 0.01}, "relocalisations": 2,
               "culling": {"truth": {"mask_iou": 0.61, "feature_precision": 0.9, "feature_recall": 0.4}},
               "restoration": {"truth": {"restoration_psnr": 24.5}}},
        orb: {"ate": {"rmse": 0.03}, "relocalisations": 0},
    })
    table = {r["preset"]: r for r in client.get(f"/api/v1/batches/{batch['id']}/table").json()}
    assert (table["full"]["mask_iou"], table["full"]["feature_precision"], table["full"]["feature_recall"],
            table["full"]["restoration_psnr"], table["full"]["relocalisations"]) == (0.61, 0.9, 0.4, 24.5, 2)
    assert (table["orb-only"]["mask_iou"], table["orb-only"]["restoration_psnr"],
            table["orb-only"]["relocalisations"]) == (None, None, 0)
    rows = list(csv.DictReader(io.StringIO(client.get(f"/api/v1/batches/{batch['id']}/table?format=csv").text)))
    assert rows[0]["restoration_psnr_db"] == "24.5" and rows[1]["mask_iou"] == ""


def test_marker_ground_truth_is_labelled_in_the_table_and_csv(client, settings, seqs):
    """A Bonn run: ATE in the published convention and corrected, RPE per second and per frame against the
    camera's ground truth, each with what it was measured against."""
    batch = client.post("/api/v1/batches", json={"sequence_ids": seqs[:1], "presets": ["full"]}).json()
    job_id = batch["jobs"][0]["id"]
    corrected = "camera (corrected from bonn-marker)"
    blob = {"ate": {"rmse": 0.016}, "rpe": {"mode": "fixed-delta", "delta_s": 1.0, "trans": {"rmse": 0.0207},
                                             "rot_deg": {"rmse": 0.59}},
            "groundtruth_frame": "bonn-marker", "ate_against": "bonn-marker (raw ground truth, published convention)",
            "ate_corrected_against": corrected, "rpe_against": corrected, "ate_corrected": {"rmse": 0.0164},
            "rpe_frame": {"mode": "fixed-frames", "delta_frames": 1, "trans": {"rmse": 0.0117},
                          "rot_deg": {"rmse": 0.366}}}
    finish_with_metrics(settings, {job_id: blob})
    row = client.get(f"/api/v1/batches/{batch['id']}/table").json()[0]
    assert (row["ate_rmse"], row["ate_corrected_rmse"], row["rpe_trans_rmse"], row["rpe_frame_trans_rmse"],
            row["rpe_frame_rot_rmse"]) == (0.016, 0.0164, 0.0207, 0.0117, 0.366)
    assert row["groundtruth_frame"] == "bonn-marker" and row["rpe_against"] == corrected
    assert "published convention" in row["ate_against"] and row["ate_corrected_against"] == corrected
    csv_row = next(csv.DictReader(io.StringIO(client.get(f"/api/v1/batches/{batch['id']}/table?format=csv").text)))
    assert csv_row["ate_corrected_rmse_m"] == "0.0164" and csv_row["rpe_against"] == corrected
    assert csv_row["rpe_frame_rot_rmse_deg"] == "0.366" and csv_row["groundtruth_frame"] == "bonn-marker"
    job = client.get(f"/api/v1/jobs/{job_id}").json()  # the api hands the labelled blob on as it is
    assert job["metrics"]["rpe_against"] == corrected and job["metrics"]["ate_corrected"]["rmse"] == 0.0164


def test_sequences_say_what_their_ground_truth_is_the_pose_of(client, seq_tgz, tmp_path):
    """The camera says it: the bonn preset, explicit intrinsics, or the folder's camera.json (which wins)."""
    plain = tar_gz(write_sequence(tmp_path / "bonn_like", n=6, camera_json=False), tmp_path / "b.tgz",
                   top="bonn_like").read_bytes()
    bonn = upload(client, plain, camera="bonn", allow_duplicate=True).json()
    tum = upload(client, plain, camera="tum3", allow_duplicate=True).json()
    explicit = upload(client, plain, allow_duplicate=True, camera='{"fx": 542.8, "fy": 542.6, "cx": 315.6, '
                      '"cy": 237.8, "groundtruth_frame": "bonn-marker"}').json()
    own_file = upload(client, seq_tgz, camera="bonn", allow_duplicate=True).json()  # its camera.json says camera
    assert (bonn["groundtruth_frame"], tum["groundtruth_frame"], explicit["groundtruth_frame"],
            own_file["groundtruth_frame"]) == ("bonn-marker", "camera", "bonn-marker", "camera")
    bad = upload(client, plain, allow_duplicate=True, camera='{"fx": 542.8, "fy": 542.6, "cx": 315.6, '
                 '"cy": 237.8, "groundtruth_frame": "tripod"}')
    assert bad.status_code == 422 and "groundtruth_frame" in bad.json()["error"]["message"]
