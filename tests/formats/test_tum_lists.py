from pathlib import Path

import pytest

from formats.errors import FormatError
from formats.tum_lists import MAX_LIST_LINES, ListEntry, parse_list, read_list


def test_parses_sorted_entries_with_comments_and_lines():
    text = "# colour images\n\n2.5 rgb/b.png\n1.0 ./rgb/a.png extra\n"
    assert parse_list(text) == [ListEntry(1.0, "rgb/a.png", 4), ListEntry(2.5, "rgb/b.png", 3)]


@pytest.mark.parametrize(("text", "message", "line"), [
    ("1.0\n", "expected 'timestamp filename'", 1),
    ("# x\nabc rgb/a.png\n", "is not a number", 2),
    ("nan rgb/a.png\n", "not finite", 1),
    ("1.0 /etc/passwd\n", "must be relative", 1),
    ("1.0 ../x.png\n", "must be relative", 1),
    ("1.0 rgb\\a.png\n", "must be relative", 1),
    ("# only a comment\n", "lists no frames", None),
])
def test_malformed_lists_name_the_line(text, message, line):
    with pytest.raises(FormatError, match=message) as info:
        parse_list(text, "rgb.txt")
    assert info.value.line == line
    assert str(info.value).startswith("rgb.txt:")


def test_too_many_lines_is_refused():
    with pytest.raises(FormatError, match=f"at most {MAX_LIST_LINES}"):
        parse_list("1.0 a.png\n" * (MAX_LIST_LINES + 1))


def test_read_list_missing_and_not_utf8(tmp_path: Path):
    with pytest.raises(FormatError, match="missing"):
        read_list(tmp_path / "rgb.txt")
    (tmp_path / "rgb.txt").write_bytes(b"1.0 \xff.png\n")
    with pytest.raises(FormatError, match="not UTF-8"):
        read_list(tmp_path / "rgb.txt")


@pytest.mark.parametrize(("text", "line"), [
    ("1.0 rgb/a.png\n1.0 rgb/b.png\n", 2),
    ("# x\n2.0 rgb/a.png\n1.0 rgb/b.png\n2.0 rgb/c.png\n", 4),
    ("100000000000000000.1 rgb/a.png\n100000000000000000.2 rgb/b.png\n", 2),  # 1e17 + t: equal in float64
])
def test_repeated_timestamps_are_refused_naming_the_line(text, line):
    """Issue 60.6: equal timestamps made a sequence of duration 0 and a run nothing can evaluate."""
    with pytest.raises(FormatError, match="strictly increase") as info:
        parse_list(text, "depth.txt")
    assert info.value.line == line and str(info.value).startswith(f"depth.txt:{line}:")
