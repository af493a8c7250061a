"""`vtdslam eval GROUNDTRUTH ESTIMATE --plot DIR` writes the figures of any two TUM files."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from formats import artifacts

ROOT = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("VTD_SHARED_DIR", Path(__file__).resolve().parents[3] / "shared"))  # ../shared
TRAJECTORIES = SHARED / "data" / "trajectories" / "tum_fr1_xyz"


@pytest.mark.skipif(not (TRAJECTORIES / "groundtruth.txt").is_file(), reason="shared TUM trajectories absent")
def test_eval_plot_writes_the_figures_of_two_tum_files(tmp_path: Path) -> None:
    cmd = [sys.executable, "-c", "from cli.main import main; main()", "eval", str(TRAJECTORIES / "groundtruth.txt"),
           str(TRAJECTORIES / "rgbdslam_estimate.txt"), "--json", "--rpe-mode", "fixed-delta",
           "--plot", str(tmp_path / "figs")]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done
    assert json.loads(done.stdout)["matched_poses"] > 100  # stdout stays JSON; the figures are named on stderr
    for name in (artifacts.PLOT_TRAJECTORY_TOP, artifacts.PLOT_XYZ, artifacts.PLOT_ATE_ERROR):
        data = (tmp_path / "figs" / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000, name
        assert name in done.stderr
    assert not (tmp_path / "figs" / artifacts.PLOT_TIMINGS).exists()  # two files hold no stage timings
