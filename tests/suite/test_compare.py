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
