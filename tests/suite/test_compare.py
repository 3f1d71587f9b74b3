"""`locbook compare`: two runs side by side, and the comparison a -p run writes with its base."""
import csv
import math

import pytest

from locbook.errors import ParameterError
from locbook.suite.cli import main
from locbook.suite.compare import compare_folders, compare_rows
from toy_suite import run


def _row(exp, pid, reproduced, se="", verdict="within", **extra):
    return {"experiment": exp, "printed_id": pid, "quantity": pid, "where": "", "unit": "m", "kind": "reproduction",
            "printed": "1.0", "reproduced": reproduced, "mc_std_error": se, "verdict": verdict, **extra}


def test_rows_are_joined_and_each_change_judged_by_the_root_of_the_squared_errors():
    base = [_row("e", "same", "2.5", "0.1"), _row("e", "noise", "2.0", "0.3"), _row("e", "moved", "2.0", "0.3"),
            _row("e", "exact", "1.25"), _row("e", "gone", "1.0"), _row("e", "text", "", verdict="")]
    variant = [_row("e", "noise", "2.9", "0.4"), _row("e", "moved", "3.1", "0.4", verdict="miss"),
               _row("e", "same", "2.5", "0.2"), _row("e", "exact", "1.2500001"), _row("e", "new", "7"),
               _row("e", "text", "", verdict="")]
    rows = {r["printed_id"]: r for r in compare_rows(base, variant)}
    # the variant's order, then what only the base holds
    assert [r["printed_id"] for r in compare_rows(base, variant)] == ["noise", "moved", "same", "exact", "new",
                                                                       "text", "gone"]
    assert rows["noise"]["difference_se"] == pytest.approx(0.5)          # sqrt(0.3^2 + 0.4^2)
    assert rows["noise"]["difference"] == pytest.approx(0.9) and rows["noise"]["change"] == "within 2 SE"
    assert rows["moved"]["difference"] == pytest.approx(1.1) and rows["moved"]["change"] == "changed"   # > 1.0
    assert (rows["moved"]["base_verdict"], rows["moved"]["variant_verdict"]) == ("within", "miss")
    assert rows["same"]["change"] == "identical" and rows["same"]["difference"] == 0
    # no Monte-Carlo error: any change of the value is a change
    assert rows["exact"]["change"] == "changed" and rows["exact"]["difference_se"] == 0
    assert rows["new"]["change"] == "only in variant" and rows["new"]["base"] == ""
    assert rows["gone"]["change"] == "only in base" and rows["gone"]["variant"] == ""
    assert rows["text"]["change"] == "no number"


def test_a_nan_or_text_value_is_never_a_number():
    rows = compare_rows([_row("e", "a", "nan", "0.1"), _row("e", "b", "yes")],
                        [_row("e", "a", "1.0", "0.1"), _row("e", "b", "yes")])
    assert [(r["change"], r["difference"]) for r in rows] == [("changed", None), ("identical", None)]


def test_a_folder_without_numbers_is_one_line(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(ParameterError, match=r"^compare: base .*empty holds no numbers.csv"):
        compare_folders(tmp_path / "empty", tmp_path)
    with pytest.raises(ParameterError, match=r"^compare: variant .*nowhere is not a folder"):
        (tmp_path / "numbers.csv").write_text("experiment,printed_id\n")
        compare_folders(tmp_path, tmp_path / "nowhere")


def compare(toy, *args):
    return main(["--suite", str(toy / "notebooks" / "experiments.toml"), "compare", "--reports", str(toy / "reports"),
                 *args])


def _csv(path):
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.notebooks
def test_a_p_run_writes_and_links_its_comparison_with_the_base_and_the_command_agrees(toy, capsys, tmp_path):
    assert run(toy) == 0
    base = {r["experiment"]: r for r in _csv(toy / "reports" / "quick" / "numbers.csv")}
    assert run(toy, "george-one", "-p", "n=7") == 0
    variant_dir, = [p for p in (toy / "reports").iterdir() if p.name.startswith("quick-n-7-")]
    variant = {r["experiment"]: r for r in _csv(variant_dir / "numbers.csv")}
    rows = _csv(variant_dir / "compare-quick.csv")
    one = next(r for r in rows if r["experiment"] == "george-one")
    assert one["base"] == base["george-one"]["reproduced"] and one["variant"] == variant["george-one"]["reproduced"]
    assert float(one["difference"]) == pytest.approx(float(one["variant"]) - float(one["base"]), abs=1e-12)
    assert one["change"] == ("identical" if one["base"] == one["variant"] else "changed")   # the toy has no MC error
    assert next(r for r in rows if r["experiment"] == "george-two")["change"] == "only in base"
    page = (variant_dir / "compare-quick.html").read_text()
    assert "<code>n</code>" in page and "<code>5</code>" in page and "<code>7</code>" in page   # quick n=5 -> 7
    assert 'href="compare-quick.html"' in (variant_dir / "index.html").read_text()
    assert "[quick](compare-quick.html)" in (variant_dir / "index.md").read_text()
    assert not list((toy / "reports" / "quick").glob("compare-*"))          # the base folder is never written

    capsys.readouterr()
    assert compare(toy, "quick", str(variant_dir), "--out", str(tmp_path / "out")) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "out" / "compare-quick.csv").read_bytes() == (variant_dir / "compare-quick.csv").read_bytes()
    assert out.startswith("2 printed numbers compared: ") and str(tmp_path / "out" / "compare-quick.html") in out
    assert compare(toy, "quick", str(tmp_path / "nowhere")) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is not a folder" in err and "Traceback" not in err
    assert math.isfinite(float(one["difference"]))


# -- a data run's results ----------------------------------------------------------------------------------------

RESULTS_HEADER = "kind,recording,method,settings,rmse_m,rmse_low_m,rmse_high_m,mean_m,mean_low_m,mean_high_m\n"


def _data_folder(path, lines):
    """A data run's folder: dataset.json, an empty numbers.csv (a data set prints nothing) and one results.csv."""
    (path / "measured-tracking").mkdir(parents=True)
    (path / "dataset.json").write_text('{"name": "toy"}')
    (path / "numbers.csv").write_text("experiment,printed_id,reproduced,mc_std_error,verdict\n")
    (path / "measured-tracking" / "results.csv").write_text(RESULTS_HEADER + "".join(lines))
    return path


def test_a_data_run_is_compared_on_each_methods_errors_with_the_bootstrap_intervals(tmp_path):
    from locbook.suite.compare import DATA_INTERVAL_Z, write_comparison
    from locbook.suite.site_data import data_index_markdown
    base = _data_folder(tmp_path / "data-toy", [
        "tracking,pooled,kf,q fitted,2.0,1.8,2.2,1.5,1.4,1.6\n",
        "tracking,walk_1,kf,q fitted,3.0,2.0,4.0,2.5,2.0,3.0\n"])
    variant = _data_folder(tmp_path / "data-toy-p", [
        "tracking,pooled,kf,q = 0.1,2.5,2.3,2.7,1.5,1.4,1.6\n",
        "tracking,walk_1,kf,q = 0.1,3.1,2.1,4.1,2.5,2.0,3.0\n"])
    comparison = compare_folders(base, variant)
    rows = {(r["where"].split(";")[0], r["quantity"]): r for r in comparison.rows}
    assert len(comparison.rows) == 4 and {r["kind"] for r in comparison.rows} == {"data"}
    pooled = rows[("pooled", "kf RMSE")]
    # SE of each: the 95 % interval's half-width over z: 0.2 / z on both sides, so sqrt(2) 0.2 / z = 0.144 m
    se = math.hypot(0.2 / DATA_INTERVAL_Z, 0.2 / DATA_INTERVAL_Z)
    assert pooled["difference"] == pytest.approx(0.5) and pooled["difference_se"] == pytest.approx(se)
    assert pooled["change"] == "changed"                                   # 0.5 m > 2 x 0.144 m
    walk = rows[("walk_1", "kf RMSE")]
    assert walk["difference"] == pytest.approx(0.1) and walk["change"] == "within 2 SE"   # 1 m half-widths
    assert rows[("pooled", "kf mean error")]["change"] == "identical"
    assert comparison.summary().startswith("4 numbers compared: 1 changed")
    write_comparison(comparison)
    html = (variant / "compare-data-toy.html").read_text()
    assert "bootstrap interval" in html and "Every number" in html
    # the data set's index links the comparison
    record = {"name": "toy"}
    assert "[data-toy](compare-data-toy.html)" in data_index_markdown(variant, [], record)
    # a folder that is not a data run has no such rows
    (base / "dataset.json").unlink()
    assert [r["change"] for r in compare_folders(base, variant).rows] == ["only in variant"] * 4
