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

from .bounds import rss_position_information
from .filters import _mT

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
    """
    if form not in PCRLB_FORMS:
        raise ValueError(f"form must be one of {PCRLB_FORMS}, got {form!r}")
    j = np.asarray(prior_information, dtype=float)
    F = np.asarray(F, dtype=float)
    Q = np.asarray(Q, dtype=float)
    jz = np.asarray(measurement_information, dtype=float)
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
    cov = _inv(np.asarray(information, dtype=float))
    idx = np.asarray(position_index)
    return np.sqrt(cov[..., idx, idx].sum(axis=-1))


def linear_measurement_information(H, R):
    """``H^T R^{-1} H`` for a linear-Gaussian measurement (Dogan Eq. (4.16))."""
    H = np.asarray(H, dtype=float)
    return _mT(H) @ _inv(np.asarray(R, dtype=float)) @ H


def rss_state_information(states, anchors_m, path_loss_exp, sigma_db, position_index, *,
                          min_distance_m: float = 0.0, height_offset_m: float = 0.0):
    """Fisher information of RSS from every anchor about the full state, ``(..., n, n)`` for states ``(..., n)``.

    ``Lambda(x) = H(x)^T R^{-1} H(x)`` (Dogan Eq. (4.19)), ``R = sigma^2 I``: the static RSS information
    (:func:`locbook.bounds.rss_position_information`, with its near-anchor regularisations) in the position block.
    """
    states = np.asarray(states, dtype=float)
    idx = np.asarray(position_index)
    block = rss_position_information(states[..., idx], anchors_m, path_loss_exp, sigma_db,
                                     min_distance_m=min_distance_m, height_offset_m=height_offset_m)
    out = np.zeros(states.shape + (states.shape[-1],))
    out[..., idx[:, None], idx[None, :]] = block
    return out
