from pathlib import Path

import pytest

from formats.errors import FormatError
from formats.frame_stats import (
    PIPELINE_COLUMNS,
    STORED_COLUMNS,
    format_frame_stats,
    read_frame_stats,
    to_stored,
    write_frame_stats,
)


def test_pipeline_columns_first_then_the_rest_sorted(tmp_path: Path):
    rows: list[dict[str, object]] = [
        {"frame_index": 0, "timestamp": 1.5, "tracked": True, "zeta": 1, "alpha": None},
        {"frame_index": 1, "timestamp": 1.6, "tracked": False, "ate_error": 0.01}]
    write_frame_stats(tmp_path / "f.csv", rows)
    raw = (tmp_path / "f.csv").read_bytes()
    assert raw.startswith(",".join([*PIPELINE_COLUMNS, "alpha", "zeta"]).encode() + b"\r\n")
    back = read_frame_stats(tmp_path / "f.csv")
    assert back[0]["alpha"] == "" and back[0]["zeta"] == "1" and back[1]["ate_error"] == "0.01"


def test_stored_rows_rename_and_default():
    row = to_stored({"frame_index": 3, "timestamp": 2.0, "tracked": True, "features": 500, "features_removed": 7})
    assert set(row) == set(STORED_COLUMNS)
    assert (row["n_features"], row["n_dynamic_removed"], row["ate_error"]) == (500, 7, None)
    assert to_stored({"frame_index": 0, "timestamp": 0.0, "tracked": False})["n_features"] == 0


def test_given_columns_drop_other_keys():
    text = format_frame_stats([{"frame_index": 0, "timestamp": 1.0, "extra": 1}], ["frame_index", "timestamp"])
    assert text == "frame_index,timestamp\r\n0,1.0\r\n"


def test_reader_needs_the_key_columns(tmp_path: Path):
    (tmp_path / "f.csv").write_text("a,b\n1,2\n")
    with pytest.raises(FormatError, match="frame_index"):
        read_frame_stats(tmp_path / "f.csv")
