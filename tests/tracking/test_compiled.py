"""The one rule of the compiled paths (locbook.tracking._compiled): where numba cannot compile or run a kernel, one
RuntimeWarning names it and points at the caller's line, every compiled path is then off for the session, and the
numpy path answers with its own numbers. (The EKF, UKF and particle filter cases are in test_filter_speed_equality,
test_ukf_compiled and test_particle_speed.)"""
import warnings

import numpy as np
import pytest

import locbook as lb
from locbook.static import box_ls
from locbook.tracking import _compiled, bayes

pytestmark = pytest.mark.compiled

pytest.importorskip("numba")

ANCHORS = np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 4.0], [5.0, 4.0]])


def _grid_call():
    cells = np.stack(np.meshgrid(np.arange(0, 5.01, 0.25), np.arange(0, 4.01, 0.25)), -1).reshape(-1, 2)
    model = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 3.0, min_distance_m=0.1))
    rss = model.mean_rss_dbm(np.tile([[2.0, 1.5]], (3, 1)))[0][None] + np.random.default_rng(0).normal(0, 3, (1, 3, 4))
    return lb.grid_bayes_filter(rss, model, cells, 0.5).mean


def _box_call():
    rng = np.random.default_rng(1)
    d = lb.pairwise_distance_m(rng.uniform(0, 4, (300, 2)), ANCHORS) * rng.uniform(0.9, 1.1, (300, 4))
    return lb.lateration_box_ls(ANCHORS, d, [0.0, 0.0], [5.0, 4.0]).position_m


CASES = {"grid filter": ("locbook.tracking._grid_kernels", "_nb_update", _grid_call),
         "box LS": ("locbook.static._box_kernels", "_nb_box_ls", _box_call)}


@pytest.mark.parametrize("what", list(CASES))
def test_a_kernel_that_cannot_compile_warns_at_the_callers_line_and_turns_every_compiled_path_off(monkeypatch, what):
    import importlib
    module, kernel, call = CASES[what]
    monkeypatch.setattr(bayes, "_GRID_MIN_WORK", 0)
    monkeypatch.setattr(box_ls, "_BOX_NUMBA_MIN_PROBLEMS", 0)
    monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", False)
    plain = call()

    def broken(*args):
        raise RuntimeError("no compiler here")

    monkeypatch.setattr(importlib.import_module(module), kernel, broken)
    monkeypatch.setattr(_compiled, "_KERNEL_MODULES", {})             # not tried yet in this session
    monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ours = call()
        again = call()
    failed = [w for w in caught if issubclass(w.category, RuntimeWarning) and "compiled" in str(w.message)]
    assert len(failed) == 1, [str(w.message) for w in caught]
    assert f"the compiled {what} failed (RuntimeError: no compiler here)" in str(failed[0].message)
    assert failed[0].filename == __file__                             # the user's line, not the library's
    assert _compiled._NUMBA_ENABLED is False                          # every compiled path, for the session
    for result in (ours, again):
        np.testing.assert_array_equal(np.asarray(result), np.asarray(plain))
