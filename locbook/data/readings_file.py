"""Reading a readings file of the long format fast (:func:`read_readings_table`: pandas' C reader for files of one
record per line, the exact reader of :mod:`locbook.data.csvfile` for any other), then checking it
(:func:`validate_readings_file`, :func:`read_readings`)."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pandas as pd

from . import csvfile  # its MAX_LINE_BYTES and MAX_EXACT_READ_BYTES are read when used (tests lower them)
from .csvfile import (
    MISSING_TEXT,
    DataFormatError,
    check_line_lengths,
    file_lines,
    numeric_column,
    read_text_table,
    shown,
    shown_names,
    size_text,
)
from .long_format import OPTIONAL_READING_COLUMNS, READING_COLUMNS, validate_readings

__all__ = ["MAX_READINGS_FILE_BYTES", "FAST_READER_BYTES_PER_BYTE", "read_readings_table", "validate_readings_file",
           "read_readings"]

#: the largest readings file (bytes) read at all: the fast reader takes about
#: :data:`FAST_READER_BYTES_PER_BYTE` bytes of memory per byte of file (measured: 10^7 readings, 336 MiB of CSV,
#: peaked at 2.2 GiB; 10^6 readings, 31 MB, 200 MB above the interpreter, 3 x 10^6 623 MB, one quoted field
#: or none), so 1 GiB of CSV (about 3 x 10^7 readings) take about 7 GiB; split larger recordings
MAX_READINGS_FILE_BYTES = 1 << 30
FAST_READER_BYTES_PER_BYTE = 7
#: rows per chunk when a large file's number column holds text that is not a number (to name its line)
_LOCATE_CHUNK_ROWS = 200_000


#: bytes per block of the field-count scan of :func:`read_readings_table` (its scratch memory is ~4x this)
_SCAN_BLOCK = 1 << 25


def _scan_records(path: Path, n_fields: int) -> str:
    """``""`` when the file after its header line is UTF-8 text with LF or CRLF line ends whose every line is one
    record of ``n_fields`` fields (a quoted field, with commas or doubled quotes in it, may appear; a quoted line
    break may not) and none is blank: then data row ``i`` is line ``i + 2`` and no row is short or long. Else the
    first reason it is not, naming the line. A line over :data:`~locbook.data.csvfile.MAX_LINE_BYTES` is refused
    here. Read in blocks of :data:`_SCAN_BLOCK` bytes (never the whole file at once); only lines holding a quote
    go through the csv module."""
    want = n_fields - 1
    with open(path, "rb") as fh:
        fh.readline(csvfile.MAX_LINE_BYTES + 2)    # the header (checked by the caller)
        line, rest = 2, b""                                # the line number of the block's first line
        while True:
            chunk = fh.read(_SCAN_BLOCK)
            if not chunk and not rest:
                return ""
            block = rest + chunk
            if chunk:                                      # cut at the last line end; the rest joins the next block
                cut = block.rfind(b"\n") + 1
                if cut == 0:
                    if len(block) > csvfile.MAX_LINE_BYTES:
                        check_line_lengths(block, path, "readings", line)
                    rest = block
                    continue
                block, rest = block[:cut], block[cut:]
            else:
                rest = b""
            check_line_lengths(block, path, "readings", line)
            a = np.frombuffer(block, np.uint8)
            ends = np.flatnonzero(a == 10)
            if a[-1] != 10:
                ends = np.r_[ends, a.size - 1]             # the last line without a line end
            cr = np.flatnonzero(a == 13)
            lone = cr[(cr + 1 >= a.size) | (a[np.minimum(cr + 1, a.size - 1)] != 10)]
            if lone.size:
                return f"line {line + int(np.searchsorted(ends, lone[0]))} ends with a CR alone (not LF or CRLF)"
            try:
                block.decode("utf-8")
            except UnicodeDecodeError as exc:
                return f"line {line + int(np.searchsorted(ends, exc.start))} is not UTF-8"
            per_line = np.diff(np.searchsorted(np.flatnonzero(a == 44), ends, side="right"), prepend=0)
            quoted = np.unique(np.searchsorted(ends, np.flatnonzero(a == 34)))
            if quoted.size:                                # those lines: fields as the csv module splits them
                starts = np.r_[0, ends[:-1] + 1]
                texts = [block[starts[k]:ends[k] + 1].decode("utf-8").rstrip("\r\n") for k in quoted]
                reader = csv.reader(texts, skipinitialspace=True, strict=True)
                try:
                    for j, row in enumerate(reader):
                        if reader.line_num != j + 1:
                            return f"line {line + int(quoted[j])} has a quoted field that goes on over a line break"
                        per_line[quoted[j]] = len(row) - 1
                except csv.Error as exc:
                    k = int(quoted[min(reader.line_num, len(quoted)) - 1])
                    return f"line {line + k} is not a readable CSV row ({exc})"
            bad = np.flatnonzero(per_line != want)
            if bad.size:
                k = int(bad[0])
                blank = not block[(0 if k == 0 else ends[k - 1] + 1):ends[k] + 1].strip()
                return (f"line {line + k} is blank" if blank else
                        f"line {line + k} has {int(per_line[k]) + 1} field(s), the header {n_fields}")
            line += ends.size


def _header(first: bytes) -> list[str] | None:
    """The header's column names (stripped), or None if the line is not a readable CSV row."""
    if first.startswith(b"\xef\xbb\xbf"):
        first = first[3:]
    text = first.decode("utf-8", "replace").rstrip("\r\n")
    if '"' not in text:
        return [c.strip() for c in text.split(",")]
    try:
        rows = list(csv.reader([text], skipinitialspace=True, strict=True))
    except csv.Error:
        return None
    return [c.strip() for c in rows[0]] if len(rows) == 1 else None


def _locate_bad_number(path: Path, header: list[str], numeric: list[str], error: Exception):
    """Name the line and column of the first number column's field the fast reader could not parse (a file too
    large for the exact reader): read it again in chunks of :data:`_LOCATE_CHUNK_ROWS` rows as text (one record
    per line, as checked) and run the long format's number check on each."""
    source = f"readings file {path}"
    try:
        offset = 0
        for chunk in pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True, engine="c",
                                 encoding="utf-8-sig", chunksize=_LOCATE_CHUNK_ROWS):
            chunk.columns = header
            lines = file_lines(len(chunk)) + offset
            for column in numeric:
                numeric_column(chunk, column, source, lines, missing_ok=column != "time_s")
            offset += len(chunk)
    except DataFormatError:
        raise
    except (ValueError, UnicodeDecodeError, pd.errors.ParserError) as exc:     # pandas' tokenizer, once more
        error = exc
    raise DataFormatError(f"{source}: pandas' reader refused it ({shown(str(error))}), and at "
                          f"{size_text(path.stat().st_size)} "
                          f"it is too large for the exact reader (MAX_EXACT_READ_BYTES = "
                          f"{size_text(csvfile.MAX_EXACT_READ_BYTES)}), which would name the line")


def _text_categories(path: Path, j: int, n_rows: int) -> pd.Series:
    """Column ``j`` of the file as categories of its text. pandas' C reader turns categories that all look like
    numbers or bools into numbers or bools (``01`` -> 1, ``1.50`` and ``1.5`` -> one point, ``true`` -> True), which
    would change ids; the column is read again as text, in chunks of :data:`_LOCATE_CHUNK_ROWS` rows (each chunk's
    strings are categories before the next is read)."""
    from pandas.api.types import union_categoricals
    parts = [chunk.iloc[:, 0].astype("category") for chunk in
             pd.read_csv(path, usecols=[j], dtype=str, keep_default_na=False, skipinitialspace=True, engine="c",
                         encoding="utf-8-sig", chunksize=_LOCATE_CHUNK_ROWS)]
    values = union_categoricals(parts) if parts else pd.Categorical([])
    if len(values) != n_rows:           # cannot happen for a file the scan passed; never a silent shift
        raise DataFormatError(f"readings file {path}: column {j + 1} read again as text has {len(values)} rows, "
                              f"not {n_rows}")
    return pd.Series(values)


def read_readings_table(path, *, time_as_text: bool = False) -> tuple[pd.DataFrame, np.ndarray]:
    """A readings CSV as :func:`validate_readings` takes it, and each row's line: the number columns as floats
    (empty, ``NaN``, ``NA``, ``N/A`` missing), the ids and other columns as categories (text, stripped later).

    Files of one record per line (every logger's output; quoted fields allowed, quoted line breaks not) are parsed
    by pandas' C reader, at a few bytes per field; any other file, or one that reader refuses, goes through the
    exact reader (``read_text_table``), whose messages name the line and column of the problem. Sizes are checked
    before anything is read: a file over :data:`MAX_READINGS_FILE_BYTES`, a line over
    :data:`~locbook.data.csvfile.MAX_LINE_BYTES`, and a file over :data:`~locbook.data.csvfile.MAX_EXACT_READ_BYTES`
    that needs the exact reader are refused, naming the limit.
    ``time_as_text`` keeps ``time_s`` as written (integer nanoseconds since 1970 lose their last digits as
    floats)."""
    path = Path(path)
    if not path.is_file():
        raise DataFormatError(f"readings file {path} does not exist")
    size = path.stat().st_size
    if size > MAX_READINGS_FILE_BYTES:
        raise DataFormatError(f"readings file {path} is {size_text(size)}: reading it would take about "
                              f"{size_text(size * FAST_READER_BYTES_PER_BYTE)}, and a readings file is at most "
                              f"{size_text(MAX_READINGS_FILE_BYTES)} (MAX_READINGS_FILE_BYTES): split the recording "
                              "into several files, one [[recording]] each")
    with open(path, "rb") as fh:
        first = fh.readline(csvfile.MAX_LINE_BYTES + 2)
    check_line_lengths(first.rstrip(b"\r\n"), path, "readings")
    header = _header(first)
    header_ok = (header is not None and all(c in header for c in READING_COLUMNS)
                 and len(set(header)) == len(header) and all(header))
    if not header_ok and size > csvfile.MAX_EXACT_READ_BYTES:
        raise DataFormatError(f"readings file {path}, line 1: the header "
                              f"{'is not a readable CSV row' if header is None else shown_names(header)}; it names "
                              f"the columns {list(READING_COLUMNS)} (and optional ones), each once, none empty")
    numeric = [c for c in ("time_s", "rssi_dbm", *OPTIONAL_READING_COLUMNS)
               if header_ok and c in header and not (time_as_text and c == "time_s")]
    why = _scan_records(path, len(header)) if header_ok else "the header is not the long format's"
    if not why:
        try:
            kinds = {c: (float if c in numeric else str if c == "time_s" else "category") for c in header}
            table = pd.read_csv(path, dtype=kinds, keep_default_na=False,
                                na_values={c: sorted(MISSING_TEXT) for c in numeric}, skipinitialspace=True,
                                engine="c", encoding="utf-8-sig")
        except (ValueError, UnicodeDecodeError, pd.errors.ParserError) as exc:
            if size > csvfile.MAX_EXACT_READ_BYTES:        # too large to read again as text: locate it in chunks
                _locate_bad_number(path, header, numeric, exc)
            why = "the fast reader refused it"             # the exact reader says what and where
    if not why and len(table.columns) != len(header):   # e.g. lines ended by a bare CR: the header read differs
        why = "the fast reader split the lines otherwise than the header line"
    if why:
        return read_text_table(path, READING_COLUMNS, "readings", why=why)
    table.columns = header
    for j, column in enumerate(header):
        if kinds[column] == "category" and table[column].cat.categories.dtype.kind not in "OUT":
            table[column] = _text_categories(path, j, len(table))
    table.attrs["parsed"] = True       # numbers already parsed: see validate_readings_file
    return table, file_lines(len(table))


def validate_readings_file(path, table: pd.DataFrame, lines, prepare=lambda t: t, **options) -> pd.DataFrame:
    """:func:`validate_readings` of a table from :func:`read_readings_table` (after ``prepare``, e.g. a unit
    conversion). Where the fast reader parsed the numbers and the table breaks a rule, the file is read again as
    text and checked again, so that the message quotes the file's own text (two times equal only as floats); a
    file too large for the exact reader (:data:`~locbook.data.csvfile.MAX_EXACT_READ_BYTES`) keeps the message of
    the parsed table."""
    source = f"readings file {path}"
    try:
        return validate_readings(prepare(table), source=source, lines=lines, **options)
    except DataFormatError:
        if not table.attrs.get("parsed") or Path(path).stat().st_size > csvfile.MAX_EXACT_READ_BYTES:
            raise
    exact, lines = read_text_table(path, READING_COLUMNS, "readings")
    return validate_readings(prepare(exact), source=source, lines=lines, **options)


def read_readings(path, *, anchor_ids=None, invalid_values_dbm=None, valid_range_dbm=None,
                  sort: bool = False) -> pd.DataFrame:
    r"""Read and check a readings CSV of the long format (:mod:`locbook.data.measured` documents it).

    Parameters
    ----------
    path : str or path-like
        The CSV file: ``time_s, transmitter, receiver, rssi_dbm`` and the optional columns.
    anchor_ids : sequence of str, optional
        Every ``receiver`` must be one of them (the link-direction rule names a swap of the two id columns).
    invalid_values_dbm : number or sequence of numbers, optional
        Values the receivers write for "no reading": NaN (not heard).
    valid_range_dbm : (low, high), optional
        The plausible readings (dBm, default :data:`~locbook.data.long_format.RSSI_RANGE_DBM`); outside: refused.
    sort : bool
        Reorder the rows by time (stably) before the checks, instead of refusing time that goes back.

    Returns
    -------
    pandas.DataFrame
        The readings typed (:func:`~locbook.data.long_format.validate_readings`): times, dBm and true positions as
        floats (NaN = missing or not heard), ids as text; other columns kept.

    Raises
    ------
    DataFormatError
        A rule broken, in one line naming the file, the line and the column.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from locbook.data.measured import read_readings
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "walk.csv"
    >>> _ = path.write_text("time_s,transmitter,receiver,rssi_dbm\n0.0,tag,A1,-61\n0.0,tag,A2,\n0.5,tag,A1,-63.5\n")
    >>> table = read_readings(path, anchor_ids=["A1", "A2"])
    >>> table["rssi_dbm"].tolist()                          # the empty field: not heard
    [-61.0, nan, -63.5]
    >>> table["receiver"].tolist(), table["time_s"].tolist()
    (['A1', 'A2', 'A1'], [0.0, 0.0, 0.5])
    >>> path.write_text("time_s,transmitter,receiver,rssi_dbm\n0.0,tag,A1,-61\n") and None
    >>> read_readings(path, anchor_ids=["B1"])             # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    locbook.data.csvfile.DataFormatError: readings file ..., line 2, column 'receiver': 'A1' is not an anchor id ...
    """
    table, lines = read_readings_table(path)
    return validate_readings_file(path, table, lines, anchor_ids=anchor_ids, invalid_values_dbm=invalid_values_dbm,
                                  valid_range_dbm=valid_range_dbm, sort=sort)

