"""A failed job's error and log.txt (readable without a token) show no absolute server path: paths below
the data dir become relative to it, any other keeps only its last component."""
from __future__ import annotations

from pathlib import Path

from storage.models import JobStatus
from storage.redact import redact_paths
from storage.repositories import jobs, sequences
from storage.settings import get_settings
from tests.worker.test_tasks import FakePipeline
from worker.consumer import build_context
from worker.tasks import execute_job


def test_job_error_and_log_hold_no_absolute_server_path(tmp_path: Path) -> None:
    settings = get_settings(data_dir=tmp_path / "data")
    data = settings.data_dir.resolve()
    error = FileNotFoundError(2, "No such file", f"{data}/sequences/ab12/rgb/1.png")
    ctx = build_context(settings, name="w1", pipeline=FakePipeline(error=error))
    with ctx.session_factory() as s:
        seq = sequences.create(s, name="s", path="sequences/s", frames=5, camera={"preset": "tum1"})
        job_id = jobs.create(s, sequence_id=seq.id, preset="orb-only").id
    assert execute_job(ctx, job_id) == JobStatus.FAILED
    with ctx.session_factory() as s:
        message = jobs.get(s, job_id).error
    assert message is not None
    log = ctx.store.path(job_id, "log.txt").read_text()
    assert "'sequences/ab12/rgb/1.png'" in message and str(tmp_path) not in message
    assert "sequences/ab12/rgb/1.png" in log and "Traceback" in log
    assert str(tmp_path) not in log and str(Path(__file__).parent) not in log  # traceback source paths too


def test_redact_paths_keeps_relative_text() -> None:
    data = Path("/srv/vtd/data")
    text = 'File "/opt/app/worker/tasks.py", line 3: /srv/vtd/data/sequences/x/rgb.txt: 0.5 m/s, http://h/a/b'
    assert redact_paths(text, data) == 'File "…/tasks.py", line 3: sequences/x/rgb.txt: 0.5 m/s, http://h/a/b'
    assert redact_paths("no paths here: a/b", data) == "no paths here: a/b"
