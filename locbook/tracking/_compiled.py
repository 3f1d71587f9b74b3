"""The compiled paths' switch and their one failure rule (every kernel module: EKF/KF, UKF, grid Bayes, particle
filter, box LS), and the compiled EKF: the same recursion as the numpy loop, run by run in compiled loops over blocks
of runs (the kernels of :mod:`locbook.tracking._kernels`, compiled on first use and cached on disk).

The EKF and the KF use them when ``_NUMBA_ENABLED`` is True (environment variable ``LOCBOOK_NUMBA=0`` turns them off),
the problem has at least ``_NUMBA_MIN_WORK`` run-steps (below that, loading numba would cost more than it saves) and
either the covariance differs between runs or the batch is at most one block of runs (a covariance shared by many runs
is updated once per step by the numpy loop instead). The kernel takes linear streams (H and R constant, per run or
per step), RSS streams and the inertial stream of :mod:`locbook.models.imu` with its Jacobian; other nonlinear
streams, F with run axes or per step (Q may differ per run), walls and outputs beyond x and P run in numpy. Either way
the results are the same to round-off (tests/tracking/test_compiled_equality.py), and every error is raised by the numpy
loop.
"""
from __future__ import annotations

import importlib.util
import os
import warnings

import numpy as np

from .._deprecation import past_wrappers
from .._linalg import _mT
from ..models.base import LinearGaussian
from ..models.imu import InertialMeasurement
from ..models.rss import RssModel
from ._loop import _Setup
from .results import KalmanResult
from .transition import PerStep

_NUMBA_ENABLED = os.environ.get("LOCBOOK_NUMBA", "1").strip().lower() not in ("0", "false", "no", "off")
_NUMBA_MIN_WORK = int(os.environ.get("LOCBOOK_NUMBA_MIN_WORK", "2000").strip() or 2000)
_NUMBA_STATE = {"ready": None}
#: most runs per block of the compiled EKF and UKF (the innermost axis of their buffers, which LLVM vectorises)
_BLOCK_LANES = 256
#: runs up to which the compiled EKF runs even where the numpy loop would compute one covariance for all runs
_SMALL_BATCH = 64
_LINEAR_PARALLEL, _LINEAR_SERIAL, _RSS_PARALLEL, _RSS_SERIAL, _INERTIAL = 0, 1, 2, 3, 4
_LINEAR_KINDS = (_LINEAR_PARALLEL, _LINEAR_SERIAL, _INERTIAL)     # the kinds whose rows use the packed H's columns


def _small_batch(setup: _Setup) -> bool:
    """At most ``_SMALL_BATCH`` runs: the compiled kernel then beats the numpy loop even where that loop computes one
    covariance for all runs (its fixed cost per step is larger than the kernel's arithmetic for so few runs)."""
    return _NUMBA_ENABLED and int(np.prod(setup.batch, dtype=np.int64)) <= _SMALL_BATCH


def _block_width(B: int) -> int:
    """Runs per block of the compiled EKF and UKF for ``B`` runs: blocks of equal width up to ``_BLOCK_LANES`` (500
    runs: 2 blocks of 250), so that the last block pads few lanes. Wide blocks pay each loop's fixed cost once for
    more runs (the measured gain of 256 lanes over 64: benchmarks/RESULTS.md, "Lane width of the compiled
    kernels"); the scratch of a block (about 0.5 MiB for n = 6) stays in a core's L2 cache."""
    blocks = -(-B // _BLOCK_LANES)
    return -(-B // blocks)


def _numba_ready() -> bool:
    """True when numba is installed (checked once, without importing it)."""
    if _NUMBA_STATE["ready"] is None:
        _NUMBA_STATE["ready"] = importlib.util.find_spec("numba") is not None
    return _NUMBA_STATE["ready"]


def _leading(value, batch, B, tail):
    """``value`` (``tail`` or ``batch + tail`` after broadcasting) as ``(1 or B,) + tail``, contiguous."""
    value = np.asarray(value, dtype=float)
    if value.ndim <= len(tail):
        return np.ascontiguousarray(np.broadcast_to(value, tail)[None])
    return np.ascontiguousarray(np.broadcast_to(value, batch + tail).reshape((B,) + tail))


def _leading_steps(value, batch, B, tail, T):
    """A LinearMeasurement's H or R as ``(1 or B, 1 or T) + tail``, contiguous: per step when given ``per_step`` (its
    time axis 1 or ``T`` long, checked by the stream)."""
    if not isinstance(value, PerStep):
        return _leading(value, batch, B, tail)[:, None]
    v = value.value
    if v.ndim <= len(tail) + 1:
        return np.ascontiguousarray(v[None])
    return np.ascontiguousarray(np.broadcast_to(v, batch + v.shape[-3:]).reshape((B,) + v.shape[-3:]))


def _kernel_array(a, dtype) -> np.ndarray:
    """``a`` as a C-contiguous, writable array of ``dtype``, copied only where needed (a read-only array would compile
    a kernel once more for its type)."""
    a = np.ascontiguousarray(a, dtype=dtype)
    return a if a.flags.writeable else a.copy()


def _side_by_side(streams) -> np.ndarray:
    """The streams' readings ``(B, T, m_s)`` side by side, ``(B, T, sum m_s)`` float64 (np.concatenate on the last
    axis). Each step's ``m_s`` readings are copied as one block of bytes (a void view), so numpy runs one loop over the
    B * T steps per stream instead of a call per step: about half the time of np.concatenate here."""
    streams = [np.asarray(z, dtype=float) for z in streams]
    widths = [z.shape[-1] for z in streams]
    Z = np.empty(streams[0].shape[:-1] + (sum(widths),))
    if Z.shape[-1] == 0:                         # no readings at all: no row type to view
        return Z
    offsets = np.cumsum([0] + widths[:-1]) * Z.itemsize
    rows = np.dtype({"names": [f"s{i}" for i in range(len(streams))], "formats": [f"V{8 * m}" for m in widths],
                     "offsets": offsets.tolist(), "itemsize": Z.shape[-1] * Z.itemsize})
    blocks = Z.view(rows)[..., 0]
    for i, z in enumerate(streams):
        if z.shape[-1] == 0:
            continue
        if z.strides[-1] != z.itemsize:          # a step's readings not adjacent: numpy's copy
            Z[..., offsets[i] // Z.itemsize:offsets[i] // Z.itemsize + z.shape[-1]] = z
            continue
        blocks[f"s{i}"] = z.view(f"V{8 * z.shape[-1]}")[..., 0]
    return Z


def _present(kinds) -> tuple:
    """Which kinds of stream a kernel call has: (linear, RSS, inertial), each 1 or None (a kernel compiled for None
    leaves that kind's code out: numba prunes the branch by the argument's type, so a call compiles what it uses)."""
    kinds = set(np.asarray(kinds).tolist())
    return tuple(1 if kinds & set(group) else None
                 for group in ((_LINEAR_PARALLEL, _LINEAR_SERIAL), (_RSS_PARALLEL, _RSS_SERIAL), (_INERTIAL,)))


def _pack_linear(meas, batch, B, n, T):
    """A linear stream (:class:`~locbook.models.base.LinearGaussian`): its H and R, per run and step."""
    model, m = meas.model, meas.model.n_readings
    if meas.mode == "serial" and meas.order != "given":
        return None                 # a per-run order of linear rows: numpy
    return (_LINEAR_PARALLEL if meas.mode == "parallel" else _LINEAR_SERIAL,
            (_leading_steps(model.H, batch, B, (m, n), T), _leading_steps(model.R, batch, B, (m, m), T)), None, None)


def _pack_rss(meas, batch, B, n, T):
    """An RSS stream (:class:`~locbook.models.rss.RssModel`): anchors ``(1 or B, 1 or T, m, dim)``, channel and its
    scalars; None (the numpy path) for walls, per-step channel parameters or more than three dimensions."""
    model = meas.model
    ch, m = model.channel, model.n_readings
    walls = model.walls_m is not None and ch.wall_attenuation_db != 0.0
    if model.dim + (model.tag_height_m is not None) > 3 or walls or model.per_step_channel or \
            not np.isfinite(ch.wall_attenuation_db):
        return None
    given = model.anchors_m
    per_step = isinstance(given, PerStep)
    anchors = np.asarray(given.value if per_step else given, dtype=float)
    dim = anchors.shape[-1]
    if not per_step:                            # fixed or per run: one time slot
        anchors = anchors[..., None, :, :]
    if anchors.ndim == 3:
        a = anchors[None]
    else:
        a = np.broadcast_to(anchors, batch + anchors.shape[-3:]).reshape((B,) + anchors.shape[-3:])
    idx = np.asarray(model.state_position_index, dtype=np.int64)
    tag = np.nan if model.tag_height_m is None else float(model.tag_height_m)
    return (_RSS_PARALLEL if meas.mode == "parallel" else _RSS_SERIAL, None,
            (dim, a, *(_leading(v, batch, B, (m,)) for v in (ch.ref_power_dbm, ch.path_loss_exp, ch.sigma_db))),
            (dim, float(ch.ref_distance_m), model.clamp_m, float(model.anchor_sigma_m), tag,
             tuple(idx) + (0,) * (3 - idx.size), idx.size, meas.order == "descending"))


def _pack_inertial(meas, batch, B, n, T):
    """An inertial stream (:class:`~locbook.models.imu.InertialMeasurement`): packed as a linear stream's readings
    and R, H marking the four components the readings depend on; its parameters ``(body frame, acceleration indices,
    heading index, yaw-rate index)`` for the kernels, which evaluate the same function."""
    model = meas.model
    index = model.acceleration_index + (model.heading_index, model.yaw_rate_index)
    if meas.mode != "parallel" or min(index) < 0 or max(index) >= n or len(set(index)) != 4:
        return None                 # an index from the end (numpy's h takes it; the kernels count from 0)
    H = np.zeros((3, n))
    H[0, list(index)] = 1.0
    R = _leading(model.R, batch, B, (3, 3))[:, None]
    return (_INERTIAL, (np.ascontiguousarray(H[None, None]), R), None,
            None, (int(model.frame == "body"),) + index)


# The compiled backend's registry: a packer per model type (exact type: a subclass may change the arithmetic). A
# stream whose model has no packer runs the whole filter on the numpy path.
_PACKERS = {LinearGaussian: _pack_linear, RssModel: _pack_rss, InertialMeasurement: _pack_inertial}


def _pack_streams(setup: _Setup, measurements, B):
    """The streams as the kernels' flat arrays (readings side by side on one axis) and the inertial parameters
    ``(streams, 5)`` (zeros for the other streams), or None if a stream's model has no packer (:data:`_PACKERS`) or
    its packer declines."""
    batch, T, n = setup.batch, setup.T, setup.n
    kinds, cols, lin, rss, scal, iner = [], [0], [], [], [], []
    for meas in measurements:
        packer = _PACKERS.get(type(meas.model))
        entry = None if packer is None else packer(meas, batch, B, n, T)
        if entry is None:
            return None
        m = meas.model.n_readings
        c0 = cols[-1]
        cols.append(c0 + m)
        kind, lin_part, rss_part, scalars = entry[:4]
        kinds.append(kind)
        if lin_part is not None:
            lin.append((c0, m) + lin_part)
        if rss_part is not None:
            rss.append((c0, m) + rss_part)
        scal.append(scalars if scalars is not None else (2, 1.0, 1.0, 0.0, 0.0, (0, 0, 0), 0, False))
        iner.append(entry[4] if len(entry) > 4 else (0, 0, 0, 0, 0))
    # the readings (B, T, M): a step's readings of all streams side by side (one stream: its own array when it is
    # already laid out so, no copy)
    flat = [z.reshape((B,) + z.shape[-2:]) for z in setup.zs]
    Z = _kernel_array(flat[0], float) if len(flat) == 1 else _side_by_side(flat)
    M = cols[-1]
    BH, TH = (max([h.shape[i] for _, _, h, _ in lin] + [1]) for i in (0, 1))
    BR, TR = (max([r.shape[i] for _, _, _, r in lin] + [1]) for i in (0, 1))
    H, R = np.zeros((BH, TH, M, n)), np.zeros((BR, TR, M, M))      # runs, steps (1 when the same throughout)
    for c0, m, h, r in lin:
        H[:, :, c0:c0 + m] = h
        R[:, :, c0:c0 + m, c0:c0 + m] = r
    BA = max([e[3].shape[0] for e in rss] + [1])
    TA = max([e[3].shape[1] for e in rss] + [1])
    BC = max([max(e[4].shape[0], e[5].shape[0], e[6].shape[0]) for e in rss] + [1])
    A, P0c, PLE, SIG = np.zeros((BA, TA, M, 3)), np.zeros((BC, M)), np.zeros((BC, M)), np.zeros((BC, M))
    for c0, m, dim, a, p0, ple, sigma in rss:
        A[:, :, c0:c0 + m, :dim] = a
        P0c[:, c0:c0 + m], PLE[:, c0:c0 + m], SIG[:, c0:c0 + m] = p0, ple, sigma
    dims, ref_d, clamp, anchor_sigma, tag_h, pidx, npos, desc = (np.array(v) for v in zip(*scal))
    nz, nnz = np.zeros((len(kinds), n), np.int64), np.zeros(len(kinds), np.int64)
    for s, (kind, c0, c1) in enumerate(zip(kinds, cols[:-1], cols[1:])):     # the columns a row can use
        used = np.flatnonzero(np.any(H[:, :, c0:c1] != 0, axis=(0, 1, 2))) if kind in _LINEAR_KINDS else \
            np.asarray(pidx[s][:npos[s]], np.int64)
        nz[s, :used.size], nnz[s] = used, used.size
    packed = (np.array(kinds, np.int64), np.array(cols, np.int64), nz, nnz, Z, H, R, A, P0c, PLE, SIG,
              dims.astype(np.int64), ref_d.astype(float), clamp.astype(float), anchor_sigma.astype(float),
              tag_h.astype(float), pidx.astype(np.int64).reshape(-1, 3), npos.astype(np.int64), desc.astype(np.bool_))
    return packed, np.array(iner, dtype=np.int64)


# The one rule of every compiled path (EKF/KF, UKF, grid Bayes, particle filter, box LS): where numba cannot compile
# or run a kernel, one RuntimeWarning names it and every compiled path is off for the rest of the session (numpy
# answers, with the same numbers to round-off). The kernel modules are imported on first use only (so that ``import
# locbook`` never loads numba); those with a trial run it once on a tiny problem (_kernel_module).
_KERNEL_MODULES: dict = {}


def _compiled_failed(what: str, exc: Exception, stacklevel: int) -> None:
    """The rule above, for the compiled ``what`` that raised ``exc``; ``stacklevel`` counts from the caller (as
    ``warnings.warn``'s from its caller: the warning points at the user's line; a deprecation wrapper of the public
    function, :func:`locbook._deprecation.old_form`, is not counted)."""
    global _NUMBA_ENABLED
    _NUMBA_ENABLED = False
    warnings.warn(f"locbook: the compiled {what} failed ({type(exc).__name__}: {exc}); using numpy from now on "
                  "(set LOCBOOK_NUMBA=0 to skip the attempt)", RuntimeWarning,
                  stacklevel=past_wrappers(stacklevel + 1))


def _kernel_module(name: str, trial, what: str, stacklevel: int):
    """The kernel module ``name`` (e.g. ``"locbook.tracking._grid_kernels"``) when the compiled paths are on (numba
    installed, ``LOCBOOK_NUMBA`` not 0, no failure yet), imported and checked once per session, else None.
    ``trial()`` builds a tiny problem with our own code (unguarded: an error of ours must not turn numba off) and
    returns ``run(module)``, which calls the kernels on it; an import or a ``run`` that raises applies the rule above
    (``what`` names the path in the warning; ``stacklevel`` counts the frames from here to the user's call, this
    function being 1)."""
    if not _NUMBA_ENABLED or not _numba_ready():
        return None
    if name not in _KERNEL_MODULES:
        run = trial()
        try:
            module = importlib.import_module(name)
            run(module)
        except Exception as exc:    # noqa: BLE001 - numba's compile and lowering errors have no common base
            _compiled_failed(what, exc, stacklevel)
            return None
        _KERNEL_MODULES[name] = module
    return _KERNEL_MODULES[name]


def _call_kernel(kernel, args, name: str):
    """``kernel(*args)``, or None when numba could not compile or run it (the rule above). Only the kernel call is
    guarded: an error of ours before it must not turn numba off."""
    try:
        return kernel(*args)
    except Exception as exc:        # noqa: BLE001 - numba's compile and lowering errors have no common base
        _compiled_failed(name, exc, 4)
        return None


def _compiled_ekf(setup: _Setup, measurements, predict_first: bool):
    """:func:`locbook.extended_kalman_filter` by the compiled kernel when it applies (numba installed and enabled, F
    without run axes, the streams of the module docstring, a large enough problem), else None: the numpy loop then runs.
    It also returns None when an update fails (a covariance that is not positive definite, a state that is not finite):
    the numpy loop then redoes the filter and raises the library's error for it."""
    F, Q, batch, T = setup.F, setup.Q, setup.batch, setup.T
    B = int(np.prod(batch, dtype=np.int64))
    if not _NUMBA_ENABLED or not setup.plain_motion:
        return None                 # time-varying or nonlinear motion, a control input: numpy
    if F.ndim != 2 or B * T < _NUMBA_MIN_WORK or B == 0 or T == 0:
        return None
    if not (np.array_equal(Q, _mT(Q)) and np.array_equal(setup.P, _mT(setup.P))):
        return None                 # the kernel keeps P exactly symmetric (it computes one triangle of F P F^T + Q)
    if not _numba_ready():
        return None
    packing = _pack_streams(setup, measurements, B)
    if packing is None:
        return None
    packed, iner = packing
    n, S = F.shape[-1], setup.steps.size
    Fi, Fj = np.nonzero(F)
    P0 = setup.P[None] if setup.P.ndim == 2 else np.broadcast_to(setup.P, batch + (n, n)).reshape(B, n, n)
    out_x, out_P = np.empty((B, S, n)), np.empty((B, S, n, n))
    out_nis, out_dof, out_ll = np.empty((B, T)), np.empty((B, T), np.int64), np.empty((B, T))
    args = (Fi.astype(np.int64), Fj.astype(np.int64), np.ascontiguousarray(F[Fi, Fj]), _leading(Q, batch, B, (n, n)),
            np.ascontiguousarray(setup.x.reshape(B, n)), np.ascontiguousarray(P0), bool(predict_first),
            setup.slot.astype(np.int64), np.array(setup.active, dtype=np.bool_).reshape(-1, T), *packed, iner, out_x,
            out_P, out_nis, out_dof, out_ll, _block_width(B), *_present(packed[0]))
    from . import _kernels  # lazy: numba loads only when the compiled path runs
    status = _call_kernel(_kernels._nb_ekf, args, "EKF")
    if status is None or status:
        return None
    return KalmanResult(out_x.reshape(batch + (S, n)), out_P.reshape(batch + (S, n, n)), setup.steps,
                        log_likelihood=out_ll.reshape(batch + (T,)), nis=out_nis.reshape(batch + (T,)),
                        nis_dof=out_dof.reshape(batch + (T,)))
