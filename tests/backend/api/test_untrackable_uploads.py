"""Uploads the pipeline could never track (frames too small, no valid depth) are a clear 422 that leaves no file
and no row behind, instead of a job that "succeeds" having tracked nothing."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.backend.api.conftest import leftovers, upload
from tests.backend.api.data import tar_gz, write_sequence


def _tiny(tmp_path: Path) -> Path:
    return write_sequence(tmp_path / "tiny", n=5, size=(32, 24), camera_json=False)


def _zero_depth(tmp_path: Path) -> Path:
    folder = write_sequence(tmp_path / "nodepth", n=30)
    for p in (folder / "depth").iterdir():
        cv2.imwrite(str(p), np.zeros((120, 160), np.uint16))
    return folder


@pytest.mark.parametrize(("make", "message"), [
    (_tiny, "images are 32x24; the pipeline needs at least 64x48 pixels"),
    (_zero_depth, "every sampled depth image (5 of 30) is all 0"),
])
def test_untrackable_uploads_are_refused(client, settings, tmp_path, make, message):
    r = upload(client, tar_gz(make(tmp_path), tmp_path / "s.tgz").read_bytes())
    assert r.status_code == 422, r.text
    err = r.json()["error"]
    assert err["code"] == "invalid_input" and message in err["message"]
    assert leftovers(settings) == []
    assert client.get("/api/v1/sequences").json()["total"] == 0
