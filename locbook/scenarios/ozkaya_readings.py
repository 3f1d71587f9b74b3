"""Deprecated: the old home of :mod:`locbook.scenarios.ozkaya_interpretations` ("reading" now means only a sensor
measurement). Importing it warns once (DeprecationWarning); its old names stay for one release."""
from .._deprecation import warn_deprecated
from .ozkaya_interpretations import (
    FITTED_VALUES,
    LAYOUTS_OF_HALF,
    fitted_calibrated_from,
    fitted_interpretations,
    record_interpretations,
    record_simulation_assumptions,
    run_summary,
    sim_interpretations,
    text_interpretation_note,
    unfitted_interpretations,
    with_interpretations,
)

# the import statement's line is the caller, past the import machinery's frames
warn_deprecated("locbook.scenarios.ozkaya_readings", "locbook.scenarios.ozkaya_interpretations",
                skip=(__name__, "importlib", "importlib._bootstrap", "importlib._bootstrap_external"))

fitted_readings = fitted_interpretations
unfitted_readings = unfitted_interpretations
text_reading_note = text_interpretation_note
sim_readings = sim_interpretations
with_readings = with_interpretations
record_readings = record_interpretations

__all__ = ["FITTED_VALUES", "LAYOUTS_OF_HALF", "fitted_calibrated_from", "fitted_readings", "record_readings",
           "record_simulation_assumptions", "run_summary", "sim_readings", "text_reading_note", "unfitted_readings",
           "with_readings"]
