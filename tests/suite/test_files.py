"""The suite's file helpers (locbook.suite.files): damaged files read as absent, the atomic write leaves the old
file and no temporary behind on failure, and a point's key is the experiment id and the SHA-256 of its values."""
import hashlib

import pytest

from locbook.suite.files import atomic_write, point_key, read_csv, read_json, write_text_atomic


def test_damaged_or_mistyped_files_read_as_absent(tmp_path):
    (tmp_path / "list.json").write_text("[1, 2]", encoding="utf-8")
    (tmp_path / "bad.json").write_bytes(b"\xff{")
    (tmp_path / "bad.csv").write_bytes(b"a,b\n\xff,1\n")
    assert read_json(tmp_path / "list.json", {}) == {}          # a list where a dict is expected
    assert read_json(tmp_path / "list.json", None) == [1, 2]
    assert read_json(tmp_path / "bad.json", {"x": 1}) == {"x": 1}
    assert read_json(tmp_path / "missing.json", []) == []
    assert read_csv(tmp_path / "bad.csv") == [] and read_csv(tmp_path / "missing.csv") == []


def test_a_failed_atomic_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "table.csv"
    write_text_atomic(path, "old\n")

    def half(tmp):
        tmp.write_text("new, half")
        raise OSError(28, "No space left on device")
    with pytest.raises(OSError):
        atomic_write(path, half)
    assert path.read_text() == "old\n" and sorted(p.name for p in tmp_path.iterdir()) == ["table.csv"]


def test_point_keys_hash_the_sorted_values_and_lengthen_on_a_collision():
    digest = hashlib.sha256(b'{"a": 1, "b": [2.5]}').hexdigest()
    assert point_key("x-y", {"b": [2.5], "a": 1}) == f"x-y-{digest}"
    assert point_key("x-y", {"a": 1, "b": [2.5]}, 10) == f"x-y-{digest[:10]}"
    # the short key already names other values: the point takes all 64 digits
    assert point_key("x-y", {"a": 1, "b": [2.5]}, 10, taken={f"x-y-{digest[:10]}": "other"}) == f"x-y-{digest}"
