"""Session-wide test rules: the numpy path for every test that is not about the compiled path.

The compiled kernels (``locbook/**/_*kernels.py``) cost minutes of CPU to compile from a cold cache (a fresh clone,
a fresh CI environment) and about a second to load once cached; a test that merely calls a filter on a large enough
problem would pay that compilation for a path it does not check. So each test runs with the compiled paths switched
off (``locbook.tracking._compiled._NUMBA_ENABLED``, and ``LOCBOOK_NUMBA=0`` for the processes it starts), except:

- tests marked ``compiled`` (the compiled-versus-numpy equality tests and the compiled path's own rules): they run
  with the switch as the environment sets it (on by default), and switch it themselves where they compare the paths;
- tests marked ``notebooks``: the notebooks run as a user runs them, compiled where the problem is large enough;
- tests marked ``slow``: they run in CI's second pass, after README's command has compiled and cached every kernel,
  on the path a user gets at their size (the long recursions, the data runs, the noise fits of whole studies: on the
  numpy path they took about 450 s of that pass, on the compiled path about 130 s).

The numpy path and the compiled path agree to round-off (tests/tracking/test_compiled_equality.py and the other
``compiled`` tests), so no other test's assertion depends on the path. docs/testing.md lists the markers.
"""
from __future__ import annotations

import os

import pytest

from locbook._lazy import skip_iri_format_checker

# what the locbook command and its workers do (locbook/_lazy.py): the test modules read notebooks with nbformat, and
# each test process would otherwise build rfc3987_syntax's grammar at import (3-4 s of CPU per process)
skip_iri_format_checker()

#: the markers whose tests keep the compiled paths as the environment sets them
_COMPILED_MARKERS = ("compiled", "notebooks", "slow")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """The whole setup, call and teardown of ``item`` with the compiled paths off (unless marked above); restored
    afterwards. A hook rather than an autouse fixture: hypothesis refuses function-scoped fixtures around ``@given``,
    and a test's own fixtures (``monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", True)``) still run inside it."""
    if any(item.get_closest_marker(m) for m in _COMPILED_MARKERS):
        yield
        return
    from locbook.tracking import _compiled
    saved, saved_env = _compiled._NUMBA_ENABLED, os.environ.get("LOCBOOK_NUMBA")
    _compiled._NUMBA_ENABLED = False
    os.environ["LOCBOOK_NUMBA"] = "0"
    try:
        yield
    finally:
        _compiled._NUMBA_ENABLED = saved
        if saved_env is None:
            os.environ.pop("LOCBOOK_NUMBA", None)
        else:
            os.environ["LOCBOOK_NUMBA"] = saved_env
