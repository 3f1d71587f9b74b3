"""The notebook suite: experiment list, typed parameters, papermill execution and reports."""
from .params import NotebookParameter, read_parameters
from .runner import KERNEL_NAME, Outcome, cache_key, run_suite, write_suite_reports
from .spec import DOCUMENT_KEYS, PROFILES, Experiment, Suite, load_suite

__all__ = ["NotebookParameter", "read_parameters", "KERNEL_NAME", "Outcome", "cache_key", "run_suite",
           "write_suite_reports", "DOCUMENT_KEYS", "PROFILES", "Experiment", "Suite", "load_suite"]
