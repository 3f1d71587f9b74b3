"""Property-based fuzzing of every public static estimator and calibration fit.

Inputs: NaN, +-inf, huge (1e300), tiny (1e-300) and +500 dBm values; one, two, collinear, nearly collinear and
coincident anchors; layouts scaled to 1e-300 and 1e300; empty batches; int and float32 dtypes; non-contiguous
(strided) arrays. The rule every call must keep:

- a correct answer: the exact position from noise-free readings of a well-conditioned layout, the exact parameters
  from noise-free calibration data; for int or float32 input the float64 answer on the same values, for a strided
  array the answer on its contiguous copy (bit for bit); or
- NaN with a per-problem status (never a finite answer with ``converged=True`` and an infinite or NaN cost, never
  ``status="ok"`` with a NaN position or parameter); or
- a clear error: a locbook error (:class:`locbook.LocbookError`), or a ``ValueError`` whose message names an
  argument of the function; never a raw numpy/scipy/cvxpy traceback (IndexError, a broadcast ValueError,
  LinAlgError, cvxpy errors, ZeroDivisionError).

Example counts are bounded (``max_examples``) so that the module runs in well under a minute.
"""
import inspect
import re
import warnings
from functools import partial

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

import locbook as lb
from locbook.static.calibration import CALIBRATION_MODES, FIT_PROBLEM_STATUSES
from locbook.static.checks import GOODNESS_OF_FIT_ALPHA
from locbook.static.lateration import LATERATION_PAIRS
from locbook.static.result import LOCALIZATION_STATUSES

pytestmark = pytest.mark.fuzz

FUZZ = settings(max_examples=200, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
FUZZ_SLOW = settings(max_examples=30, deadline=None, derandomize=True,
                     suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])

SPECIALS = {"nan": np.nan, "inf": np.inf, "-inf": -np.inf, "huge": 1e300, "-huge": -1e300, "tiny": 1e-300,
            "+500": 500.0, "zero": 0.0, "negative": -3.0}
MODEL = lb.PathLossModel(-45.0, 2.2, 3.0)
#: names a ValueError may give besides the function's own arguments: the fields of its PathLossModel argument
EXTRA_NAMES = ("model.ref_power_dbm", "model.path_loss_exp", "model.sigma_db")


#: ValueErrors that name no argument of the function they come from (none left: each now names its argument)
KNOWN_UNNAMED: dict[str, str] = {}


def names_an_argument(message: str, names) -> bool:
    """Whether ``message`` names one of ``names`` as a whole word ('y' is not named by 'only', 'distance_m' not by
    'min_distance_m' or 'distance')."""
    return any(re.search(rf"(?<![\w.]){re.escape(name)}(?!\w)", message) for name in names)


class Refused(Exception):
    """The call ended in an allowed, clear error."""


def call(fn, *args, **kwargs):
    """``fn(*args, **kwargs)``; an allowed error becomes :class:`Refused`, any other exception fails the test."""
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return fn(*args, **kwargs)
    except lb.LocbookError as exc:
        assert str(exc), f"{fn.__name__}: a locbook error without a message"
        raise Refused(str(exc)) from None
    except np.linalg.LinAlgError as exc:
        raise AssertionError(f"{fn.__name__}: a raw LinAlgError escaped: {exc}") from exc
    except ValueError as exc:
        names = tuple(inspect.signature(fn).parameters) + EXTRA_NAMES
        assert names_an_argument(str(exc), names) or str(exc).startswith(KNOWN_UNNAMED.get(fn.__name__, "\0")), \
            f"{fn.__name__}: a ValueError that names no argument ({names}): {exc}"
        raise Refused(str(exc)) from None


def refused_or(fn, *args, **kwargs):
    """The result, or None if the call was refused clearly."""
    try:
        return call(fn, *args, **kwargs)
    except Refused as exc:
        event(f"{fn.__name__} refused: {str(exc)[:40]}")
        return None


# -- inputs ------------------------------------------------------------------------------------------------------
LAYOUTS = ("good", "good", "good", "one", "two", "collinear", "nearly_collinear", "coincident", "tiny", "huge")


def layout(kind: str, rng) -> np.ndarray:
    corners = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    good = np.vstack([corners, rng.uniform(1.0, 9.0, (int(rng.integers(0, 3)), 2))])
    if kind == "good":
        return good
    if kind == "one":
        return good[:1]
    if kind == "two":
        return good[:2]
    if kind == "collinear":
        return np.c_[np.linspace(0.0, 10.0, 4), np.linspace(0.0, 5.0, 4)]
    if kind == "nearly_collinear":
        a = np.c_[np.linspace(0.0, 10.0, 4), np.zeros(4)]
        a[1, 1] = 10.0 ** -rng.uniform(7, 12)
        return a
    if kind == "coincident":
        return np.vstack([good, good[int(rng.integers(0, len(good)))]])
    return good * (1e-300 if kind == "tiny" else 1e300)


def batch_shape(draw_index: int):
    return [(), (0,), (1,), (3,), (2, 2)][draw_index]


def inject(values: np.ndarray, specials, rng) -> np.ndarray:
    """``values`` with each special of ``specials`` written at a random entry."""
    values = np.array(values, dtype=float)
    if values.size == 0:
        return values
    flat = values.reshape(-1)
    for name in specials:
        flat[int(rng.integers(0, flat.size))] = SPECIALS[name]
    return flat.reshape(values.shape)


def as_dtype(values: np.ndarray, dtype: str, strided: bool) -> np.ndarray:
    """``values`` in another dtype and/or as a strided view (every other entry of a larger array)."""
    if dtype == "int":
        with np.errstate(invalid="ignore"):
            values = np.round(values).astype(np.int64)
    elif dtype == "float32":
        values = values.astype(np.float32)
    if strided and values.ndim:
        big = np.zeros(values.shape[:-1] + (2 * values.shape[-1],), dtype=values.dtype)
        big[..., ::2] = values
        values = big[..., ::2]
    return values


def same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return np.array_equal(a, b, equal_nan=a.dtype.kind == "f" and b.dtype.kind == "f")


def same_rows(a, b) -> np.ndarray:
    """Per row of ``(k, m)`` arrays: equal, NaN equal to NaN."""
    return np.all((a == b) | (np.isnan(a) & np.isnan(b)), axis=-1)


def same_result(a, b):
    if a is None or b is None:
        assert a is None and b is None, "one dtype/layout of the same values was refused, the other not"
        return
    if isinstance(a, lb.LocalizationResult):
        assert same(a.position_m, b.position_m) and same(a.converged, b.converged) and same(a.status, b.status)
    elif isinstance(a, lb.PathLossFit):
        assert same(a.ref_power_dbm, b.ref_power_dbm) and same(a.path_loss_exp, b.path_loss_exp)
        assert same(a.problem_status, b.problem_status)
    elif isinstance(a, lb.RlsResult):
        assert same(a.x, b.x) and same(a.P, b.P)
    elif hasattr(a, "sigma_db"):                 # a reference-tag calibration
        assert same(a.ref_power_dbm, b.ref_power_dbm) and same(a.sigma_db, b.sigma_db)
    else:
        assert same(a, b)


# -- the rule for each kind of result ----------------------------------------------------------------------------
def judge_localization(res: lb.LocalizationResult, batch, dim: int, with_cost: bool):
    assert res.position_m.shape == batch + (dim,) and res.converged.shape == batch and res.status.shape == batch
    assert set(np.unique(res.status).tolist()) <= set(LOCALIZATION_STATUSES), res.status
    # poor_fit: converged on readings that do not fit the model together (the ML answer is kept)
    assert same(res.converged, np.isin(res.status, ["ok", "poor_fit"]))
    assert np.isfinite(res.position_m[res.converged]).all(), "converged with a NaN position"
    failed = ~np.isin(res.status, ["ok", "not_converged", "poor_fit"])
    assert np.isnan(res.position_m[failed]).all(), "a failed problem with a position"
    if with_cost:
        assert np.isfinite(res.cost[res.converged]).all(), "converged with an infinite or NaN cost"
        # flagged only beyond the chi-square bound: MODEL has one sigma, at least 3 anchors are heard (dof >= 1),
        # and the quantile grows with dof, so every flagged cost exceeds the 1-dof quantile
        poor = res.status == "poor_fit"
        assert np.all(res.cost[poor] / MODEL.sigma_db**2 > chi2.ppf(1 - GOODNESS_OF_FIT_ALPHA, 1))


def judge_fit(fit: lb.PathLossFit, batch):
    assert np.shape(fit.ref_power_dbm) == np.shape(fit.path_loss_exp) == np.shape(fit.problem_status) == batch
    assert set(np.unique(fit.problem_status).tolist()) <= set(FIT_PROBLEM_STATUSES)
    usable = fit.problem_ok
    for name in ("ref_power_dbm", "path_loss_exp", "residual_sigma_db"):
        value = np.asarray(getattr(fit, name))
        assert np.isfinite(value[usable]).all(), f"a usable fit with a non-finite {name}"
        if name != "residual_sigma_db":
            assert np.isnan(value[~usable]).all(), f"an unusable fit with a {name}"
    assert fit.ok == bool(np.all(usable))


# -- lateration, RSS ML, grid ML, k-NN ---------------------------------------------------------------------------
ESTIMATORS = ("ls", "wls", "box", "ml", "grid", "knn")
GRID = np.stack(np.meshgrid(np.arange(0.0, 10.5, 0.5), np.arange(0.0, 10.5, 0.5)), -1).reshape(-1, 2)


def rss_ml_position(rss_dbm, anchors_m, model):
    """:func:`locbook.rss_ml_position` with its RssModel built in the call (the model's refusals count as its own)."""
    return lb.rss_ml_position(rss_dbm, lb.RssModel(anchors_m, model))


def grid_ml_position(rss_dbm, anchors_m, model, cells_m):
    """:func:`locbook.grid_ml_position` with its RssModel built in the call."""
    return lb.grid_ml_position(rss_dbm, lb.RssModel(anchors_m, model), cells_m)


def model_fingerprints(cells_m, anchors_m, model):
    """:func:`locbook.model_fingerprints` with its RssModel built in the call."""
    return lb.model_fingerprints(cells_m, lb.RssModel(anchors_m, model))


def run_estimator(name: str, anchors, readings, scale: float):
    """``readings`` are ranges for the lateration family, powers for the others."""
    if name == "ls":
        return call(lb.lateration_ls, anchors, readings)
    if name == "wls":
        m = np.shape(anchors)[0]
        return call(lb.lateration_wls, anchors, readings, np.arange(1.0, max(m, 1)))
    if name == "box":
        return call(lb.lateration_box_ls, anchors, readings, -scale, 11.0 * scale)
    if name == "ml":
        return call(rss_ml_position, readings, anchors, MODEL)
    if name == "grid":
        return call(grid_ml_position, readings, anchors, MODEL, GRID * scale)
    maps = call(model_fingerprints, GRID * scale, anchors, MODEL)
    return call(lb.knn_position, readings, maps, GRID * scale, 1)


@FUZZ
@given(name=st.sampled_from(ESTIMATORS), kind=st.sampled_from(LAYOUTS), shape=st.integers(0, 4),
       specials=st.lists(st.sampled_from(sorted(SPECIALS)), max_size=2), dtype=st.sampled_from(["float64", "float32",
                                                                                               "int"]),
       strided=st.booleans(), seed=st.integers(0, 2**16))
@pytest.mark.slow
def test_static_estimators(name, kind, shape, specials, dtype, strided, seed):
    rng = np.random.default_rng(seed)
    anchors = layout(kind, rng)
    scale = {"tiny": 1e-300, "huge": 1e300}.get(kind, 1.0)
    batch = batch_shape(shape)
    # true positions on the grid (so grid ML and k-NN can be exact), off the anchors (a tag on an anchor is closer
    # than the RSS ML's near-field clamp, 1 mm, and its power beyond what the model explains)
    away = GRID[np.min(np.linalg.norm(GRID[:, None] - anchors / scale, axis=-1), axis=-1) > 0.3] \
        if len(anchors) else GRID
    truth = away[rng.integers(0, len(away), batch)] * scale
    with np.errstate(all="ignore"):
        distance = np.sqrt(np.sum((truth[..., None, :] - anchors) ** 2, -1))
        readings = distance if name in ("ls", "wls", "box") else \
            MODEL.ref_power_dbm - 10 * MODEL.path_loss_exp * np.log10(np.maximum(distance, 1e-6))
    clean = readings.copy()
    readings = inject(readings, specials, rng)
    try:
        res = run_estimator(name, anchors, readings, scale)
        event(f"{name}: {'answered' if res is not None else 'refused'}")
    except Refused as exc:
        event(f"{name} refused: {str(exc)[:40]}")
        res = None
    # another dtype or a strided view of the same values: the float64 answer on those values, bit for bit
    if dtype != "float64" or strided:
        if not (dtype == "int" and not np.isfinite(readings).all()):
            other = as_dtype(readings, dtype, strided)
            try:
                res_other = run_estimator(name, as_dtype(anchors, dtype, False), other, scale)
            except Refused:
                res_other = None
            try:
                res_same = run_estimator(name, as_dtype(anchors, dtype, False).astype(float),
                                         np.asarray(other, dtype=float), scale)
            except Refused:
                res_same = None
            same_result(res_other, res_same)
    if res is None:
        return
    if name == "knn":
        res = np.asarray(res)
        assert res.shape == batch + (2,)
        ok = np.isfinite(res).all(-1)
        assert np.isnan(res[~ok]).all()
        if kind in ("good",) and not specials:
            np.testing.assert_array_equal(res, truth)
        return
    judge_localization(res, batch, 2, with_cost=name in ("ml", "grid"))
    # a batch is isolated: every problem whose own readings are clean is what the estimator gives it alone,
    # whatever the others hold
    flat_pos, flat_status = res.position_m.reshape(-1, 2), res.status.reshape(-1)
    flat_readings = readings.reshape(-1, readings.shape[-1])
    untouched = same_rows(flat_readings, clean.reshape(flat_readings.shape))
    if flat_readings.shape[0] > 1:
        for i in np.flatnonzero(untouched):
            alone = run_estimator(name, anchors, flat_readings[i], scale)
            assert alone.status == flat_status[i], (i, alone.status, flat_status)
            # a batched matrix product rounds unlike a single one; the ML's last iterate after max_iter steps of a
            # problem that did not converge depends on those ulps, so only its status is compared
            if flat_status[i] != "not_converged":
                np.testing.assert_allclose(flat_pos[i], alone.position_m, rtol=0,
                                           atol=1e-6 if name in ("box", "ml") else 1e-9)
    if kind == "good" and not specials:      # noise-free readings of a well-conditioned layout: the exact position
        assert res.status.size == 0 or set(res.status.ravel().tolist()) == {"ok"}, res.status
        np.testing.assert_allclose(res.position_m, truth, rtol=0, atol=1e-6)


def rss_crlb_m(position_m, anchors_m):
    """The CRLB of the anchors' RSS model (n = 2.2, sigma = 3 dB), its construction inside the refused call."""
    return lb.rss_crlb_m(position_m, lb.RssModel(anchors_m, lb.PathLossModel(0.0, 2.2, 3.0)))


@FUZZ
@given(kind=st.sampled_from(LAYOUTS), shape=st.integers(0, 4), specials=st.lists(st.sampled_from(sorted(SPECIALS)),
                                                                                max_size=2),
       dtype=st.sampled_from(["float64", "float32", "int"]), strided=st.booleans(), seed=st.integers(0, 2**16))
def test_crlb(kind, shape, specials, dtype, strided, seed):
    rng = np.random.default_rng(seed)
    anchors = layout(kind, rng)
    batch = batch_shape(shape)
    position = inject(rng.uniform(0.5, 9.5, batch + (2,)) * {"tiny": 1e-300, "huge": 1e300}.get(kind, 1.0),
                      specials, rng)
    bound = refused_or(rss_crlb_m, position, anchors)
    other = as_dtype(position, dtype, strided)
    same_result(refused_or(rss_crlb_m, other, as_dtype(anchors, dtype, False)),
                refused_or(rss_crlb_m, np.asarray(other, float), as_dtype(anchors, dtype, False).astype(float)))
    if bound is None:
        return
    bound = np.asarray(bound)
    assert bound.shape == batch
    assert not np.any(bound < 0), "a negative bound"
    if kind == "good" and not specials:
        # the bound scales with the layout (exact for a power of two): an invariant of the formula
        assert np.isfinite(bound).all()
        np.testing.assert_allclose(rss_crlb_m(2.0 * position, 2.0 * anchors), 2.0 * bound, rtol=1e-12)


# -- Palvai's lateration from receivers per problem, recursive least squares ------------------------------------
@FUZZ
@given(n=st.integers(0, 6), shape=st.integers(0, 4), specials=st.lists(st.sampled_from(sorted(SPECIALS)), max_size=2),
       where=st.sampled_from(["receivers", "distance"]), reference=st.sampled_from(LATERATION_PAIRS),
       dtype=st.sampled_from(["float64", "float32", "int"]), strided=st.booleans(), collinear=st.booleans(),
       seed=st.integers(0, 2**16))
def test_lateration_ls_with_pairs(n, shape, specials, where, reference, dtype, strided, collinear, seed):
    rng = np.random.default_rng(seed)
    batch = batch_shape(shape)
    receivers = rng.uniform(0.0, 10.0, batch + (n, 2))
    if collinear:
        receivers[..., 1] = 2.0 * receivers[..., 0]
    truth = rng.uniform(0.0, 10.0, batch + (2,))
    distance = np.sqrt(np.sum((receivers - truth[..., None, :]) ** 2, -1))
    if where == "receivers":
        receivers = inject(receivers, specials, rng)
    else:
        distance = inject(distance, specials, rng)
    res = refused_or(lb.lateration_ls, receivers, distance, pairs=reference)
    if dtype != "float64" or strided:
        if dtype != "int" or (np.isfinite(receivers).all() and np.isfinite(distance).all()):
            r_o, d_o = as_dtype(receivers, dtype, strided), as_dtype(distance, dtype, strided)
            same_result(refused_or(lb.lateration_ls, r_o, d_o, pairs=reference),
                        refused_or(lb.lateration_ls, np.asarray(r_o, float), np.asarray(d_o, float),
                                   pairs=reference))
    if res is None:
        return
    judge_localization(res, batch, 2, with_cost=False)
    if not specials and not collinear and n >= 3:
        good = res.status == "ok"
        np.testing.assert_allclose(res.position_m[good], truth[good], rtol=0, atol=1e-6)


@FUZZ
@given(k=st.integers(0, 5), shape=st.integers(0, 4), specials=st.lists(st.sampled_from(sorted(SPECIALS)), max_size=2),
       where=st.sampled_from(["H", "y"]), dtype=st.sampled_from(["float64", "float32", "int"]), strided=st.booleans(),
       seed=st.integers(0, 2**16))
def test_recursive_least_squares(k, shape, specials, where, dtype, strided, seed):
    rng = np.random.default_rng(seed)
    batch = batch_shape(shape)
    H = rng.normal(size=batch + (k, 2))
    y = H @ np.array([1.5, -2.0]) if k else np.zeros(batch + (0,))
    if where == "H":
        H = inject(H, specials, rng)
    else:
        y = inject(y, specials, rng)
    res = refused_or(lb.recursive_least_squares, H, y)
    if dtype != "float64" or strided:
        if dtype != "int" or (np.isfinite(H).all() and np.isfinite(y).all()):
            h_o, y_o = as_dtype(H, dtype, strided), as_dtype(y, dtype, strided)
            same_result(refused_or(lb.recursive_least_squares, h_o, y_o),
                        refused_or(lb.recursive_least_squares, np.asarray(h_o, float), np.asarray(y_o, float)))
    if res is None:
        return
    assert res.x.shape == batch + (k, 2) and res.P.shape == batch + (k, 2, 2)
    # each estimate is finite (a usable answer) or NaN (no answer); never infinite
    assert not np.isinf(res.x).any() and not np.isinf(res.P).any()
    if not specials and k:
        # the regularised batch solution of the rows so far (Palvai 2008, Eqs. (2.49)-(2.58)), here after all rows
        info = np.eye(2) / 1e6 + np.einsum("...ki,...kj->...ij", H, H)
        want = np.linalg.solve(info, np.einsum("...ki,...k->...i", H, y)[..., None])[..., 0]
        np.testing.assert_allclose(res.x[..., -1, :], want, rtol=1e-6, atol=1e-6)


# -- calibration fits --------------------------------------------------------------------------------------------
FIT_MODES = {"closed_form": {}, "exact": {"path_loss_exp_bounds": (1.5, 3.0), "ref_power_bounds_dbm": (-60.0, -30.0)},
             "cvxpy": {"solver": "cvxpy"}, "huber": {"loss": "huber"}}


def _fit_case(rng, n, batch, distinct):
    d = rng.uniform(1.0, 20.0, n) if distinct else np.full(n, 4.0)
    p = np.broadcast_to(-45.0 - 22.0 * np.log10(d), batch + (n,)).copy()
    return d, p


@FUZZ
@given(mode=st.sampled_from(["closed_form", "exact"]), n=st.integers(0, 6), shape=st.integers(0, 4),
       specials=st.lists(st.sampled_from(sorted(SPECIALS)), max_size=2), where=st.sampled_from(["d", "p"]),
       distinct=st.sampled_from([True, True, True, False]), dtype=st.sampled_from(["float64", "float32", "int"]),
       strided=st.booleans(), seed=st.integers(0, 2**16))
def test_fit_path_loss_exact_modes(mode, n, shape, specials, where, distinct, dtype, strided, seed):
    _fuzz_fit(mode, n, shape, specials, where, distinct, dtype, strided, seed)


@FUZZ_SLOW
@given(mode=st.sampled_from(["cvxpy", "huber"]), n=st.integers(0, 5), shape=st.integers(0, 4),
       specials=st.lists(st.sampled_from(sorted(SPECIALS)), max_size=2), where=st.sampled_from(["d", "p"]),
       distinct=st.sampled_from([True, True, True, False]), seed=st.integers(0, 2**16))
def test_fit_path_loss_cvxpy_modes(mode, n, shape, specials, where, distinct, seed):
    _fuzz_fit(mode, n, shape, specials, where, distinct, "float64", False, seed)


def _fuzz_fit(mode, n, shape, specials, where, distinct, dtype, strided, seed):
    rng = np.random.default_rng(seed)
    batch = batch_shape(shape)
    d, p = _fit_case(rng, n, batch, distinct)
    if where == "d":
        d = inject(d, specials, rng)
    else:
        p = inject(p, specials, rng)
    fit = refused_or(lb.fit_path_loss, d, p, **FIT_MODES[mode])
    if dtype != "float64" or strided:
        if dtype != "int" or (np.isfinite(d).all() and np.isfinite(p).all()):
            d_o, p_o = as_dtype(d, dtype, strided), as_dtype(p, dtype, strided)
            same_result(refused_or(lb.fit_path_loss, d_o, p_o, **FIT_MODES[mode]),
                        refused_or(lb.fit_path_loss, np.asarray(d_o, float), np.asarray(p_o, float), **FIT_MODES[mode]))
    if fit is None:
        return
    judge_fit(fit, batch)
    flat_p = np.broadcast_to(p, batch + (n,)).reshape(-1, n)
    if flat_p.shape[0] > 1:      # a batch is isolated: every problem is what fitting it alone gives
        for i in range(flat_p.shape[0]):
            alone = call(lb.fit_path_loss, d, flat_p[i], **FIT_MODES[mode])
            assert alone.problem_status == fit.problem_status.reshape(-1)[i]
            for got, want in ((fit.ref_power_dbm, alone.ref_power_dbm), (fit.path_loss_exp, alone.path_loss_exp)):
                np.testing.assert_allclose(got.reshape(-1)[i], want, rtol=0,
                                           atol=1e-5 if mode in ("cvxpy", "huber") else 1e-12)
    if not specials and distinct and n >= 2:     # noise-free data: the exact parameters
        assert fit.ok
        atol = 1e-4 if mode in ("cvxpy", "huber") else 1e-9
        np.testing.assert_allclose(fit.ref_power_dbm, -45.0, rtol=0, atol=atol)
        np.testing.assert_allclose(fit.path_loss_exp, 2.2, rtol=0, atol=atol)


@FUZZ
@given(mode=st.sampled_from(CALIBRATION_MODES), locations=st.integers(0, 4), kind=st.sampled_from(LAYOUTS),
       shape=st.integers(0, 4), specials=st.lists(st.sampled_from(sorted(SPECIALS)), max_size=2),
       dtype=st.sampled_from(["float64", "float32", "int"]), strided=st.booleans(), seed=st.integers(0, 2**16))
def test_calibrate_path_loss(mode, locations, kind, shape, specials, dtype, strided, seed):
    rng = np.random.default_rng(seed)
    anchors = layout(kind, rng)
    batch = batch_shape(shape)
    points = rng.uniform(0.5, 9.5, (locations, 2)) * {"tiny": 1e-300, "huge": 1e300}.get(kind, 1.0)
    with np.errstate(all="ignore"):
        d = np.broadcast_to(np.sqrt(np.sum((points[:, None] - anchors) ** 2, -1)), batch + (locations, len(anchors)))
        p = -45.0 - 22.0 * np.log10(d)
    p = inject(p, specials, rng)
    fit = refused_or(lb.calibrate_path_loss, d, p, mode)
    if (dtype != "float64" or strided) and (dtype != "int" or np.isfinite(p).all()):
        d_o, p_o = as_dtype(np.ascontiguousarray(d), dtype, strided), as_dtype(p, dtype, strided)
        same_result(refused_or(lb.calibrate_path_loss, d_o, p_o, mode),
                    refused_or(lb.calibrate_path_loss, np.asarray(d_o, float), np.asarray(p_o, float), mode))
    if fit is not None:
        judge_fit(fit, batch + ((len(anchors),) if mode == "per_anchor" else ()))
    if not specials and kind == "good" and locations >= (2 if mode == "per_anchor" else 1):
        # clean and well-posed (per anchor: two locations give two distances; else one location gives the 4 to 6
        # anchors' distinct distances): the fit must be usable and exact, never silently not ok
        assert fit is not None and fit.ok, (mode, locations, None if fit is None else fit.problem_status)
        np.testing.assert_allclose(fit.path_loss_exp, 2.2, rtol=0, atol=1e-9)
        np.testing.assert_allclose(fit.ref_power_dbm, -45.0, rtol=0, atol=1e-8)


@FUZZ
@given(steps=st.integers(0, 3), tags=st.integers(0, 5), kind=st.sampled_from(LAYOUTS), bounded=st.booleans(),
       specials=st.lists(st.sampled_from(sorted(SPECIALS)), max_size=2),
       dtype=st.sampled_from(["float64", "float32", "int"]), strided=st.booleans(), seed=st.integers(0, 2**16))
def test_calibrate_from_reference_tags(steps, tags, kind, bounded, specials, dtype, strided, seed):
    rng = np.random.default_rng(seed)
    readers = layout(kind, rng)
    tag_positions = rng.uniform(0.5, 9.5, (tags, 2))
    model = lb.PathLossModel(-47.0, 2.1)
    with np.errstate(all="ignore"):
        rss = np.broadcast_to(refused_or(model_fingerprints, tag_positions, readers, model)
                              if tags else np.zeros((0, len(readers))), (steps, tags, len(readers)))
    rss = inject(rss, specials, rng)
    kw = {} if bounded else {"ref_power_bounds_dbm": None, "path_loss_exp_bounds": None}
    cal = refused_or(lb.calibrate_from_reference_tags, rss, tag_positions, readers, **kw)
    if (dtype != "float64" or strided) and (dtype != "int" or np.isfinite(rss).all()):
        r_o = as_dtype(rss, dtype, strided)
        same_result(refused_or(lb.calibrate_from_reference_tags, r_o, tag_positions, readers, **kw),
                    refused_or(lb.calibrate_from_reference_tags, np.asarray(r_o, float), tag_positions, readers, **kw))
    if cal is None:
        return
    assert cal.ref_power_dbm.shape == cal.path_loss_exp.shape == (steps, len(readers))
    judge_fit(cal.fit, (steps, len(readers)))
    assert cal.fit.ok, "a calibration returned from a fit that is not usable"
    if not specials and kind == "good":     # two tags at nearby distances: the normal equations lose digits
        np.testing.assert_allclose(cal.path_loss_exp, 2.1, rtol=0, atol=1e-6)
        np.testing.assert_allclose(cal.ref_power_dbm, -47.0, rtol=0, atol=1e-6)


# -- regression tests for what the fuzzing found -----------------------------------------------------------------


@pytest.mark.parametrize("case", ["lateration_ls_pairs", "model_fingerprints", "calibrate_from_reference_tags"])
def test_messages_found_naming_no_argument_now_name_one(case):
    """Found by the fuzzing: a negative distance, and cells, tags or readers so far apart that their distances
    overflow, were refused with messages that blamed no argument (or an internal distance_m); each names one now."""
    fn, args = {"lateration_ls_pairs": (partial(lb.lateration_ls, pairs="consecutive"), (GRID[:3], [1.0, -1.0, 2.0])),
                "model_fingerprints": (model_fingerprints, (GRID[:3] * 1e300, -GRID[:4] * 1e300, MODEL)),
                "calibrate_from_reference_tags": (lb.calibrate_from_reference_tags,
                                                  (np.full((1, 3, 4), -60.0), GRID[:3] + 1.0,
                                                   np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
                                                   * 1e300))}[case]
    with pytest.raises(ValueError) as info, np.errstate(all="ignore"):
        fn(*args)
    assert names_an_argument(str(info.value), tuple(inspect.signature(fn).parameters) + EXTRA_NAMES), str(info.value)


# -- a masked reading is a reading not heard ---------------------------------------------------------
MASK_ANCHORS = np.array([[0.0, 0.0], [20.0, 0.0], [0.0, 20.0], [20.0, 20.0], [10.0, -5.0]])
MASK_GRID = np.stack(np.meshgrid(np.arange(0.0, 20.5, 1.0), np.arange(0.0, 20.5, 1.0)), -1).reshape(-1, 2)
MASK_ESTIMATORS = {
    "lateration_ls": lambda d, p: lb.lateration_ls(MASK_ANCHORS, d),
    "lateration_ls pairs": lambda d, p: lb.lateration_ls(MASK_ANCHORS, d, pairs="last"),
    "lateration_wls": lambda d, p: lb.lateration_wls(MASK_ANCHORS, d, np.ones(4)),
    "lateration_box_ls": lambda d, p: lb.lateration_box_ls(MASK_ANCHORS, d, 0.0, 20.0),
    "rss_ml_position": lambda d, p: lb.rss_ml_position(p, lb.RssModel(MASK_ANCHORS, MODEL)),
    "grid_ml_position": lambda d, p: lb.grid_ml_position(p, lb.RssModel(MASK_ANCHORS, MODEL), MASK_GRID),
}


@FUZZ
@given(name=st.sampled_from(sorted(MASK_ESTIMATORS)), seed=st.integers(0, 10_000),
       share=st.sampled_from([0.0, 0.2, 0.5]),
       garbage=st.sampled_from([0.0, 1e3, -1.0, np.inf, np.nan]))
def test_property_masked_readings_equal_nan_readings_whatever_lies_under_the_mask(name, seed, share, garbage):
    """The result on a masked array (any value under the mask, even inf) equals the result with NaN there, position
    and status alike: the mask is applied by the converter, the data under it never read."""
    rng = np.random.default_rng(seed)
    truth = rng.uniform(1, 19, (4, 2))
    d = np.linalg.norm(truth[:, None] - MASK_ANCHORS, axis=-1)
    power = MODEL.ref_power_dbm - 10 * MODEL.path_loss_exp * np.log10(d) + rng.normal(0, 1, d.shape)
    where = rng.random(d.shape) < share
    masked = lambda v: np.ma.array(np.where(where, garbage, v), mask=where)
    solve = MASK_ESTIMATORS[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        got = solve(masked(d), masked(power))
        ref = solve(np.where(where, np.nan, d), np.where(where, np.nan, power))
    np.testing.assert_array_equal(got.position_m, ref.position_m)
    np.testing.assert_array_equal(got.status, ref.status)
