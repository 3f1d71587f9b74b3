"""The one RSS measurement model against independent facts: its Jacobian against central finite differences, its
log-likelihood against sums of scipy.stats.norm.logpdf, its Fisher information against the closed form and against
bounds.crlb.rss_fisher_information of the same model; run blocks that change no bit; the one resampling module."""
import numpy as np
import pytest
from scipy.stats import norm

import locbook as lb
from locbook.models import rss as rss_module

ANCHORS = np.array([[0.0, 0.0], [8.0, 0.5], [1.0, 7.0], [7.5, 6.0]])
ANCHORS_3D = np.array([[0.0, 0.0, 2.5], [8.0, 0.5, 2.1], [1.0, 7.0, 2.8], [7.5, 6.0, 1.9]])
TAG_HEIGHT_M = 1.1


def _models():
    """Shared parameters, per-anchor parameters with heights, per-run-and-step parameters."""
    rng = np.random.default_rng(0)
    yield "shared", lb.RssModel(ANCHORS, lb.PathLossModel(-45.0, 2.3, 4.0, min_distance_m=0.1))
    yield "per_anchor_heights", lb.RssModel(ANCHORS_3D, lb.PathLossModel(np.array([-44.0, -47.0, -50.0, -46.0]),
                                                                         np.array([2.0, 2.4, 2.8, 1.9]),
                                                                         np.array([3.0, 4.5, 6.0, 5.0])),
                                            tag_height_m=TAG_HEIGHT_M)
    yield "per_run_step", lb.RssModel(ANCHORS, lb.PathLossModel(rng.uniform(-50, -40, (2, 3, 4)),
                                                                rng.uniform(1.8, 3.0, (2, 3, 4)),
                                                                rng.uniform(2.0, 6.0, (2, 3, 1))),
                                      per_step_channel=True)


def _positions(runs=2, count=9, seed=1):
    return np.random.default_rng(seed).uniform([0.5, 0.5], [7.5, 6.5], (runs, count, 2))


@pytest.mark.parametrize("name, model", list(_models()))
def test_jacobian_equals_central_differences(name, model):
    pos = _positions()
    step = 2 if name == "per_run_step" else 0
    jac = model.jacobian(pos, step)
    assert jac.shape == (2, 9, 4, 2)
    h = 1e-6
    for axis in range(2):
        e = np.zeros(2)
        e[axis] = h
        fd = (model.mean_rss_dbm(pos + e, step) - model.mean_rss_dbm(pos - e, step)) / (2 * h)
        np.testing.assert_allclose(jac[..., axis], fd, rtol=1e-6, atol=1e-8)


def test_jacobian_inside_the_clamp_is_the_derivative_of_the_clamped_mean():
    """Within d_min the clamped mean P_0 - 10 n log10(d_min / d0) is flat: its derivative (central differences,
    the oracle) is 0 for that anchor and the usual one for the others, and the reading adds no Fisher information
    (the same as the model without that anchor). Replaces the earlier capped-extension convention."""
    model = lb.RssModel(ANCHORS, lb.PathLossModel(-45.0, 2.3, 4.0, min_distance_m=0.5))
    p = np.array([[0.1, 0.2]])                                  # 0.22 m from anchor 0
    jac = model.jacobian(p)[0, 0]
    assert np.all(jac[0] == 0.0) and np.all(jac[1:] != 0.0)
    h = 1e-6
    for axis in range(2):
        e = np.zeros(2)
        e[axis] = h
        fd = (model.mean_rss_dbm(p + e) - model.mean_rss_dbm(p - e))[0, 0] / (2 * h)
        np.testing.assert_allclose(jac[:, axis], fd, rtol=1e-6, atol=1e-12)
    without = lb.RssModel(ANCHORS[1:], lb.PathLossModel(-45.0, 2.3, 4.0, min_distance_m=0.5))
    np.testing.assert_allclose(model.fisher_information(p), without.fisher_information(p), rtol=1e-15)
    on_anchor = model.jacobian(ANCHORS[:1])[0, 0]               # finite at the anchor itself
    assert np.all(on_anchor[0] == 0.0) and np.all(np.isfinite(on_anchor))


@pytest.mark.parametrize("name, model", list(_models()))
def test_log_likelihood_is_the_sum_of_normal_log_densities_over_heard_readings(name, model):
    rng = np.random.default_rng(2)
    pos = _positions()
    step = 1 if name == "per_run_step" else 0
    rss = rng.normal(-65.0, 6.0, (2, 4))
    rss[1, 2] = np.nan                                                    # anchor 2 not heard in run 1
    ll = model.log_likelihood(rss, pos, step)
    mean = model.mean_rss_dbm(pos, step)
    sigma = np.broadcast_to(np.asarray(model.channel.sigma_db, float)[:, step]
                            if np.ndim(model.channel.sigma_db) == 3 else model.channel.sigma_db, (2, 4))
    for r in range(2):
        heard = ~np.isnan(rss[r])
        want = norm.logpdf(rss[r, heard], mean[r][:, heard], sigma[r, heard]).sum(axis=-1)
        np.testing.assert_allclose(ll[r], want, rtol=1e-12)
        kernel = model.log_likelihood(rss, pos, step, constant=False)[r]
        np.testing.assert_allclose(ll[r] - kernel, (ll[r] - kernel)[0], rtol=1e-13)   # a constant per run only
    np.testing.assert_array_equal(model.log_likelihood(np.full((2, 4), np.nan), pos, step), 0.0)   # nothing heard


def test_fisher_information_equals_the_closed_form_and_bounds_crlb():
    pos = _positions(1, 12)[0]
    n, sigma = np.array([2.0, 2.4, 2.8, 1.9]), np.array([3.0, 4.5, 6.0, 5.0])
    model = lb.RssModel(ANCHORS, lb.PathLossModel(-45.0, n, sigma))
    info = model.fisher_information(pos)[0]
    diff = pos[:, None, :] - ANCHORS
    d2 = np.sum(diff**2, axis=-1)
    beta2 = (10 * n / (sigma * np.log(10))) ** 2                        # Patwari et al. (2003), Eq. (5)
    closed = np.einsum("pj,pji,pjk->pik", beta2 / d2**2, diff, diff)
    np.testing.assert_allclose(info, closed, rtol=1e-12)
    np.testing.assert_allclose(info, lb.rss_fisher_information(pos, model), rtol=1e-12)
    heard = np.array([True, False, True, True])
    np.testing.assert_allclose(model.fisher_information(pos, heard=heard)[0],
                               lb.rss_position_information(pos, model, heard=heard), rtol=1e-12)
    # with heights: the 3-D distance, as the bound's anchors at their heights above the tag
    high = lb.RssModel(ANCHORS_3D, lb.PathLossModel(-45.0, n, sigma), tag_height_m=TAG_HEIGHT_M)
    offsets = lb.RssModel(np.column_stack([ANCHORS, ANCHORS_3D[:, 2] - TAG_HEIGHT_M]), lb.PathLossModel(0.0, n, sigma),
                          tag_height_m=0.0)
    np.testing.assert_allclose(high.fisher_information(pos)[0], lb.rss_position_information(pos, offsets), rtol=1e-12)
    # the information is the expected outer product of the score (Monte Carlo over readings)
    rng = np.random.default_rng(4)
    p = pos[:1]
    z = model.mean_rss_dbm(p)[0, 0] + sigma * rng.standard_normal((200_000, 4))
    score = np.einsum("sj,jd->sd", (z - model.mean_rss_dbm(p)[0, 0]) / sigma**2, model.jacobian(p)[0, 0])
    np.testing.assert_allclose(score.T @ score / len(z), info[0], rtol=0.02, atol=0.02 * np.abs(info[0]).max())


def test_per_run_anchors_equal_one_model_per_run():
    rng = np.random.default_rng(5)
    anchors = rng.uniform(0, 50, (3, 4, 3))
    ch = lb.PathLossModel(-20.0, 3.0, 6.0, min_distance_m=1.0)
    pos = rng.uniform(0, 50, (3, 6, 3))
    rss = rng.uniform(-90, -50, (3, 4))
    joint = lb.RssModel(anchors, ch)
    assert joint.runs == 3 and joint.dim == 3
    ll = joint.log_likelihood(rss, pos)
    for r in range(3):
        alone = lb.RssModel(anchors[r], ch)
        np.testing.assert_array_equal(ll[r], alone.log_likelihood(rss[r:r + 1], pos[r])[0])
        np.testing.assert_array_equal(joint.jacobian(pos)[r], alone.jacobian(pos[r])[0])
    with pytest.raises(ValueError, match="runs"):
        joint.log_likelihood(rss[:2], pos[:2])


def test_run_blocks_change_no_bit(monkeypatch):
    """The likelihood is evaluated in blocks of runs to bound memory; each run's arithmetic is the same."""
    for name, model in _models():
        rng = np.random.default_rng(6)
        pos, rss = _positions(2, 50), rng.normal(-65.0, 6.0, (2, 4))
        rss[0, 1] = np.nan
        step = 1 if name == "per_run_step" else 0
        whole = model.log_likelihood(rss, pos, step)
        monkeypatch.setattr(rss_module, "LIKELIHOOD_BLOCK_VALUES", 1)          # one run per block
        np.testing.assert_array_equal(model.log_likelihood(rss, pos, step), whole)
        np.testing.assert_array_equal(model.log_likelihood(rss, pos[0], step),
                                      model.log_likelihood(rss, pos[[0, 0]], step))
        monkeypatch.undo()


def test_walls_attenuate_the_mean_and_select_runs_keeps_them():
    walls = np.array([[[4.0, -1.0], [4.0, 9.0]]])
    ch = lb.PathLossModel(np.zeros((3, 2, 4)) - 45.0, 2.0, 4.0, wall_attenuation_db=3.0, min_distance_m=0.1)
    model = lb.RssModel(ANCHORS, ch, walls_m=walls)
    p = np.array([[2.0, 3.0]])
    no_walls = lb.RssModel(ANCHORS, lb.PathLossModel(-45.0, 2.0, 4.0, min_distance_m=0.1))
    crossing = (ANCHORS[:, 0] > 4.0).astype(float)
    np.testing.assert_allclose(model.mean_rss_dbm(p)[:, 0],
                               np.tile(no_walls.mean_rss_dbm(p)[0, 0] - 3.0 * crossing, (3, 1)), rtol=1e-13)
    part = model.select_runs(slice(1, 3))
    assert part.runs == 2 and part.walls_m is not None
    np.testing.assert_array_equal(part.mean_rss_dbm(p), model.mean_rss_dbm(p)[1:3])


def test_model_inputs_are_checked_and_named():
    with pytest.raises(ValueError, match="channel must be a PathLossModel"):
        lb.RssModel(ANCHORS, -45.0)
    with pytest.raises(ValueError, match=r"channel.ref_power_dbm must be a scalar or end in \(1,\) or \(4,\)"):
        lb.RssModel(ANCHORS, lb.PathLossModel(np.zeros(3), 2.0, 4.0))
    with pytest.raises(ValueError, match="disagree on the number of runs"):
        lb.RssModel(np.zeros((2, 4, 2)) + ANCHORS, lb.PathLossModel(np.zeros((3, 1, 4)), 2.0, 4.0))
    with pytest.raises(ValueError, match="walls_m needs 2-D"):
        lb.RssModel(np.zeros((4, 3)), lb.PathLossModel(-45.0, 2.0, 4.0), walls_m=[[[0, 0], [1, 1]]])
    with pytest.raises(ValueError, match="Fisher information needs sigma_db > 0"):
        lb.RssModel(ANCHORS, lb.PathLossModel(-45.0, 2.0, 0.0)).fisher_information(np.ones((1, 2)))


# -- the one resampling module and the one particle filter --------------------------------------------
def test_resampling_module_imports_no_filter():
    import ast
    import inspect

    from locbook.tracking import resampling
    tree = ast.parse(inspect.getsource(resampling))
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    assert not {m for m in imported if m and ("bayes" in m or "particle" in m or "kalman" in m)}


def test_effective_sample_size_is_n_for_equal_weights_and_one_for_a_point_mass():
    np.testing.assert_allclose(lb.effective_sample_size(np.full((2, 8), 1 / 8)), 8.0)
    np.testing.assert_allclose(lb.effective_sample_size(np.eye(5)[:1]), 1.0)


def test_scheduled_resampling_and_a_callable_transition():
    rng = np.random.default_rng(7)
    start = rng.normal(0, 1, (2, 100, 1))
    calls = []

    def walk(x, t, rng):                 # any motion model: here a drift of +1 per step and no noise
        calls.append(t)
        return x + 1.0

    res = lb.particle_filter(None, lambda x, k: -0.5 * x[..., 0] ** 2, rng=np.random.default_rng(1), n_steps=6,
                             initial_particles_m=start, transition=walk, resample_every=3)
    assert calls == [1, 2, 3, 4, 5]
    np.testing.assert_array_equal(res.resampled, np.tile([False, False, True, False, False, True], (2, 1)))
    with pytest.raises(ValueError, match="not both"):
        lb.particle_filter(None, lambda x, k: x[..., 0], rng=rng, n_steps=2, initial_particles_m=start,
                           resample_every=2, resample_threshold=0.5)
    with pytest.raises(ValueError, match="transition must return"):
        lb.particle_filter(None, lambda x, k: x[..., 0], rng=rng, n_steps=2, initial_particles_m=start,
                           transition=lambda x, t, rng: x[:, :5])


def test_a_model_of_positions_keeps_its_one_run_axis_forms_and_a_model_of_states_reads_states():
    channel = lb.PathLossModel(np.array([-44.0, -47.0, -50.0, -46.0]), 2.3, np.array([3.0, 4.5, 6.0, 5.0]))
    of_positions = lb.RssModel(ANCHORS, channel)
    p = _positions(runs=1, count=5)[0]                                   # (5, 2)
    assert of_positions.mean(p).shape == (1, 5, 4) and of_positions.jacobian(p, 0).shape == (1, 5, 4, 2)
    np.testing.assert_array_equal(of_positions.jacobian(p), of_positions.position_jacobian(p))
    np.testing.assert_array_equal(np.broadcast_to(of_positions.covariance(p), (1, 5, 4, 4))[0, 3],
                                  np.diag(np.square(channel.sigma_db)))
    # the same model of states [x, y, vx, vy]: the position block of its Jacobian is the one above, the rest 0
    of_states = lb.RssModel(ANCHORS, channel, position_index=[0, 1])
    x = np.concatenate([p, np.ones((5, 2))], axis=-1)
    H = of_states.jacobian(x)
    np.testing.assert_array_equal(H[..., :2], of_positions.jacobian(p)[0])
    assert not H[..., 2:].any()
    np.testing.assert_array_equal(of_states.mean(x), of_positions.mean(p)[0])
    with pytest.raises(ValueError, match=r"step must be an integer in \[0, 3\)"):
        lb.RssModel(lb.per_step(np.broadcast_to(ANCHORS, (3, 4, 2))), channel, position_index=[0, 1]).mean(x, step=3)


def test_the_old_unmarked_per_run_and_step_form_warns_and_reads_as_before():
    rng = np.random.default_rng(6)
    ref, exp, sigma = rng.uniform(-50, -40, (2, 4, 4)), rng.uniform(1.8, 3.0, (2, 4, 4)), rng.uniform(2, 6, (2, 4))
    with pytest.warns(DeprecationWarning, match="per_step_channel=True with sigma") as caught:
        old = lb.RssModel(ANCHORS, lb.PathLossModel(ref, exp, sigma))       # T = m = 4: a sigma per run and step
    assert caught[0].filename == __file__
    new = lb.RssModel(ANCHORS, lb.PathLossModel(ref, exp, sigma[..., None]), per_step_channel=True)
    pos = _positions()
    z = rng.normal(-65.0, 6.0, (2, 4))
    for step in range(4):
        np.testing.assert_array_equal(old.log_likelihood(z, pos, step), new.log_likelihood(z, pos, step))
        np.testing.assert_array_equal(old.sigma_at(step), sigma[:, step, None])
