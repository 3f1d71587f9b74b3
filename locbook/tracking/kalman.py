"""The linear and extended Kalman filters, vectorized over leading Monte-Carlo axes: one argument order for the whole
Kalman family (motion ``F, Q``, then the prior ``x0, P0``, then the measurement streams), one result
(:class:`locbook.tracking.results.KalmanResult`).

Standard recursion (filterpy / Dogan 2015, Table 3.1 notation; :mod:`locbook.tracking.functional`):

    x_{k|k-1} = F x_{k-1|k-1}                      P_{k|k-1} = F P_{k-1|k-1} F^T + Q
    S_k = H P_{k|k-1} H^T + R                      K_k = P_{k|k-1} H^T S_k^{-1}
    x_{k|k} = x_{k|k-1} + K_k (z_k - H x_{k|k-1})
    P_{k|k} = (I - K_k H) P_{k|k-1} (I - K_k H)^T + K_k R K_k^T     (Joseph form)

Document 003 (George and Vadivukkarasi, Eqs. (9)-(13)) prints the update with ``X_{k-1}`` and
``P_{k-1}`` in place of the predicted quantities, so the prediction of Eqs. (9)-(10) is computed and
then discarded. That literal form is available as ``variant="literal_george"`` (flagged; the paper prints no
year, so the name has none): it reduces to a running average of the measurements. The default is
``variant="corrected"`` (``"standard"``, its earlier name, is accepted for one release with a ``DeprecationWarning``).

The module's layout: the streams and their updates in :mod:`locbook.tracking.streams`, the functional
predict / update in :mod:`locbook.tracking.functional`, the shared time loop in ``_loop``, the compiled EKF in
``_compiled`` / ``_kernels``, the result and the consistency guard (NIS, divergence flags, batch isolation) in
:mod:`locbook.tracking.results`.
"""
from __future__ import annotations

from .._deprecation import RENAMED_KF_VARIANTS, check_variant
from . import _compiled
from ._loop import _check_outputs, _covariance_shared_throughout, _run, _setup, _streams
from .results import DIVERGENCE_PROBABILITY, DIVERGENCE_WINDOW, KalmanResult, _check_guard, _flag
from .streams import _ekf_update
from .transition import MotionModel

__all__ = ["kalman_filter", "extended_kalman_filter", "KF_VARIANTS"]

#: the KF's update forms: the corrected (standard) recursion and George and Vadivukkarasi's printed one (flagged)
KF_VARIANTS = ("corrected", "literal_george")


def kalman_filter(F, Q, x0, P0, measurements, *, B=None, u=None, record=None, predict_first: bool = True,
                  variant: str = "corrected", joseph: bool = True, outputs=(),
                  divergence_window: int | None = DIVERGENCE_WINDOW,
                  divergence_probability: float = DIVERGENCE_PROBABILITY) -> KalmanResult:
    """Linear Kalman filter over one or several :class:`LinearMeasurement` streams, vectorized over leading
    Monte-Carlo axes: :func:`extended_kalman_filter` restricted to linear streams, with the KF's own options.

    Parameters
    ----------
    F, Q : motion ``(n, n)`` and process covariance (symmetric positive semi-definite, checked up front); may carry
        run axes ``batch + (n, n)``, or be given per step, ``per_step(batch + (T, n, n))`` (F_k moves step k - 1 to
        step k; :mod:`locbook.tracking.transition`). An unmarked stack of T matrices (filterpy's list of per-step
        ``Fs``) in a call whose readings, x0 and P0 have no run axes would be T runs: it is refused, naming
        ``per_step`` (so are such stacks of B and a stream's H, and filterpy's lists of Q and R; an array of Q or R
        stays a run axis, e.g. a sweep of noise levels).
    B, u : the control input: ``x_{k|k-1} = F_k x_{k-1} + B_k u_k``, ``u`` ``batch + (T, p)``, ``B`` ``(n, p)``,
        ``batch + (n, p)`` or ``per_step(...)``; pykalman's transition offsets are ``B = I``.
    x0, P0 : initial state ``batch + (n,)`` and covariance. With ``predict_first=True`` they are the posterior one
        step *before* the first reading (filterpy's convention: predict, then update, at every step); with
        ``predict_first=False`` the prior at the first reading, used without a prediction.
    measurements : a :class:`LinearMeasurement` (readings ``batch + (T, m)``, H, R) or a list of them on one time
        grid, applied in order at each step. A NaN reading is a missing component: the update uses those present
        and a step without any is prediction only. ``T = 0`` steps give an empty result.
    record : step indices to keep (default all).
    outputs : optional fields to keep at those steps, among
        ``("x_pred", "P_pred", "P_cross", "innovation", "S")`` (:class:`~locbook.tracking.results.KalmanResult`).
    variant : ``"corrected"`` (the standard recursion) or ``"literal_george"`` (Eqs. (11)-(13) of George and
        Vadivukkarasi as printed: each update starts from the previous posterior; ``x_pred`` and ``P_pred`` are then
        that posterior).
    joseph : the Joseph-form covariance update (keeps P symmetric positive definite); False: ``(I - K H) P``.
    divergence_window, divergence_probability : the consistency guard (:mod:`locbook.tracking.results`): a run whose
        NIS exceeds ``chi2.ppf(divergence_probability, dof)`` at ``divergence_window`` consecutive updates is flagged
        in ``diverged`` / ``diverged_step``; 0 or None turns it off.

    Returns a :class:`~locbook.tracking.results.KalmanResult`. Speed: as :func:`extended_kalman_filter` (compiled
    loops over blocks of runs; with the same components missing in every run and F, Q, P0, H, R without run axes,
    more than 64 runs share one covariance recursion, once per step in numpy).

    Examples
    --------
    A constant, read twice as 2.0 with unit variance from the prior N(0, 1): the posterior means are 2 k / (k + 1) and
    the variances 1 / (k + 1) after k readings.

    >>> import numpy as np
    >>> import locbook as lb
    >>> run = lb.kalman_filter([[1.0]], [[0.0]], [0.0], [[1.0]], lb.LinearMeasurement([[2.0], [2.0]], [[1.0]], [[1.0]]))
    >>> print(np.round(run.mean[:, 0], 4), np.round(run.cov[:, 0, 0], 4))
    [1.     1.3333] [0.5    0.3333]
    """
    variant = check_variant(variant, KF_VARIANTS, where="kalman_filter", renamed=RENAMED_KF_VARIANTS)
    window, probability = _check_guard(divergence_window, divergence_probability)
    outputs = _check_outputs(outputs)
    measurements = _streams(measurements)
    if isinstance(F, MotionModel) and not F.linear:
        raise ValueError("kalman_filter takes a linear motion F; a NonlinearMotion needs extended_kalman_filter or "
                         "unscented_kalman_filter")
    if not all(m.model.linear for m in measurements):
        raise ValueError("kalman_filter takes LinearMeasurement streams (linear models), got "
                         f"{[m.name for m in measurements]} (RSS and nonlinear streams: "
                         "extended_kalman_filter or unscented_kalman_filter)")
    setup = _setup(F, Q, x0, P0, measurements, record, "kalman_filter", B, u)
    if variant == "corrected" and joseph and not outputs and (
            _compiled._small_batch(setup) or not _covariance_shared_throughout(setup, measurements)):
        compiled = _compiled._compiled_ekf(setup, measurements, predict_first)
        if compiled is not None:
            return _flag(compiled, window, probability)
    return _flag(_run(setup, measurements, lambda x, P, z, meas, k, want: _ekf_update(x, P, z, meas, k, want, joseph),
                      predict_first, shared=True, literal=variant == "literal_george", joseph=joseph, outputs=outputs),
                 window, probability)


def extended_kalman_filter(F, Q, x0, P0, measurements, *, B=None, u=None, record=None, predict_first: bool = True,
                           outputs=(),
                           divergence_window: int | None = DIVERGENCE_WINDOW,
                           divergence_probability: float = DIVERGENCE_PROBABILITY) -> KalmanResult:
    """Multi-rate (extended) Kalman filter on one time grid, vectorized over leading Monte-Carlo axes.

    At every step: predict with ``x = F x + B u``, ``P = F P F^T + Q`` (F, Q constant, with run axes or
    ``per_step``; or any motion model of the protocol (:class:`~locbook.models.base.MotionModel`): a linear one, e.g.
    a :class:`~locbook.models.motion.KinematicModel`, by its F and Q (``Q=None``: the model's own), a nonlinear one,
    e.g. a :class:`~locbook.tracking.transition.NonlinearMotion` ``f`` with its Jacobian J: ``x = f(x) + B u``,
    ``P = J P J^T + Q``; :mod:`locbook.tracking.transition`; what a user's f and J return is checked: real, the state's
    shape, finite, else one line naming the motion, the function and the step, and a filterpy-style ``fx(x, dt)`` gets
    a line saying how to bind dt), then apply
    the ``measurements`` in the given order, each update starting from the previous one's posterior (Dogan
    Table 3.5: acceleration first, then RSS at RSS epochs). Each entry is a :class:`~locbook.tracking.streams.Stream`
    of readings and any measurement model (:class:`~locbook.models.base.MeasurementModel`, linearised at the state so
    far; one stream may be given without a list): the library's :func:`LinearMeasurement` (KF, e.g. accelerometer or
    MLE position fixes), :func:`RssMeasurement` (parallel or serial EKF), :func:`NonlinearMeasurement` with its
    Jacobian, or a user's model. Covariance updates use
    the Joseph form (Tables 3.1-3.4 print ``P - K S K^T``; equal in exact arithmetic).

    ``x0``, ``P0``: ``batch + (n,)``, ``batch + (n, n)``; with ``predict_first`` (filterpy's convention) they
    are the posterior one step before step 0, else the prior at step 0. ``record``: step indices to return
    (default all); ``outputs``: optional fields among ``("x_pred", "P_pred", "P_cross", "innovation", "S")`` kept at
    those steps
    (innovations of several streams and serial updates side by side, S block diagonal: :mod:`locbook.tracking.results`).
    ``F``, ``Q``, ``P0`` and the streams' H, R and anchors may carry run axes (the batch is the broadcast of all run
    axes); Q, P0 and R must be symmetric positive semi-definite (checked up front).

    ``divergence_window``, ``divergence_probability``: the consistency guard (:mod:`locbook.tracking.results`). The
    result's ``nis`` ``batch + (T,)`` sums the NIS of the step's updates (for a serial stream, its scalar updates,
    whose innovations are independent under the model, so the sum is chi-square with one dof per reading: exactly for
    a LinearMeasurement, to first order for an RSS or nonlinear stream, whose h is linearised), and
    ``log_likelihood`` their Gaussian log-likelihoods; a run whose NIS exceeds ``chi2.ppf(divergence_probability,
    dof)`` at ``divergence_window`` consecutive updates is flagged in ``diverged`` with its ``diverged_step``; 0 or
    None turns the flag off. A flag means the run's innovations stay inconsistent with its covariance: a lost track,
    or (at many readings per step) a noise level far off (the results module's docstring gives the probabilities).

    Speed: compiled loops (numba, ``locbook.tracking._compiled``) run blocks of runs, except when the covariance is the
    same in every run of a large batch (more than one block of runs): numpy then updates it once per step for all runs.
    ``LOCBOOK_NUMBA=0`` turns the compiled loops off; they do not produce ``outputs`` and do not take nonlinear or
    time-varying motion (the numpy loop runs those). All paths give the same numbers to round-off.

    Examples
    --------
    A static tag at (3, 4) m ranged from three anchors, starting from (5, 5) m:

    >>> import numpy as np
    >>> import locbook as lb
    >>> anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])
    >>> def ranges(x):                                   # states (..., 2) -> ranges (..., 3)
    ...     return np.linalg.norm(x[..., None, :] - anchors, axis=-1)
    >>> def jacobian(x):                                 # (..., 3, 2)
    ...     d = x[..., None, :] - anchors
    ...     return d / np.linalg.norm(d, axis=-1, keepdims=True)
    >>> z = np.tile(ranges(np.array([3.0, 4.0])), (5, 1))            # five steps of exact ranges (T, m)
    >>> run = lb.extended_kalman_filter(np.eye(2), 1e-6 * np.eye(2), [5.0, 5.0], 4.0 * np.eye(2),
    ...                                 lb.NonlinearMeasurement(z, ranges, 0.01 * np.eye(3), jacobian))
    >>> print(np.round(run.mean[-1], 3))
    [3.013 4.002]
    """
    window, probability = _check_guard(divergence_window, divergence_probability)
    outputs = _check_outputs(outputs)
    measurements = _streams(measurements)
    setup = _setup(F, Q, x0, P0, measurements, record, "extended_kalman_filter", B, u)
    if not outputs and (_compiled._small_batch(setup) or not _covariance_shared_throughout(setup, measurements)):
        compiled = _compiled._compiled_ekf(setup, measurements, predict_first)
        if compiled is not None:
            return _flag(compiled, window, probability)
    return _flag(_run(setup, measurements, _ekf_update, predict_first, shared=True, outputs=outputs),
                 window, probability)
