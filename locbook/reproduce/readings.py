"""Deprecated: the old home of :mod:`locbook.reproduce.interpretations` ("reading" now means only a sensor
measurement). Importing it warns once (DeprecationWarning) and gives the old names for one release."""
from .._deprecation import warn_deprecated
from .interpretations import (
    BASES,
    INTERPRETATION_COLUMNS,
    INTERPRETATIONS_DIR,
    MAX_DECLARATION_BYTES,
    OPTIONAL_INTERPRETATION_COLUMNS,
    Interpretation,
    InterpretationsError,
    interpretations,
    interpretations_for,
    load_interpretation_file,
    read_declaration,
    utf8_text,
)

# the import statement's line is the caller, past the import machinery's frames
warn_deprecated("locbook.reproduce.readings", "locbook.reproduce.interpretations",
                skip=(__name__, "importlib", "importlib._bootstrap", "importlib._bootstrap_external"))

Reading = Interpretation
ReadingsError = InterpretationsError
readings = interpretations
readings_for = interpretations_for
load_reading_file = load_interpretation_file
READINGS_DIR = INTERPRETATIONS_DIR
READING_COLUMNS = INTERPRETATION_COLUMNS
OPTIONAL_READING_COLUMNS = OPTIONAL_INTERPRETATION_COLUMNS

__all__ = ["Reading", "ReadingsError", "readings", "readings_for", "load_reading_file", "READINGS_DIR",
           "READING_COLUMNS", "OPTIONAL_READING_COLUMNS", "BASES", "utf8_text", "read_declaration",
           "MAX_DECLARATION_BYTES"]
