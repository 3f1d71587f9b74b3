"""The reproduction layer: the numbers each source printed, the scoreboard's rules, and what a notebook records.

- :mod:`.printed_values`: :func:`printed` reads a document's printed numbers (package data ``locbook/data/printed``),
  each a :class:`Printed` with its text, value and rounding;
- :mod:`.scoring`: a row's kind, window (printed rounding + 2 Monte-Carlo standard errors + a named
  :class:`Ambiguity`) and verdict (:func:`score`);
- :mod:`.report`: :class:`Report`, whose :meth:`Report.number` applies those rules (window, verdict and note),
  so that a notebook never computes a window itself;
- :mod:`.interpretations`: each document's unprinted assumptions and contested interpretations (package data
  ``locbook/data/interpretations``): the default, the plausible alternatives or range, the basis (printed, assumed,
  or fitted to printed output) and the source, as :class:`Interpretation` (:func:`interpretations`,
  :func:`interpretations_for`). The old names (``Reading``, ``readings``, ... of ``locbook.reproduce.readings``)
  work for one release with a DeprecationWarning (:data:`RENAMED`).

Scenarios may import this layer; it imports nothing from the suite (the suite imports it). Names load on first use,
so that ``import locbook.reproduce.printed_values`` does not pay for the report's numpy.
"""
from .._lazy import lazy_exports

_EXPORTS = {
    **dict.fromkeys(("Printed", "PrintedValues", "printed", "printed_number", "printed_rounding", "PRINTED_DIR",
                     "PRINTED_COLUMNS"), "printed_values"),
    **dict.fromkeys(("KINDS", "JUDGED_KINDS", "VERDICTS", "CLAIM_RELATIONS", "WITHIN_LIMIT", "Ambiguity", "Score",
                     "score", "SCORED_VERDICTS", "VERDICT_COLUMNS", "BRACKETS", "verdict_column",
                     "scoreboard_counts", "verdict_counts_text"), "scoring"),
    **dict.fromkeys(("Report", "Table", "NUMBER_COLUMNS"), "report"),
    **dict.fromkeys(("Interpretation", "InterpretationsError", "interpretations", "interpretations_for",
                     "load_interpretation_file", "INTERPRETATIONS_DIR", "INTERPRETATION_COLUMNS", "BASES"),
                    "interpretations"),
}
#: the names before "reading" meant only a sensor measurement: old -> new (deprecated aliases for one release)
RENAMED = {"Reading": "Interpretation", "ReadingsError": "InterpretationsError", "readings": "interpretations",
           "readings_for": "interpretations_for", "load_reading_file": "load_interpretation_file",
           "READINGS_DIR": "INTERPRETATIONS_DIR", "READING_COLUMNS": "INTERPRETATION_COLUMNS"}
__all__ = list(_EXPORTS)
_getattr, __dir__ = lazy_exports(__name__, _EXPORTS)


def __getattr__(name: str):
    if name in RENAMED:
        # imported here: locbook._deprecation loads numpy, which `locbook --version` and `locbook list` never need
        from .._deprecation import warn_deprecated
        warn_deprecated(f"{__name__}.{name}", f"{__name__}.{RENAMED[name]}")
        return _getattr(RENAMED[name])
    return _getattr(name)
