"""The numbers each source document printed, read from ``locbook/data/printed/<document>.csv``.

One CSV per document, transcribed from the source by the locbook authors, with the columns
``location, item, statistic, unit, printed``: where the number stands (``Table 7.1``, ``Fig. 5 text``,
``Abstract``), the row or item, the statistic or column, the unit, and the text exactly as printed
(``2.2867``, ``1.0``, ``about 6``, ``more than 50 %``). Lines starting with ``#`` are comments.
Printed numbers live only here: scenarios and notebooks read them, none is typed into code.
"""
from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

__all__ = ["Printed", "PrintedValues", "printed", "printed_number", "printed_rounding", "PRINTED_DIR",
           "PRINTED_COLUMNS"]

PRINTED_DIR = Path(__file__).resolve().parents[1] / "data" / "printed"    # package data of locbook.data
PRINTED_COLUMNS = ("location", "item", "statistic", "unit", "printed")


_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def printed_number(text: str) -> float:
    """The number in a printed text: ``"2.2867"`` -> 2.2867, ``"about 6"`` -> 6, ``"more than 50 %"`` -> 50.
    A text holding no number, or more than one, is refused (it needs an explicit threshold)."""
    found = _NUMBER.findall(str(text))
    if len(found) != 1:
        raise ValueError(f"printed text {text!r} must hold exactly one number, found {len(found)}")
    return float(found[0])


def printed_rounding(text: str) -> float:
    """Half a unit in the last printed digit: ``"2.2867"`` -> 0.00005, ``"24"`` -> 0.5, ``"1.5e-3"`` -> 0.00005."""
    found = _NUMBER.findall(str(text))
    if len(found) != 1:
        raise ValueError(f"printed text {text!r} must hold exactly one number, found {len(found)}")
    mantissa, _, exponent = found[0].lower().partition("e")
    decimals = len(mantissa.partition(".")[2])
    return 0.5 * 10.0 ** (-decimals + (int(exponent) if exponent else 0))


@dataclass(frozen=True)
class Printed:
    """One printed quantity of one document: where it stands, its unit, and its text as printed."""

    document: str
    location: str
    item: str
    statistic: str
    unit: str
    text: str

    @property
    def id(self) -> str:
        """Identifies the quantity within its document: ``"Table 7.1 | 6 | rmse_m"``."""
        return " | ".join((self.location, self.item, self.statistic))

    @property
    def where(self) -> str:
        return ", ".join(p for p in (self.location, self.item, self.statistic) if p)

    @property
    def value(self) -> float:
        """The printed number (for a statement such as ``more than 50 %``, its one number)."""
        return printed_number(self.text)

    @property
    def rounding(self) -> float:
        """Half a unit in the last printed digit."""
        return printed_rounding(self.text)


class PrintedValues:
    """Every printed quantity of one document, looked up by location, item and statistic."""

    def __init__(self, document: str, rows: tuple[Printed, ...]):
        self.document = document
        self.rows = rows
        self._by_key = {(p.location, p.item, p.statistic): p for p in rows}

    def get(self, location: str, item: str = "", statistic: str = "") -> Printed:
        try:
            return self._by_key[(location, item, statistic)]
        except KeyError:
            raise KeyError(f"{self.document} prints nothing at {location!r}, item {item!r}, statistic "
                           f"{statistic!r} (see {PRINTED_DIR / (self.document + '.csv')})") from None

    def find(self, location: str, item: str = "", statistic: str = "") -> Printed | None:
        return self._by_key.get((location, item, statistic))

    def where(self, location: str | None = None, **match) -> list[Printed]:
        """The rows at ``location`` (all if None) whose fields equal ``match`` (e.g. ``statistic="rmse_m"``)."""
        return [p for p in self.rows if (location is None or p.location == location)
                and all(getattr(p, k) == v for k, v in match.items())]

    def __iter__(self):
        return iter(self.rows)

    def __len__(self):
        return len(self.rows)


@lru_cache(maxsize=None)
def printed(document: str) -> PrintedValues:
    """The printed quantities of ``document`` (``"george"``, ``"ozkaya2011"``, ``"dogan2015"``, ...)."""
    path = PRINTED_DIR / f"{document}.csv"
    if not path.is_file():
        known = sorted(p.stem for p in PRINTED_DIR.glob("*.csv"))
        raise KeyError(f"no printed values for document {document!r}; known: {known}")
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(line for line in fh if not line.startswith("#"))
        if tuple(reader.fieldnames or ()) != PRINTED_COLUMNS:
            raise ValueError(f"{path}: columns must be {PRINTED_COLUMNS}, got {reader.fieldnames}")
        rows = []
        for line, r in enumerate(reader, start=2):
            if not r["location"] or not r["printed"]:
                raise ValueError(f"{path}, data row {line - 1}: location and printed text are required")
            rows.append(Printed(document, r["location"], r["item"], r["statistic"], r["unit"], r["printed"]))
    keys = [(p.location, p.item, p.statistic) for p in rows]
    if len(set(keys)) != len(keys):
        dup = next(k for k in keys if keys.count(k) > 1)
        raise ValueError(f"{path}: {dup} is transcribed twice")
    return PrintedValues(document, tuple(rows))
