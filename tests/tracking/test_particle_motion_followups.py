"""Follow-ups in the particle filter and the motion model: a masked reading of a single
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
    got = lb.particle_filter(masked, MODEL, rng=np.random.default_rng(7), **kw)
    ref = lb.particle_filter(np.where(where, np.nan, power), MODEL, rng=np.random.default_rng(7), **kw)
    np.testing.assert_array_equal(got.mean, ref.mean)


def test_a_motion_whose_f_or_jacobian_is_complex_is_refused_by_its_own_methods():
    motion = lb.NonlinearMotion(lambda x: x * (1 + 1j), lambda x: np.eye(2) * (1 + 0j), name="spin")
    with pytest.raises(ValueError, match="spin: f returned complex values"):
        motion.apply(np.zeros((3, 2)), 0)
    with pytest.raises(ValueError, match="spin: jacobian returned complex values"):
        motion.jacobian_at(np.zeros((3, 2)), 0)
    plain = lb.NonlinearMotion(lambda x: 2 * x, lambda x: 2 * np.eye(2))
    np.testing.assert_array_equal(plain.apply(np.ones((3, 2)), 0), 2 * np.ones((3, 2)))
    np.testing.assert_array_equal(plain.jacobian_at(np.ones((3, 2)), 0), 2 * np.eye(2))


def test_a_list_of_masked_rows_keeps_every_rows_mask():
    # np.asarray of a list of masked arrays drops their masks: the 1e3 under the mask was used (a fix 8 km off)
    anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    d = np.linalg.norm(anchors - [3.0, 4.0], axis=1)
    bad = d.copy()
    bad[1] = 1e3
    rows = [np.ma.array(bad, mask=[0, 1, 0, 0]), np.ma.array(d)]
    for given in (rows, [rows]):
        np.testing.assert_allclose(lb.lateration_ls(anchors, given).position_m.reshape(-1, 2), [[3.0, 4.0]] * 2)
    with pytest.raises(ValueError, match="distance_m must be a rectangular array"):
        lb.lateration_ls(anchors, [rows[0], d[:3]])


def test_a_bad_reading_after_a_blank_line_is_named_by_its_own_line(tmp_path):
    from locbook.reproduce.readings import READING_COLUMNS, ReadingsError, load_reading_file
    path = tmp_path / "r.csv"
    path.write_text(",".join(READING_COLUMNS) + "\n\n" + "slope,george-study,a,,1.0,[1.0],,,,assumed,s,,r\n")
    with pytest.raises(ReadingsError, match=r"r\.csv, line 3 \(slope\)"):
        load_reading_file(path)


def test_a_scalar_h_of_a_one_component_reading_equals_the_vector_h():
    # m = 1, one run: the EKF calls h on one state, and a scalar can only mean that one component (the refusal is for
    # m > 1, where it would broadcast). The UKF calls h on all sigma points at once: there h must keep their axis.
    filt = lb.extended_kalman_filter
    model = lb.constant_velocity(1.0, 0.05)
    z = np.linspace(0.0, 3.0, 10)[:, None]
    R = np.array([[0.5]])
    jac = lambda x: np.array([[1.0, 0.0, 0.0, 0.0]])
    x0, P0 = np.zeros(4), np.eye(4)
    scalar = filt(model.F, model.Q, x0, P0, lb.NonlinearMeasurement(z, lambda x: x[0], R, jacobian=jac))
    vector = filt(model.F, model.Q, x0, P0, lb.NonlinearMeasurement(z, lambda x: x[:1], R, jacobian=jac))
    np.testing.assert_array_equal(scalar.mean, vector.mean)
