"""CSV text as the data files' rules read it: the exact reader (every field as text, each row's line as an editor
counts it), number columns, the size limits checked before a file is read, and quoting a file's text in messages
(at most :data:`MAX_QUOTED_CHARS` characters). The leaf of :mod:`locbook.data`: every file reader builds on it
(:mod:`locbook.data.measured` documents the files)."""
from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pandas as pd

from .._text import decode_utf8
from ..errors import LocbookError

__all__ = ["DataFormatError", "MAX_COORDINATE_M", "MAX_LINE_BYTES", "MAX_EXACT_READ_BYTES",
           "EXACT_READER_BYTES_PER_BYTE", "MAX_QUOTED_CHARS", "MISSING_TEXT", "shown", "shown_names", "size_text",
           "check_line_lengths", "decode_file_text", "read_text_table", "numeric_column", "file_lines", "seconds_text"]

#: anchor, outline, path and true-position coordinates of this magnitude (m) or more are refused: no site is larger
#: (projected map coordinates, e.g. UTM northings, stay below 1e7 m); beyond it is a unit error, and distances
#: of 1e300 overflow
MAX_COORDINATE_M = 1e7
#: a line of a CSV longer than this (bytes) is refused: no row of the long format is that long, it is a file
#: without line ends or not a CSV at all (the csv module's own field limit, ``csv.field_size_limit()``, is 128 KiB)
MAX_LINE_BYTES = 128 << 10
#: the largest file the exact reader (``read_text_table``) takes: it holds every field as a Python string, about
#: :data:`EXACT_READER_BYTES_PER_BYTE` bytes of memory per byte of file (measured: 800 bytes per reading), so
#: 64 MiB of CSV take about 1.5 GiB; larger files must be one record per line (the fast reader) or are refused
MAX_EXACT_READ_BYTES = 64 << 20
#: peak memory of the exact reader per byte of file (measured: 10^6 readings, 30 MiB of CSV, peaked at 0.99 GB;
#: 4.1 M readings, about 140 MiB, at 2.84 GB)
EXACT_READER_BYTES_PER_BYTE = 24
#: characters of a file's text an error message quotes at most (a field, a header, a line): a message never echoes
#: a file (a symlink to /proc/self/environ, a binary file)
MAX_QUOTED_CHARS = 60
#: the text a number column reads as missing (NaN)
MISSING_TEXT = {"", "nan", "NaN", "NAN", "NA", "N/A"}

class DataFormatError(LocbookError, ValueError):
    """A measured-data file that breaks a rule of the long format; the message names file, line and column."""


# -- reading and checking CSV text ---------------------------------------------------------------------------
def shown(value) -> str:
    """``repr(value)`` for a message, cut to :data:`MAX_QUOTED_CHARS` characters (with the full length) so that a
    message never echoes a large or binary file."""
    text = value if isinstance(value, str) else str(value)
    if len(text) <= MAX_QUOTED_CHARS:
        return repr(value)
    return f"{text[:MAX_QUOTED_CHARS]!r}... ({len(text):,} characters)"


def shown_names(names, limit: int = 12) -> str:
    """A list of column names for a message: each cut by :func:`shown`, at most ``limit`` of them."""
    names = list(names)
    listed = ", ".join(shown(n) for n in names[:limit])
    return f"[{listed}{f', ... ({len(names)} names)' if len(names) > limit else ''}]"


def size_text(n_bytes: float) -> str:
    return f"{n_bytes / (1 << 30):.1f} GiB" if n_bytes >= 1 << 30 else f"{n_bytes / (1 << 20):.1f} MiB"


def check_line_lengths(data: bytes, path: Path, what: str, first_line: int = 1) -> None:
    """Refuse a line longer than :data:`MAX_LINE_BYTES` (bytes ``data`` start at line ``first_line``)."""
    a = np.frombuffer(data, np.uint8)
    ends = np.flatnonzero(a == 10)
    bounds = np.r_[-1, ends, a.size]
    length = np.diff(bounds) - 1
    long = np.flatnonzero(length > MAX_LINE_BYTES)
    if long.size:
        k = int(long[0])
        raise DataFormatError(f"{what} file {path}, line {first_line + k}: the line is {int(length[k]):,} bytes "
                              f"long, more than the {MAX_LINE_BYTES:,} bytes a line may have (MAX_LINE_BYTES): not "
                              "a row of a CSV (no line ends, or not a text file)")


def decode_file_text(data: bytes, path: Path, what: str) -> str:
    """The file's text; a byte that is not UTF-8 is an error naming its line and its byte in the line."""
    def fail(line, column, offset, line_bytes):
        line_text = line_bytes[:4 * MAX_QUOTED_CHARS].decode("utf-8", errors="replace")
        raise DataFormatError(
            f"{what} file {path}, line {line}, byte {column} of the "
            f"line (byte {offset + 1} of the file): 0x{data[offset]:02x} is not UTF-8 ({shown(line_text.rstrip())}); "
            "locbook reads UTF-8 only: re-save the file as UTF-8 (e.g. iconv -f cp1252 -t utf-8)")
    return decode_utf8(data, fail)


def read_text_table(path, required: tuple[str, ...], what: str, why: str = "") -> tuple[pd.DataFrame, np.ndarray]:
    """The CSV as text (nothing converted yet), with every required column present, and each row's line in the
    file (as an editor counts it: blank lines count, a quoted field over several lines gives its first line).

    Every row must have exactly as many fields as the header: a missing field is never read as empty (an empty
    field is written ``,,``) and an extra one never shifts the columns. A file over :data:`MAX_EXACT_READ_BYTES`
    is refused before it is read (``why``: the reason it came here, for the message)."""
    path = Path(path)
    if not path.is_file():
        raise DataFormatError(f"{what} file {path} does not exist")
    size = path.stat().st_size
    if size > MAX_EXACT_READ_BYTES:
        raise DataFormatError(
            f"{what} file {path}{': ' + why if why else ''}: such a file is read by the exact reader, which would "
            f"take about {size_text(size * EXACT_READER_BYTES_PER_BYTE)} for its {size_text(size)}; it reads files "
            f"up to {size_text(MAX_EXACT_READ_BYTES)} (MAX_EXACT_READ_BYTES): write one record per line (LF or CRLF "
            "line ends, no blank lines, no quoted line breaks) or split the file")
    data = path.read_bytes()
    check_line_lengths(data, path, what)
    text = decode_file_text(data, path, what)
    reader = csv.reader(io.StringIO(text, newline=""), skipinitialspace=True, strict=True)
    rows, lines, header, header_line, end, wrong = [], [], None, 0, 0, None
    try:
        for row in reader:
            first, end = end + 1, reader.line_num
            if not row or (len(row) == 1 and not row[0].strip()):   # a blank (or whitespace) line
                continue
            if header is None:
                header, header_line = [c.strip() for c in row], first
                continue
            if len(row) != len(header) and wrong is None:
                wrong = (first, row)                             # reported after the header's own checks
            rows.append(row)
            lines.append(first)
    except csv.Error as exc:
        raise DataFormatError(f"{what} file {path}, line {reader.line_num}: not a readable CSV row ({exc})") from None
    if header is None:
        raise DataFormatError(f"{what} file {path} is empty (no header line)")
    duplicated = sorted({c for c in header if header.count(c) > 1})
    if duplicated:
        raise DataFormatError(f"{what} file {path}: column(s) {shown_names(duplicated)} appear more than once in "
                              "the header")
    missing = [c for c in required if c not in header]
    if missing:
        raise DataFormatError(f"{what} file {path}: missing column(s) {missing}; the header has {shown_names(header)} "
                              f"(required: {list(required)})")
    if wrong is not None:
        _wrong_field_count(path, what, *wrong, header, header_line)
    names = [c if c else f"Unnamed: {j}" for j, c in enumerate(header)]     # pandas' name for a blank header
    table = pd.DataFrame(rows, columns=names, dtype=object) if rows else pd.DataFrame(
        {c: pd.Series([], dtype=object) for c in names})
    return table, np.asarray(lines, dtype=int)


def _wrong_field_count(path, what: str, line: int, row: list[str], header: list[str], header_line: int):
    named = len(header)
    while named and not header[named - 1]:          # empty names at the end of the header
        named -= 1
    if named < len(header) and len(row) == named:   # rows without them: the header alone has trailing commas
        raise DataFormatError(f"{what} file {path}, line {header_line}: the header ends with an empty column name "
                              f"(a trailing comma?): it has {len(header)} names, {shown_names(header)}, but line "
                              f"{line} has "
                              f"{len(row)} field(s); remove the trailing comma from the header")
    if len(row) < len(header):
        absent = header[len(row):]
        raise DataFormatError(f"{what} file {path}, line {line}, column(s) {shown_names(absent)}: the row has "
                              f"{len(row)} field(s), "
                              f"the header {len(header)}: {'it is' if len(absent) == 1 else 'they are'} missing "
                              "(an empty value is written as an empty field, e.g. '0.5,tag,A,' for not heard)")
    raise DataFormatError(f"{what} file {path}, line {line}: the row has {len(row)} fields, the header {len(header)} "
                          f"fields ({shown_names(header)}); a value with a comma must be quoted, and an extra column "
                          "needs a "
                          "name in the header")


def numeric_column(table: pd.DataFrame, column: str, source: str, lines, *, missing_ok: bool,
             coordinate: bool = False) -> np.ndarray:
    """A text column as floats; empty / NaN text is missing (allowed only where ``missing_ok``); anything else
    that is not a finite number is an error naming the line. A ``coordinate`` of magnitude
    :data:`MAX_COORDINATE_M` or more is refused too."""
    raw = table[column]
    if pd.api.types.is_numeric_dtype(raw) and not pd.api.types.is_bool_dtype(raw):
        values = raw.to_numpy(dtype=float, na_value=np.nan)
        missing = np.isnan(values)
    else:
        text = raw.astype(object).where(raw.notna(), "").astype(str).str.strip()
        missing = text.isin(MISSING_TEXT).to_numpy()
        values = pd.to_numeric(text.where(~missing, None), errors="coerce").to_numpy(dtype=float)
    bad = ~missing & ~np.isfinite(values)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column {column!r}: {shown(table[column].iloc[i])} is "
                              "not a finite "
                              f"number ({int(bad.sum())} such value(s) in the column)")
    if missing.any() and not missing_ok:
        i = int(np.flatnonzero(missing)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column {column!r}: value is missing ({int(missing.sum())} "
                              "missing value(s) in the column; it must be given on every row)")
    if coordinate:
        far = np.abs(values) >= MAX_COORDINATE_M          # NaN compares False
        if far.any():
            i = int(np.flatnonzero(far)[0])
            raise DataFormatError(f"{source}, line {lines[i]}, column {column!r}: {values[i]:g} is not a coordinate of "
                                  f"a site (coordinates are less than {MAX_COORDINATE_M:g} in magnitude, "
                                  f"MAX_COORDINATE_M; {int(far.sum())} such value(s)): a unit error?")
    return values


def file_lines(n_rows: int) -> np.ndarray:
    return np.arange(n_rows) + 2            # the header is line 1

def seconds_text(value) -> str:
    """A time with every digit it has (``repr``): ``1581250000.25 s``, never ``1.58125e+09 s``."""
    return f"{float(value)!r} s"


