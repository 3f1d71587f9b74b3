"""The report site's drawing helpers: round ticks, and the printed-versus-ours plots as files report.md embeds."""
import math
import xml.etree.ElementTree as ET

import pytest

from locbook.suite.site import nice_ticks, printed_versus_ours, write_pvo_files


@pytest.mark.parametrize("lo, hi", [(0.93, 1.07), (-3.2, 47.1), (1e-7, 5e-7), (0.0, 1.0), (123.4, 123.9),
                                    (-0.02, 0.03), (7.0, 7000.0)])
def test_ticks_are_round_inside_the_range_and_evenly_spaced(lo, hi):
    ticks = nice_ticks(lo, hi)
    assert 2 <= len(ticks) <= 5 and all(lo - 1e-12 <= v <= hi + 1e-12 for v in ticks)
    steps = {round(b - a, 12) for a, b in zip(ticks, ticks[1:])}
    assert len(steps) == 1
    step = steps.pop()
    mantissa = step / 10 ** math.floor(math.log10(step))
    assert any(math.isclose(mantissa, m) for m in (1, 2, 2.5, 5))
    assert all(math.isclose(v / step, round(v / step), abs_tol=1e-9) for v in ticks)   # multiples of the step


def test_a_small_tables_plot_labels_its_points_and_the_file_stands_alone(tmp_path):
    rows = [{"printed_id": "Table 1 | mean | x", "quantity": "mean error", "unit": "m", "printed": "2.0",
             "reproduced": "2.1", "window_low": "1.8", "window_high": "2.2", "verdict": "within",
             "kind": "reproduction"}]
    plot, = printed_versus_ours(rows)
    assert "mean error: within" in plot["svg"]                      # visible, not only the hover title
    (name, title), = write_pvo_files(rows, tmp_path)
    root = ET.parse(tmp_path / name).getroot()
    assert root.tag == "{http://www.w3.org/2000/svg}svg" and title == "Table 1 (m)"
    style = root.find("{http://www.w3.org/2000/svg}style").text
    assert ".pvo .v-within .ours" in style                          # coloured without the site's stylesheet
