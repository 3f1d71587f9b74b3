"""The notebook suite: experiment list, typed parameters, papermill execution and reports.

Names are imported on first use (PEP 562): a notebook needs none of the suite (its ``Report`` lives in
:mod:`locbook.reproduce`), and the runner's dependencies (papermill, nbformat, jinja2) would cost every kernel
seconds at start-up.
"""
from .._lazy import lazy_exports

_EXPORTS = {
    "NotebookParameter": "params", "ParameterRule": "params", "read_parameters": "params",
    "KERNEL_NAME": "runner", "Outcome": "runner", "SuiteRun": "runner", "cache_key": "cachekey",
    "override_folder_name": "run", "run_suite": "run", "write_suite_reports": "site",
    "Task": "runner", "run_tasks": "run",
    "Study": "study", "StudyPoint": "study", "load_study": "study", "load_studies": "study",
    "expand_study": "study", "run_study": "study", "STUDY_COLUMNS": "study",
    "DOCUMENT_KEYS": "spec", "PROFILES": "spec", "Experiment": "spec", "Suite": "spec", "SuiteError": "spec",
    "load_suite": "spec",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
