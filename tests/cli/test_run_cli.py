"""`vtdslam run` refuses a stage order the pipeline cannot run with a message and the bad-input exit code."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tests.backend.api.data import write_sequence

ROOT = Path(__file__).resolve().parents[2]


def test_a_wrong_stage_order_is_a_message_and_exit_code_2(tmp_path: Path) -> None:
    seq = write_sequence(tmp_path / "seq", n=3)
    cmd = [sys.executable, "-c", "from cli.main import main; main()", "run", str(seq), "--out", str(tmp_path / "o"),
           "--quiet", "--config", '{"stages": ["restoration"]}']
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done
    assert "error: pipeline stage 'restoration' needs dynamic_mask" in done.stderr
    assert "list 'culling' before 'restoration'" in done.stderr and not (tmp_path / "o").exists()
