"""UTF-8 text of the files locbook reads (readings, manifests, declarations): one decoder, one way to name where a
byte that is not UTF-8 lies."""
from __future__ import annotations

from collections.abc import Callable

__all__ = ["decode_utf8"]


def decode_utf8(data: bytes, fail: Callable[[int, int, int, bytes], None]) -> str:
    """``data`` decoded as UTF-8, a leading byte-order mark (Excel writes one) dropped. At a byte that is not UTF-8,
    ``fail(line, column, offset, line_bytes)`` is called and must raise: ``line`` and ``column`` are 1-based (the
    column in bytes), lines ending at LF, CR or CRLF as the csv reader counts them (a CR-only file has no LF at all),
    ``offset`` the byte's 0-based offset in the file and ``line_bytes`` its line."""
    bom = data.startswith(b"\xef\xbb\xbf")
    try:
        return data[3:].decode("utf-8") if bom else data.decode("utf-8")
    except UnicodeDecodeError as exc:
        offset = exc.start + (3 if bom else 0)
        line_start = max(data.rfind(b"\n", 0, offset), data.rfind(b"\r", 0, offset)) + 1
        ends = [i for i in (data.find(b"\n", offset), data.find(b"\r", offset)) if i >= 0]
        before = data[:offset]
        line = before.count(b"\n") + before.count(b"\r") - before.count(b"\r\n") + 1
        fail(line, offset - line_start + 1, offset, data[line_start:min(ends) if ends else len(data)])
        raise AssertionError("decode_utf8: fail must raise") from None
