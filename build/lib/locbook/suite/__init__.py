"""The notebook suite: experiment list, typed parameters, papermill execution and reports."""
from .params import NotebookParameter, ParameterRule, read_parameters
from .runner import KERNEL_NAME, Outcome, SuiteRun, cache_key, override_folder_name, run_suite, write_suite_reports
from .spec import DOCUMENT_KEYS, PROFILES, Experiment, Suite, SuiteError, load_suite

__all__ = ["NotebookParameter", "ParameterRule", "read_parameters", "KERNEL_NAME", "Outcome", "SuiteRun",
           "cache_key", "override_folder_name", "run_suite", "write_suite_reports", "DOCUMENT_KEYS", "PROFILES",
           "Experiment", "Suite", "SuiteError", "load_suite"]
