"""The vectorisable elementary functions of the compiled kernels (locbook.tracking._vecmath) against numpy's on their
domains: the natural log of positive normal finite values within 2 ulp (musl's algorithm is within 1 ulp of the
correct value, numpy's too), exact at 1; the exp of non-positive values within 2 ulp, 0 below the underflow."""
import numpy as np
import pytest

numba = pytest.importorskip("numba")
from locbook.tracking import _vecmath as V  # noqa: E402

pytestmark = pytest.mark.compiled

# compiled here without the disk cache: a cached caller keeps the callee's code it was compiled with (numba checks
# only the caller's own file), and these tests must see the current one


@numba.njit
def _logs(x, out):
    for i in range(x.size):
        out[i] = V._log_positive(x[i])


@numba.njit
def _exps(x, out):
    for i in range(x.size):
        out[i] = V._exp_nonpositive(x[i])


def _ulps(a, b):
    return np.abs(a - b) / np.spacing(np.abs(b))


def test_log_is_within_two_ulp_of_numpy_across_the_normal_range():
    rng = np.random.default_rng(11)
    tiny, huge = np.finfo(float).tiny, np.finfo(float).max
    x = np.concatenate([np.exp(rng.uniform(-708, 709, 400_000)), 1.0 + rng.uniform(-1e-6, 1e-6, 50_000),
                        rng.uniform(0.5, 2.0, 50_000), 2.0 ** np.arange(-1022, 1024),
                        [tiny, huge, np.sqrt(2.0), np.sqrt(0.5), np.nextafter(1.0, 0.0), np.nextafter(1.0, 2.0)]])
    out = np.empty_like(x)
    _logs(x, out)
    ref = np.log(x)
    assert np.max(_ulps(out[ref != 0], ref[ref != 0])) <= 2.0
    one = np.array([1.0])
    _logs(one, one)
    assert one[0] == 0.0


def test_exp_of_nonpositive_values_is_within_two_ulp_of_numpy_and_underflows_to_zero():
    rng = np.random.default_rng(12)
    x = np.concatenate([-np.exp(rng.uniform(-40, np.log(745.0), 400_000)), [0.0, -0.0, -1e-300, -745.0, -746.5,
                                                                            -1e5, -np.inf]])
    out = np.empty_like(x)
    _exps(x, out)
    ref = np.exp(x)
    normal = ref >= np.finfo(float).tiny
    assert np.max(_ulps(out[normal], ref[normal])) <= 2.0
    assert np.all(np.abs(out[~normal] - ref[~normal]) <= np.spacing(0.0))         # subnormal results: 1 ulp of 0
    np.testing.assert_array_equal(out[x < -746.0], 0.0)
