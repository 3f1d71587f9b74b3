"""Issue 44 follow-ups in the particle filter and the motion model (items 6 and 12): a masked reading of a single
run is not heard, and a complex motion output is refused by the model's own methods too."""
import numpy as np
import pytest

import locbook as lb

READERS = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
MODEL = lb.RssModel(READERS, lb.PathLossModel(-40.0, 2.0, 3.0, min_distance_m=0.1))


def test_a_single_runs_masked_reading_is_not_heard_in_the_particle_filter():
    truth = np.stack([np.linspace(1, 9, 8), np.linspace(2, 8, 8)], -1)
    power = MODEL.mean_rss_dbm(truth[None])[0] + np.random.default_rng(3).normal(0, 3, (8, 4))
    where = np.zeros(power.shape, bool)
    where[::2, 1] = True
    masked = np.ma.array(np.where(where, 1e3, power), mask=where)      # 1e3 dBm under the mask: never read
    kw = dict(n_particles=200, region_m=([0.0, 0.0], [10.0, 10.0]))
    got = lb.particle_filter(masked, MODEL, np.random.default_rng(7), **kw)
    ref = lb.particle_filter(np.where(where, np.nan, power), MODEL, np.random.default_rng(7), **kw)
    np.testing.assert_array_equal(got.mean_m, ref.mean_m)


def test_a_motion_whose_f_or_jacobian_is_complex_is_refused_by_its_own_methods():
    motion = lb.NonlinearMotion(lambda x: x * (1 + 1j), lambda x: np.eye(2) * (1 + 0j), name="spin")
    with pytest.raises(ValueError, match="spin: f returned complex values"):
        motion.apply(np.zeros((3, 2)), 0)
    with pytest.raises(ValueError, match="spin: jacobian returned complex values"):
        motion.jacobian_at(np.zeros((3, 2)), 0)
    plain = lb.NonlinearMotion(lambda x: 2 * x, lambda x: 2 * np.eye(2))
    np.testing.assert_array_equal(plain.apply(np.ones((3, 2)), 0), 2 * np.ones((3, 2)))
    np.testing.assert_array_equal(plain.jacobian_at(np.ones((3, 2)), 0), 2 * np.eye(2))
