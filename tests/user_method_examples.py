"""Methods of one's own for the tests of user methods (tests/scenarios/test_user_methods.py): registered by file
(``tests/user_method_examples.py:weighted_centroid``) or by module (``user_method_examples:weighted_centroid``, the
tests folder being on pytest's path). Each takes one ``locbook.MethodInput``."""
import numpy as np


def weighted_centroid(inp):
    """The anchors' centroid weighted by each reading's power in milliwatts (a static method; no fix where no anchor
    was heard)."""
    w = np.where(np.isnan(inp.rss_dbm), 0.0, 10.0 ** (inp.rss_dbm / 10.0))          # (E, m) mW, 0 where not heard
    total = w.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (w @ inp.anchors_m[:, :2]) / np.where(total > 0, total, np.nan)


def centroid_with_covariance(inp):
    """The weighted centroid with a covariance per fix (the tuple form)."""
    p = weighted_centroid(inp)
    return p, np.broadcast_to(np.eye(2), (len(p), 2, 2))


def smoothed_centroid(inp):
    """A tracker: the weighted centroid, exponentially smoothed in time order (a tick not heard keeps the last
    estimate)."""
    fixes = weighted_centroid(inp)
    out, last = np.full_like(fixes, np.nan), None
    for k, f in enumerate(fixes):
        if np.isfinite(f).all():
            last = f if last is None else 0.7 * last + 0.3 * f
        out[k] = last if last is not None else np.nan
    return out


def boom(inp):
    """A static method that raises."""
    return _divide(len(inp.rss_dbm))


def _divide(n):
    return n / 0


def wrong_shape(inp):
    return np.zeros((inp.n_epochs, 3))


def infinite(inp):
    out = np.zeros((inp.n_epochs, 2))
    out[1, 0] = np.inf
    return out


def text(inp):
    return "here"


def not_psd(inp):
    return np.zeros((inp.n_epochs, 2)), np.broadcast_to(np.diag([1.0, -1.0]), (inp.n_epochs, 2, 2))


def mutates(inp):
    """Tries to write into what it is given (a read-only copy: it raises, and nothing else changes)."""
    inp.rss_dbm[:] = 0.0
    return weighted_centroid(inp)


NOT_A_FUNCTION = 3
