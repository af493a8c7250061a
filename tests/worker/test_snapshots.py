"""An ordinary (offline) job writes partial results while it runs (issue 61 part 3): the map and trajectory so far
grow from snapshot to snapshot, and the snapshot files are gone once the job's final artifacts are in place."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from formats import artifacts
from formats.ply import read_ply
from storage.models import JobStatus
from storage.repositories import jobs, sequences
from storage.settings import get_settings
from tests.backend.api.data import write_sequence
from worker import tasks
from worker.consumer import build_context
from worker.snapshots import PartialWriter, SnapshotConfig

pytestmark = pytest.mark.usefixtures("no_vtd_env")  # tests/conftest.py


class Recording(PartialWriter):
    """Keeps what each snapshot held when it was written (the files are removed at the end)."""

    seen: list[tuple[int, int, int]] = []  # (frames, poses in partial_trajectory.txt, points in partial_map.ply)

    def _write(self, snap) -> None:  # noqa: ANN001
        super()._write(snap)
        d = self.store.job_dir(self.job_id)
        poses = len((d / artifacts.PARTIAL_TRAJECTORY).read_text().splitlines())
        Recording.seen.append((snap.frames, poses, len(read_ply(d / artifacts.PARTIAL_MAP)[0])))


def test_an_offline_job_shows_its_run_so_far(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    settings = get_settings(data_dir=tmp_path / "data")
    # every frame's snapshot, written on the pipeline thread: none skipped
    ctx = build_context(settings, name="w1", snapshots=SnapshotConfig(interval_s=0.0, background=False))
    folder = write_sequence(tmp_path / "seq", n=24)
    monkeypatch.setattr(tasks, "PartialWriter", Recording)
    Recording.seen = []
    with ctx.session_factory() as s:
        seq = sequences.create(s, name="seq", path=str(folder), frames=24,
                               camera=json.loads((folder / "camera.json").read_text()))
        job = jobs.create(s, sequence_id=seq.id, preset="orb-only")
    assert tasks.execute_job(ctx, job.id) == JobStatus.SUCCEEDED
    frames = [f for f, _, _ in Recording.seen]
    assert frames == list(range(1, 25))  # a snapshot after every frame (interval 0)
    poses = [p for _, p, _ in Recording.seen]
    points = [n for _, _, n in Recording.seen]
    assert poses[-1] > poses[0] and all(b >= a for a, b in zip(poses, poses[1:]))
    assert points[-1] > points[0]  # the map grew while the job ran
    names = {p.name for p in ctx.store.job_dir(job.id).iterdir()}
    assert set(artifacts.PIPELINE_OUTPUTS) <= names and not names & set(artifacts.PARTIALS)
    on_disk = json.loads((ctx.store.job_dir(job.id) / artifacts.METRICS).read_text())
    assert "snapshots" in on_disk["timings_ms"]  # what they cost the pipeline thread is on record


def test_a_failed_snapshot_never_fails_the_job(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog) -> None:
    settings = get_settings(data_dir=tmp_path / "data")
    ctx = build_context(settings, name="w1", snapshots=SnapshotConfig(interval_s=0.0))
    folder = write_sequence(tmp_path / "seq", n=8)

    def broken(self, snap) -> None:  # noqa: ANN001
        raise OSError("disk gone")

    monkeypatch.setattr(PartialWriter, "_write", broken)
    with ctx.session_factory() as s:
        seq = sequences.create(s, name="seq", path=str(folder), frames=8,
                               camera=json.loads((folder / "camera.json").read_text()))
        job = jobs.create(s, sequence_id=seq.id, preset="orb-only")
    assert tasks.execute_job(ctx, job.id) == JobStatus.SUCCEEDED
    assert "partial results not written: OSError: disk gone" in caplog.text
    with ctx.session_factory() as s:
        stored = jobs.get(s, job.id).metrics
        assert stored is not None and "partial results not written: OSError: disk gone" in stored.metrics["warnings"]
    on_disk = json.loads((ctx.store.job_dir(job.id) / artifacts.METRICS).read_text())
    assert "partial results not written: OSError: disk gone" in on_disk["warnings"]


def test_the_current_frame_is_coloured_by_class_with_its_legend(tmp_path: Path) -> None:
    import cv2
    import numpy as np

    from formats.class_palette import class_colour
    from storage.artifacts import ArtifactStore
    from worker.slam.stages import ClassLabels
    from worker.snapshots import _Snapshot

    writer = PartialWriter(ArtifactStore(tmp_path), "job1", SnapshotConfig(background=False))
    rgb = np.full((60, 80, 3), 120, np.uint8)
    labels = np.zeros((60, 80), np.uint8)
    labels[10:50, 10:40] = 1  # a dog
    labels[10:50, 50:70] = 2  # a sofa: seen, not masked
    seg = ClassLabels(labels, ("background", "dog", "sofa"), ("dog",))
    snap = _Snapshot(1, [], [], [], [], [], None, rgb, labels == 1, np.zeros((60, 80), bool), seg)
    writer._write_images(snap)
    writer.write_state()
    d = writer.store.job_dir("job1")
    state = json.loads((d / artifacts.PARTIAL_STATE).read_text())
    assert [(e["name"], e["dynamic"]) for e in state["frame_legend"]] == [("dog", True), ("sofa", False)]
    bgr = cv2.imread(str(d / artifacts.PARTIAL_FRAME_MASK))
    assert bgr is not None
    img = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB).astype(int)
    dog, sofa = np.array(class_colour("dog")), np.array(class_colour("sofa"))
    assert np.abs(img[30, 25] - (0.45 * 120 + 0.55 * dog)).max() < 8  # strongly tinted in the dog's colour
    assert np.abs(img[30, 60] - (0.8 * 120 + 0.2 * sofa)).max() < 8  # faintly in the sofa's
    assert np.abs(img[5, 5] - 120).max() < 4  # background as it was
