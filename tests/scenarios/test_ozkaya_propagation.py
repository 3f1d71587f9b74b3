"""Document 004 (Ozkaya 2011), Ch. 6 and Appendix A: the synthetic offline calibration campaign against the moments
it is drawn with, and the bookkeeping of the printed CRLB repeats."""
import numpy as np
import pytest

from locbook.scenarios import ozkaya as oz


def _campaign(rng, n=400, reader=1, location_sigma_db=3.0, **kw):
    distances = np.array([1.0, 2.0, 3.0, 3.0])
    walls = np.array([0.0, 0.0, 0.0, 1.0])
    design = dict(location_sigma_db=location_sigma_db, locations_per_distance=4, readings_per_location=100) | kw
    return distances, walls, oz.synthetic_campaign(reader, n, rng, distances, walls, **design)


def test_synthetic_campaign_has_the_printed_mean_and_total_sigma_split_into_location_and_reading_parts():
    P, j, loc = oz.OFFLINE_PARAMETERS, 1, 3.0
    distances, walls, data = _campaign(np.random.default_rng(7))
    assert data.shape == (400, 4, 4, 100)
    assert np.all(data == np.round(data)) and data.min() >= oz.READER_SENSITIVITY_DBM      # 1 dB steps, -90 floor
    sigma2, read2 = P["sigma_db"][j] ** 2, P["sigma_db"][j] ** 2 - loc**2
    q = 1.0 / 12.0                                      # Sheppard: rounding to 1 dB adds step^2/12 to the variance
    eq64 = P["alpha_dbm"][j] - 10 * P["path_loss_exp"][j] * np.log10(distances) - P["waf_db"] * walls
    grand = data.mean(axis=(0, 2, 3))                   # per distance; se^2 = loc^2/(n L) + read^2/(n L R)
    se = np.sqrt(loc**2 / 1600 + read2 / 160000)
    assert np.all(np.abs(grand - eq64) < 4 * se)
    assert grand[2] - grand[3] == pytest.approx(P["waf_db"], abs=6 * se)                # one wall at 3 m
    rel = 4 * np.sqrt(2 / 1600)    # 4 sd of a variance estimated from 1600 independent location offsets
    total = data.reshape(400, 4, -1).transpose(1, 0, 2).reshape(4, -1).var(axis=1)
    np.testing.assert_allclose(total, sigma2 + q, rtol=rel)                            # Table 6.1's sigma in total
    within = data.var(axis=-1, ddof=1).mean(axis=(0, 2))                                # the reading part
    np.testing.assert_allclose(within, read2 + q, rtol=0.02)        # 160000 readings: sd 0.4 %
    between = data.mean(axis=-1).var(axis=(0, 2), ddof=1)                               # location means
    np.testing.assert_allclose(between, loc**2 + (read2 + q) / 100, rtol=rel)


def test_synthetic_campaign_is_reproducible_clips_at_the_floor_and_refuses_a_location_spread_above_sigma():
    a = _campaign(np.random.default_rng(3), n=5)[2]
    np.testing.assert_array_equal(a, _campaign(np.random.default_rng(3), n=5)[2])
    weak = dict(oz.OFFLINE_PARAMETERS, alpha_dbm=(-95.0,) * 3)                          # every mean below -90 dBm
    floor = _campaign(np.random.default_rng(3), n=5, parameters=weak)[2]
    assert floor.min() == oz.READER_SENSITIVITY_DBM and np.mean(floor == oz.READER_SENSITIVITY_DBM) > 0.5
    with pytest.raises(ValueError, match="location_sigma_db"):
        _campaign(np.random.default_rng(3), n=5, location_sigma_db=oz.OFFLINE_PARAMETERS["sigma_db"][1] + 0.1)


def test_crlb_rows_link_each_repeat_of_a_printed_bound_once_and_note_the_rest():
    rows = oz.crlb_rows()
    groups = {}
    for r in rows:
        groups.setdefault((r["layout"], r["sigma_db"]), []).append(r)
    linked = 0
    for (layout, _), group in groups.items():
        first = group[0]["printed"]
        assert all(r["first_printed"] is first for r in group)      # one first printing per (layout, sigma)
        assert group[0]["same_as"] is None and "prints this bound again" not in group[0]["note"]
        for r in group[1:]:
            p = r["printed"]
            if p.value == first.value:                                   # the same bound printed again: linked
                assert r["same_as"] is first and "prints this bound again" not in r["note"]
                linked += 1
            else:                                                        # a different value: compared, and said so
                assert r["same_as"] is None and first.text in r["note"] and first.where in r["note"]
        for r in group:
            assert (oz.CRLB_NOT_FROM_FORMULA in r["note"]) == (layout in ("half3", "large3", "large4"))
    assert linked > 0 and len({r["printed"].id for r in rows}) == len(rows)
