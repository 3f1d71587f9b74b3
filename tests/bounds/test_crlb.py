"""CRLB against a closed form, numerical Fisher information and the printed thesis values (the metrics:
tests/bounds/test_metrics.py; the random streams and standard errors: tests/bounds/test_montecarlo.py)."""
import numpy as np
import pytest

import locbook as lb

SQUARE = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 4.0], [4.0, 4.0]])


def rss(anchors_m, n, sigma_db, tag_height_m=None, **channel):
    """The bounds' RSS model: the anchors, exponent n, sigma (and the channel's clamp, walls...)."""
    return lb.RssModel(np.asarray(anchors_m, float), lb.PathLossModel(0.0, n, sigma_db, **channel),
                       tag_height_m=tag_height_m)


def test_crlb_closed_form_at_square_centre():
    # centre of a square: J = 2c/d^2 I with c = (10 n / (sigma ln10))^2, so the bound is d / sqrt(c)
    n, sigma = 2.3, 4.0
    c = (10 * n / (sigma * np.log(10))) ** 2
    d = np.sqrt(8.0)
    assert lb.rss_crlb_m([2.0, 2.0], rss(SQUARE, n, sigma)) == pytest.approx(d / np.sqrt(c), rel=1e-12)


def test_fisher_information_equals_numerical_jacobian():
    model = lb.PathLossModel(-45.0, 2.1843, 3.0)
    p = np.array([0.7, 2.9])
    eps = 1e-6
    jac = np.stack([(model.mean_rss_dbm(lb.pairwise_distance_m(p + eps * e, SQUARE))
                     - model.mean_rss_dbm(lb.pairwise_distance_m(p - eps * e, SQUARE))) / (2 * eps)
                    for e in np.eye(2)], axis=1)
    np.testing.assert_allclose(lb.rss_fisher_information(p, rss(SQUARE, 2.1843, 3.0)), jac.T @ jac / 9.0, rtol=1e-6)


def test_ml_attains_bound_at_high_snr():
    model = lb.PathLossModel(-45.0, 2.5, 0.5)
    p = np.array([1.3, 2.6])
    power = model.sample_rss_dbm(np.broadcast_to(lb.pairwise_distance_m(p, SQUARE), (20000, 4)),
                                   rng=np.random.default_rng(11))
    err2 = np.sum((lb.rss_ml_position(power, lb.RssModel(SQUARE, model)).position_m - p) ** 2, axis=-1)
    bound = lb.rss_crlb_m(p, rss(SQUARE, 2.5, 0.5))
    se = err2.std() / np.sqrt(err2.size)
    assert abs(err2.mean() - bound**2) < 4 * se + 0.02 * bound**2


@pytest.mark.parametrize("anchors, printed",
                         [([[0, 0], [5, 0], [0, 8]], 0.80), ([[0, 0], [5, 0], [0, 8], [5, 8]], 0.64)])
def test_ozkaya_printed_form_reproduces_thesis_crlb(anchors, printed):
    # Ozkaya (2011), Fig. 7.1 / Appendix A: 5 m x 8 m room, sigma 5.2 dB, printed 1/d^2 form with n = 2
    xs, ys = np.meshgrid(np.linspace(0.025, 4.975, 100), np.linspace(0.025, 7.975, 160))
    pts = np.stack([xs.ravel(), ys.ravel()], -1)
    bound = lb.crlb_rms_over_area_m(pts, rss(anchors, 2.0, 5.2), variant="literal_ozkaya2011")
    assert bound == pytest.approx(printed, abs=0.02)


def test_crlb_at_anchor_raises():
    with pytest.raises(lb.DegenerateGeometryError):
        lb.rss_crlb_m([0.0, 0.0], rss(SQUARE, 2.0, 4.0))


def test_rss_crlb_with_a_known_tag_height_is_the_xy_block_of_the_3d_information():
    """3-D anchors: the known-height 2-D bound inverts the (x, y) block of the 3-D Fisher information at the tag's
    height (independent route: the 3-D information, sliced and inverted by numpy); the 3-D bound (height unknown)
    is never below it (Schur complement), and the choice is explicit (2-D anchors take no tag height)."""
    anchors = np.array([[0.0, 0.0, 2.8], [8.0, 0.0, 2.5], [8.0, 6.0, 2.9], [0.0, 6.0, 2.6], [4.0, 3.0, 3.0]])
    xy = np.array([[2.0, 1.5], [5.5, 4.0], [4.0, 1.0]])
    h = 1.3
    known = lb.rss_crlb_m(xy, rss(anchors, 2.2, 4.0, h))
    xyz = np.column_stack([xy, np.full(len(xy), h)])
    info3 = lb.rss_fisher_information(xyz, rss(anchors, 2.2, 4.0))
    expected = np.sqrt(np.trace(np.linalg.inv(info3[:, :2, :2]), axis1=-2, axis2=-1))
    np.testing.assert_allclose(known, expected, rtol=1e-12)
    full3d = lb.rss_crlb_m(xyz, rss(anchors, 2.2, 4.0))
    assert np.all(full3d >= known)
    assert lb.crlb_rms_over_area_m(xy, rss(anchors, 2.2, 4.0, h)) == pytest.approx(
        float(np.sqrt(np.mean(known**2))), rel=1e-12)
    with pytest.raises(ValueError, match=r"anchors_m must end in \(m, 3\).*with tag_height_m"):
        lb.rss_crlb_m(xy, rss(anchors[:, :2], 2.2, 4.0, h))


def test_the_bound_of_the_anchors_heard_is_the_bound_of_that_subset():
    """rss_crlb_m(heard=): each position's bound from the anchors it heard only (the closed form on that subset);
    a position that heard one anchor has no finite bound."""
    anchors = np.array([[0.0, 0.0, 2.5], [8.0, 0.0, 2.4], [0.0, 6.0, 2.6], [8.0, 6.0, 2.5], [4.0, 3.0, 3.0]])
    n, sigma = np.array([2.0, 2.2, 2.5, 1.8, 2.1]), np.array([4.0, 5.0, 6.0, 4.5, 5.5])
    pos = np.array([[1.0, 1.0], [5.0, 2.0], [3.0, 4.0]])
    heard = np.array([[True] * 5, [True, False, True, True, False], [False, False, True, False, False]])
    got = lb.rss_crlb_m(pos, rss(anchors, n, sigma, 1.2), heard=heard)
    np.testing.assert_allclose(got[0], lb.rss_crlb_m(pos[0], rss(anchors, n, sigma, 1.2)), rtol=1e-12)
    keep = heard[1]
    np.testing.assert_allclose(got[1], lb.rss_crlb_m(pos[1], rss(anchors[keep], n[keep], sigma[keep], 1.2)),
                               rtol=1e-12)
    assert got[2] == np.inf


# -- the bounds' one RssModel: what a bound cannot honour is refused by name ----------------------------
@pytest.mark.parametrize("model, message", [
    (lb.PathLossModel(0.0, 2.0, 4.0), r"takes model = RssModel\(anchors_m, channel\).*got PathLossModel"),
    (SQUARE, r"takes model = RssModel\(anchors_m, channel\).*got ndarray"),
    (lb.RssModel(SQUARE, lb.PathLossModel(0.0, 2.0, 4.0, wall_attenuation_db=3.0), walls_m=[[1.0, -1.0], [1.0, 5.0]]),
     r"cannot honour the model's walls \(walls_m\).*replace\(model, walls_m=None\)"),
    (lb.RssModel(np.stack([SQUARE, SQUARE + 0.1]), lb.PathLossModel(0.0, 2.0, 4.0)),
     r"anchors_m \(2, 4, 2\) per run or step"),
    (lb.RssModel(SQUARE, lb.PathLossModel(0.0, np.full((1, 3, 4), 2.0), 4.0), per_step_channel=True),
     r"channel.path_loss_exp \(1, 3, 4\) per run or step"),
    (lb.RssModel(SQUARE, lb.PathLossModel(0.0, 2.0, np.full((2, 3, 1), 4.0)), per_step_channel=True),
     r"channel.sigma_db \(2, 3, 1\) per run or step"),
    (lb.RssModel(SQUARE, lb.PathLossModel(0.0, 2.0, np.full((2, 1), 4.0))),
     r"channel.sigma_db \(2, 1\) per run or step"),
])
def test_a_bound_refuses_what_it_cannot_honour_by_name(model, message):
    for call in (lambda: lb.rss_crlb_m([1.0, 2.0], model), lambda: lb.rss_position_information([1.0, 2.0], model),
                 lambda: lb.rss_state_information(np.zeros(4), model, [0, 1])):
        with pytest.raises((ValueError, TypeError), match=message):
            call()


def test_the_literal_form_uses_the_models_exponent_sigma_and_clamp():
    """Ozkaya's printed 1/d^2 information (Eqs. (A.10)-(A.12)) of the model's channel: per-anchor n and sigma, and
    within the clamp d_min^2 in the denominator."""
    n, sigma = np.array([2.0, 2.4, 2.8, 1.9]), np.array([3.0, 4.5, 6.0, 5.0])
    p = np.array([[0.3, 0.2], [2.5, 1.0]])
    info = lb.rss_position_information(p, rss(SQUARE, n, sigma, min_distance_m=0.5), variant="literal_ozkaya2011")
    diff = p[:, None, :] - SQUARE
    d2 = np.maximum(np.sum(diff**2, axis=-1), 0.25)
    beta2 = (10 * n / (sigma * np.log(10))) ** 2
    np.testing.assert_allclose(info, np.einsum("pj,pji,pjk->pik", beta2 / d2, diff, diff), rtol=1e-13)
    with pytest.raises(ValueError, match=r"variant must be one of \('corrected', 'literal_ozkaya2011'\)"):
        lb.rss_crlb_m(p, rss(SQUARE, n, sigma), variant="printed")


# -- the call forms before the readings-first convention: one test each, the warning at the caller's line and the
# same numbers ------------------------------------------------------------------------------------------------------
A3 = np.array([[0.0, 0.0, 2.8], [8.0, 0.5, 2.5], [7.5, 6.0, 2.9], [0.3, 6.2, 2.6], [4.0, 3.1, 3.0]])
N5, S5 = np.array([2.0, 2.2, 2.5, 1.8, 2.1]), np.array([4.0, 5.0, 6.0, 4.5, 5.5])
P_XY = np.array([[1.0, 1.5], [5.0, 2.0], [3.0, 4.0], [6.5, 5.5]])
HEARD = np.array([[True] * 5, [True, False, True, True, False], [False, True, True, True, True], [True] * 5])
LIFTED = rss(np.column_stack([A3[:, :2], A3[:, 2] - 1.2]), N5, S5, 0.0, min_distance_m=0.4)


@pytest.mark.parametrize("old, new", [
    (lambda: lb.rss_fisher_information(P_XY, A3[:, :2], N5, S5, "ozkaya_printed", min_distance_m=0.4,
                                       height_offset_m=A3[:, 2] - 1.2),
     lambda: lb.rss_fisher_information(P_XY, LIFTED, variant="literal_ozkaya2011")),
    (lambda: lb.rss_position_information(P_XY, A3[:, :2], N5, S5, min_distance_m=0.4, height_offset_m=A3[:, 2] - 1.2,
                                         heard=HEARD),
     lambda: lb.rss_position_information(P_XY, LIFTED, heard=HEARD)),
    (lambda: lb.rss_crlb_m(P_XY, A3, N5, S5, "correct", tag_height_m=1.2, heard=HEARD),
     lambda: lb.rss_crlb_m(P_XY, rss(A3, N5, S5, 1.2), heard=HEARD)),
    (lambda: lb.crlb_rms_over_area_m(P_XY, A3, N5, S5, form="ozkaya_printed", tag_height_m=1.2),
     lambda: lb.crlb_rms_over_area_m(P_XY, rss(A3, N5, S5, 1.2), variant="literal_ozkaya2011")),
    (lambda: lb.bounds.rss_crlb_checked_m(P_XY, A3, N5, S5, tag_height_m=1.2, heard=HEARD),
     lambda: lb.bounds.rss_crlb_checked_m(P_XY, rss(A3, N5, S5, 1.2), heard=HEARD)),
    (lambda: lb.rss_state_information(np.column_stack([P_XY, P_XY]), A3[:, :2], N5, S5, [0, 1], min_distance_m=0.4,
                                      height_offset_m=A3[:, 2] - 1.2, heard=HEARD),
     lambda: lb.rss_state_information(np.column_stack([P_XY, P_XY]), LIFTED, [0, 1], heard=HEARD)),
], ids=["rss_fisher_information", "rss_position_information", "rss_crlb_m", "crlb_rms_over_area_m",
        "rss_crlb_checked_m", "rss_state_information"])
def test_the_old_call_form_warns_at_the_caller_and_gives_the_same_numbers(old, new):
    with pytest.warns(DeprecationWarning, match=r"\(position_m, anchors_m|\(points_m, anchors_m|\(states, anchors_m") \
            as caught:
        got = old()
    assert len(caught) == 1 and caught[0].filename == __file__
    assert "is deprecated: use" in str(caught[0].message) and "RssModel(anchors_m, PathLossModel(" in \
        str(caught[0].message)
    want = new()
    for a, b in zip(got if isinstance(got, tuple) else (got,), want if isinstance(want, tuple) else (want,)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("old, new", [("correct", "corrected"), ("ozkaya_printed", "literal_ozkaya2011")])
def test_the_old_form_values_as_variant_warn_and_give_the_same_numbers(old, new):
    model = rss(A3, N5, S5, 1.2)
    with pytest.warns(DeprecationWarning, match=fr"rss_crlb_m\(variant='{old}'\) is deprecated: use "
                                                fr"rss_crlb_m\(variant='{new}'\)") as caught:
        got = lb.rss_crlb_m(P_XY, model, variant=old)
    assert len(caught) == 1 and caught[0].filename == __file__
    np.testing.assert_array_equal(got, lb.rss_crlb_m(P_XY, model, variant=new))
