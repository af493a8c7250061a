from pathlib import Path

import pytest

from formats.errors import FormatError
from formats.frame_stats import (
    PIPELINE_COLUMNS,
    STORED_COLUMNS,
    FrameStats,
    format_frame_stats,
    load_frame_stats,
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


def test_typed_rows_read_either_naming_and_csv_strings(tmp_path: Path):
    pipeline = FrameStats.from_row({"frame_index": 3, "timestamp": 2.0, "tracked": False, "features": 500,
                                    "features_removed": 7, "ate_error": 0.01})
    stored = FrameStats.from_row({"frame_index": 3, "timestamp": 2.0, "tracked": False, "n_features": 500,
                                  "n_dynamic_removed": 7, "ate_error": 0.01})
    assert pipeline == stored == FrameStats(3, 2.0, False, 500, 7, 0.01)
    write_frame_stats(tmp_path / "f.csv", [{"frame_index": 0, "timestamp": 1.5, "tracked": False, "features": 9},
                                           {"frame_index": 1, "timestamp": 1.6, "tracked": True, "ate_error": 0.2}])
    assert load_frame_stats(tmp_path / "f.csv") == [FrameStats(0, 1.5, False, 9), FrameStats(1, 1.6, True, 0, 0, 0.2)]
    assert FrameStats.from_row({"frame_index": "2", "timestamp": "1", "ate_error": "nan"}).ate_error is None
    for bad in ({"timestamp": 1.0}, {"frame_index": 1.5, "timestamp": 1.0}, {"frame_index": 0, "timestamp": "x"},
                {"frame_index": 0, "timestamp": 0, "n_features": "many"}):
        with pytest.raises(FormatError):
            FrameStats.from_row(bad)
