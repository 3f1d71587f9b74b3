"""Posterior Cramer-Rao lower bound (PCRLB) for filtering: the Tichavsky recursion (Dogan 2015, Ch. 4).

For ``x_{k+1} = F x_k + w_k``, ``w_k ~ N(0, Q)`` and measurements with Fisher information ``J_z`` about
``x_{k+1}``, the information matrix of any unbiased filter obeys (Tichavsky, Muravchik and Nehorai 1998;
Dogan Eqs. (4.7)-(4.16))

    J_{k+1} = D22 - D21 (J_k + D11)^{-1} D12,
    D11 = F^T Q^{-1} F,  D12 = D21^T = -F^T Q^{-1},  D22 = Q^{-1} + J_z,

which by the matrix-inversion lemma equals the information-filter Riccati form
``J_{k+1} = (F J_k^{-1} F^T + Q)^{-1} + J_z`` (the form Stone Soup's ``PCRBMetric`` uses, and the only one
that tolerates a singular Q). ``J_0`` is the prior information ``P_{0|0}^{-1}`` (Eq. (4.11)).

``J_z`` is ``H^T R^{-1} H`` for a linear measurement (the "linear" bound of Dogan Figs. 4.2/4.4, and the KF's own
information recursion), or for RSS the expectation of ``H(x)^T R^{-1} H(x)`` over the state (Eq. (4.18)),
approximated by an average over simulated trajectories (Eq. (4.22)); evaluated at one known trajectory it is
the truth-conditioned bound.
"""
from __future__ import annotations

import numpy as np

from .._deprecation import warn_deprecated
from .._linalg import _mT
from .._validate import as_array, check_choice
from .crlb import _bound_model, _old_form, _old_model, rss_position_information

__all__ = ["posterior_crlb", "position_bound_m", "rss_state_information", "linear_measurement_information",
           "PCRLB_FORMS"]

PCRLB_FORMS = ("tichavsky", "riccati")


def _inv(a):
    return np.linalg.inv(a)


def posterior_crlb(prior_information, F, Q, measurement_information, *, form: str = "tichavsky"):
    """Information matrices ``(K + 1, ..., n, n)`` of the PCRLB over ``K`` steps.

    ``prior_information``: ``J_0`` ``(..., n, n)``; ``F``, ``Q``: ``(n, n)`` (or with the batch axes);
    ``measurement_information``: ``J_z`` for steps 1..K, ``(K, ..., n, n)`` (zeros where no measurement arrives).
    ``form="tichavsky"`` is Eq. (4.7) as printed (needs an invertible Q); ``"riccati"`` is the equivalent
    information-filter form.

    Examples
    --------
    A constant-velocity state whose position is measured with variance 1/4 at each of three steps, from a unit prior:
    the position bound (the root of the first diagonal entry of ``J^-1``) falls from 1 m towards the measurement's
    0.5 m.

    >>> import numpy as np
    >>> import locbook as lb
    >>> F, Q = np.array([[1.0, 1.0], [0.0, 1.0]]), 0.01 * np.eye(2)
    >>> J = lb.posterior_crlb(np.eye(2), F, Q, np.broadcast_to(np.diag([4.0, 0.0]), (3, 2, 2)))
    >>> print(J.shape, np.round(np.sqrt(np.linalg.inv(J)[:, 0, 0]), 3))
    (4, 2, 2) [1.    0.472 0.448 0.429]
    """
    check_choice("form", form, PCRLB_FORMS)
    F = as_array("F", F)
    if F.ndim < 2 or F.shape[-1] != F.shape[-2]:
        raise ValueError(f"F must be square (n, n) or batch + (n, n), got {F.shape}")
    n = F.shape[-1]
    shapes = {}
    for name, value, lead in (("prior_information", prior_information, 0), ("Q", Q, 0),
                              ("measurement_information", measurement_information, 1)):
        value = as_array(name, value)
        if value.ndim < 2 + lead or value.shape[-2:] != (n, n):
            raise ValueError(f"{name} must have shape {'(K, ...' if lead else '(...'}, {n}, {n}), got {value.shape}")
        shapes[name] = value
    j, Q, jz = shapes["prior_information"], shapes["Q"], shapes["measurement_information"]
    if form == "tichavsky":
        try:
            q_inv = _inv(Q)
        except np.linalg.LinAlgError as exc:
            raise np.linalg.LinAlgError("the Tichavsky form needs an invertible Q; use form='riccati'") from exc
        d11 = _mT(F) @ q_inv @ F
        d12 = -_mT(F) @ q_inv
        d21 = _mT(d12)
    out = np.empty((jz.shape[0] + 1,) + np.broadcast_shapes(j.shape, jz.shape[1:]))
    out[0] = j
    for k in range(jz.shape[0]):
        if form == "tichavsky":
            j = q_inv + jz[k] - d21 @ _inv(j + d11) @ d12                       # Eqs. (4.7), (4.14)-(4.16)
        else:
            j = _inv(F @ _inv(j) @ _mT(F) + Q) + jz[k]
        out[k + 1] = j
    return out


def position_bound_m(information, position_index):
    """Dogan Eq. (4.23): ``sqrt(sum_i [J^{-1}]_{ii})`` over the position indices -> ``(...)``."""
    information = as_array("information", information, min_ndim=2)
    if information.shape[-1] != information.shape[-2]:
        raise ValueError(f"information must be square (..., n, n), got {information.shape}")
    cov = _inv(information)
    idx = np.asarray(position_index)
    return np.sqrt(cov[..., idx, idx].sum(axis=-1))


def linear_measurement_information(H, R):
    """``H^T R^{-1} H`` for a linear-Gaussian measurement (Dogan Eq. (4.16))."""
    H = as_array("H", H, min_ndim=2)
    R = as_array("R", R, min_ndim=2)
    if R.shape[-2:] != (H.shape[-2],) * 2:
        raise ValueError(f"R must have shape ({H.shape[-2]}, {H.shape[-2]}) for H with {H.shape[-2]} rows, "
                         f"got {R.shape}")
    return _mT(H) @ _inv(R) @ H


def _old_state_information(states, anchors_m, path_loss_exp, sigma_db, position_index, *,
                           min_distance_m: float = 0.0, height_offset_m: float = 0.0, heard=None):
    warn_deprecated("rss_state_information(states, anchors_m, path_loss_exp, sigma_db, position_index, ...)",
                    "rss_state_information(states, RssModel(anchors_m, PathLossModel(0.0, path_loss_exp, sigma_db, "
                    "min_distance_m=...)), position_index, heard=...)", skip=(__name__, "locbook.bounds.crlb"))
    return rss_state_information(states, _old_model(anchors_m, path_loss_exp, sigma_db, min_distance_m=min_distance_m,
                                                    height_offset_m=height_offset_m), position_index, heard=heard)


@_old_form(_old_state_information)
def rss_state_information(states, model, position_index, *, heard=None):
    """Fisher information of RSS from every anchor about the full state, ``(..., n, n)`` for states ``(..., n)``.

    ``Lambda(x) = H(x)^T R^{-1} H(x)`` (Dogan Eq. (4.19)), ``R = sigma^2 I``: the one RSS model's Fisher information
    (``model``, an :class:`~locbook.models.rss.RssModel`: :meth:`locbook.models.rss.RssModel.fisher_information`,
    through :func:`locbook.bounds.crlb.rss_position_information` with the model's near-anchor regularisations, the
    anchors' heights above the tag and the channel's clamp giving 0 within ``min_distance_m``, and its ``heard`` mask
    for readings that are not there) in the position block ``position_index``.
    """
    model = _bound_model(model, "rss_state_information")
    states = as_array("states", states, min_ndim=1)
    idx = np.asarray(position_index)
    if idx.ndim != 1 or idx.size == 0 or idx.max() >= states.shape[-1]:
        raise ValueError(f"position_index must index the {states.shape[-1]} state entries, got {position_index!r}")
    block = rss_position_information(states[..., idx], model, heard=heard)
    out = np.zeros(states.shape + (states.shape[-1],))
    out[..., idx[:, None], idx[None, :]] = block
    return out
