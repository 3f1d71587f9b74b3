"""The claims declared per document (locbook/data/claims/*.csv) and their evaluation: a three-valued test
decided only beyond two standard errors of a difference, on printed values as printed."""
import math
import re

import pytest

from locbook.reproduce.claims import CLAIM_COLUMNS, CLAIMS_DIR, ClaimsError, Value, claims, evaluate, load_claims_file

DOCUMENTS = ("dogan2015", "gudipati2017", "palvai2008", "george", "ozkaya2011")


def test_a_comparison_is_decided_only_beyond_two_standard_errors_of_the_difference():
    a = Value(1.0, 0.1)
    s = 2 * math.hypot(0.1, 0.1)                           # 0.283
    assert evaluate("a < b", {"a": a, "b": Value(1.0 + s + 1e-9, 0.1)}) is True
    assert evaluate("a < b", {"a": a, "b": Value(1.0 + s - 1e-9, 0.1)}) is None
    assert evaluate("a < b", {"a": a, "b": Value(1.0 - s - 1e-9, 0.1)}) is False
    assert evaluate("a > b", {"a": a, "b": Value(0.5, 0.1)}) is True
    # exact values (printed, or a closed form) compare as they are, ties included
    assert evaluate("a < b", {"a": Value(1.22), "b": Value(1.22)}) is False
    assert evaluate("a <= b", {"a": Value(1.22), "b": Value(1.22)}) is True


def test_trends_chains_and_kleene_logic():
    env = {"x": Value(1.0), "y": Value(2.0), "z": Value(3.0), "u": Value(2.0, 1.0)}
    assert evaluate("increasing(x, y, z)", env) is True and evaluate("decreasing(z, y, x)", env) is True
    assert evaluate("increasing(x, z, y)", env) is False
    assert evaluate("x < y < z", env) is True and evaluate("x < z < y", env) is False
    assert evaluate("increasing(x, u, z)", env) is None           # u is within 2 SE of both neighbours
    # False and unknown is False; True or unknown is True; not unknown is unknown
    assert evaluate("x > y and x < u", env) is False
    assert evaluate("x < y or x < u", env) is True
    assert evaluate("not (x < u)", env) is None


def test_arithmetic_carries_the_standard_error_by_the_delta_method():
    a, b = Value(2.0, 0.1), Value(4.0, 0.2)
    # a / b = 0.5 with se = sqrt((0.1/4)^2 + (2 * 0.2 / 16)^2) = 0.0354; 0.5 - 0.0707 is the decision edge
    se = math.sqrt((0.1 / 4) ** 2 + (2 * 0.2 / 16) ** 2)
    assert evaluate("a / b > c", {"a": a, "b": b, "c": Value(0.5 - 2 * se - 1e-6)}) is True
    assert evaluate("a / b > c", {"a": a, "b": b, "c": Value(0.5 - 2 * se + 1e-6)}) is None
    # a - b < 0 is the same test as a < b
    for b2 in (Value(2.5, 0.1), Value(2.2, 0.1), Value(1.5, 0.1)):
        assert evaluate("a - b < 0", {"a": a, "b": b2}) == evaluate("a < b", {"a": a, "b": b2})
    assert evaluate("abs(a - b) < 0.5", {"a": a, "b": Value(2.1)}) is True


def test_a_claim_rows_own_verdict():
    assert evaluate("verdict(r)", {"r": Value(float("nan"), 0.0, "within")}) is True
    assert evaluate("verdict(r)", {"r": Value(float("nan"), 0.0, "miss")}) is False
    assert evaluate("verdict(r)", {"r": Value(float("nan"), 0.0, "loose")}) is None
    assert evaluate("a < b", {"a": Value(float("nan")), "b": Value(1.0)}) is None      # no value: undecidable


def _write(tmp_path, *rows):
    import csv
    path = tmp_path / "doc.csv"
    with open(path, "w", newline="", encoding="utf-8") as fh:
        fh.write("# claims of a toy document\n")
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(CLAIM_COLUMNS)
        for r in rows:
            w.writerow([r.get(c, "") for c in CLAIM_COLUMNS])
    return path


GOOD = {"id": "map_worse", "location": "Sec. 1 (line 9)", "claim": "MAP is worse than MMSE", "kind": "ranking",
        "evidence": '{ map = "doc-sim | Table 1 | MAP | rmse_m", mmse = "doc-sim | Table 1 | MMSE | rmse_m" }',
        "test": "map > mmse"}


def test_a_good_claims_file_loads(tmp_path):
    (c,) = load_claims_file(_write(tmp_path, GOOD))
    assert c.evidence == {"map": ("doc-sim", "Table 1 | MAP | rmse_m"), "mmse": ("doc-sim", "Table 1 | MMSE | rmse_m")}
    assert c.testable and c.document == "doc"


@pytest.mark.parametrize("change, problem", [
    ({"kind": "opinion"}, "unknown kind 'opinion'"),
    ({"id": "Bad Id"}, "must be snake_case"),
    ({"test": "map > other"}, "names 'other', which is not in evidence"),
    ({"test": "__import__('os')"}, "calls something other than"),
    ({"test": "map.real > 0"}, "uses Attribute, which is not allowed"),
    ({"test": "map > 'x'"}, "only numbers are allowed"),
    ({"evidence": '{ map = "no separator" }', "test": "map > 0"}, "must read"),
    ({"evidence": "not toml"}, "is not a TOML inline table"),
    ({"ambiguity": "two readings"}, "ambiguity and alt_test go together"),
    ({"claim": ""}, "claim is empty"),
])
def test_a_broken_claim_is_one_line_naming_file_and_claim(tmp_path, change, problem):
    with pytest.raises(ClaimsError, match=re.escape(problem)) as info:
        load_claims_file(_write(tmp_path, {**GOOD, **change}))
    assert str(tmp_path / "doc.csv") in str(info.value) and "\n" not in str(info.value)


def test_the_packaged_claims_files_load():
    for doc in DOCUMENTS:
        if (CLAIMS_DIR / f"{doc}.csv").is_file():
            found = claims(doc)
            assert found and len({c.id for c in found}) == len(found)


def test_a_claim_is_judged_on_printed_values_on_ours_and_under_every_other_reading(tmp_path):
    from locbook.suite.conclusions import conclusions_markdown, judge_claim
    (c,) = load_claims_file(_write(tmp_path, GOOD))
    rows = {("doc-sim", "Table 1 | MAP | rmse_m"): {"experiment": "doc-sim", "printed_id": "Table 1 | MAP | rmse_m",
                                                    "printed": "1.30", "reproduced": "1.40", "mc_std_error": "0.01",
                                                    "kind": "reproduction", "verdict": "miss"},
            ("doc-sim", "Table 1 | MMSE | rmse_m"): {"experiment": "doc-sim", "printed_id": "Table 1 | MMSE | rmse_m",
                                                     "printed": "1.22", "reproduced": "1.20", "mc_std_error": "0.01",
                                                     "kind": "reproduction", "verdict": "within"}}
    values = {"doc-sim": [
        # a textual reading under which MAP is no worse; a fitted one under which it still is
        {"point": "p1", "interpretation": "noise: n='x'", "basis": "textual", "printed_id": "Table 1 | MAP | rmse_m",
         "ours": "1.10", "mc_std_error": "0.01", "verdict": "miss"},
        {"point": "p2", "interpretation": "noise [fitted]: n='y'", "basis": "fitted",
         "printed_id": "Table 1 | MAP | rmse_m",
         "ours": "1.50", "mc_std_error": "0.01", "verdict": "miss"},
        {"point": "p0", "interpretation": "default", "basis": "default", "printed_id": "Table 1 | MAP | rmse_m",
         "ours": "1.40", "mc_std_error": "0.01", "verdict": "miss"}]}
    # values.csv holds every scored row under every point: MMSE too, unchanged here
    values["doc-sim"] += [{"point": p, "interpretation": r, "basis": b, "printed_id": "Table 1 | MMSE | rmse_m",
                           "ours": "1.20", "mc_std_error": "0.01", "verdict": "within"}
                          for p, r, b in (("p1", "noise: n='x'", "textual"), ("p2", "noise [fitted]: n='y'", "fitted"),
                                          ("p0", "default", "default"))]
    j = judge_claim(c, rows, values)
    assert (j["printed"], j["ours"], j["interpretations"]) == (True, True, 2)      # 1.30 > 1.22 as printed; 1.40 > 1.20
    assert j["changed_by"] == ["doc-sim, noise: n='x' [textual]: fails"]
    page = conclusions_markdown("doc", "A. Author", 2011, [j], "full")
    assert ("1 hold, 0 fail and 0 are undecidable" in page
            and "changes under doc-sim, noise: n='x' [textual]: fails" in page)
    # a bracket whose default run is not this report's (another profile, other code) judges no other reading
    stale = {k: {**v, "reproduced": "1.41"} if "MAP" in k[1] else v for k, v in rows.items()}
    j3 = judge_claim(c, stale, values)
    assert j3["interpretations"] == 0 and "its bracket's default run differs from this report" in j3["not_judged"][0]
    # a linked evidence row follows its master's value under each reading
    linked = {**rows, ("doc-sim", "Table 2 | MAP | rmse_m"): {**rows[("doc-sim", "Table 1 | MAP | rmse_m")],
                                                               "printed_id": "Table 2 | MAP | rmse_m",
                                                               "same_as": "Table 1 | MAP | rmse_m", "verdict": ""}}
    c2 = load_claims_file(_write(tmp_path, {**GOOD, "evidence": GOOD["evidence"].replace("Table 1 | MAP",
                                                                                            "Table 2 | MAP")}))[0]
    assert judge_claim(c2, linked, values)["changed_by"] == ["doc-sim, noise: n='x' [textual]: fails"]
    # a repeat in another experiment (a comparison table) follows its master's experiment's bracket
    other = {**rows, ("doc-cmp", "Table 2 | MAP | rmse_m"): {**rows[("doc-sim", "Table 1 | MAP | rmse_m")],
                                                              "experiment": "doc-cmp", "document": "doc",
                                                              "printed_id": "Table 2 | MAP | rmse_m",
                                                              "same_as": "Table 1 | MAP | rmse_m", "verdict": ""}}
    for k in list(other):
        other[k] = {"document": "doc", **other[k]}
    c3 = load_claims_file(_write(tmp_path, {**GOOD, "evidence": GOOD["evidence"].replace(
        "doc-sim | Table 1 | MAP", "doc-cmp | Table 2 | MAP")}))[0]
    assert judge_claim(c3, other, values)["changed_by"] == ["doc-sim, noise: n='x' [textual]: fails"]
    # a row missing from the folder leaves the claim undecidable, saying which
    (j2,) = [judge_claim(c, {k: v for k, v in rows.items() if "MAP" not in k[1]}, {})]
    assert j2["ours"] is None and "Table 1 | MAP | rmse_m is not in this folder's numbers.csv" in j2["why"]


@pytest.mark.parametrize("test, problem", [
    ("verdict(map) < 1", "is a truth where a number is needed"),
    ("map + (map < mmse) > 0", "is a truth where a number is needed"),
    ("(map < mmse) < 1", "is a truth where a number is needed"),
    ("abs(map < mmse) > 0", "is a truth where a number is needed"),
    ("increasing(map, mmse) < 1", "is a truth where a number is needed"),
    ("abs() > 0", "abs() takes one argument"),
    ("abs < map", "abs is a function; call it"),
    ("verdict(increasing)", "increasing is a function; call it"),
    ("increasing(map)", "needs two or more arguments"),
    ("map", "is a number, not a statement"),
    ("not map", "is a number where a truth is needed"),
])
def test_a_test_that_mixes_numbers_and_truths_is_refused_when_the_file_loads(tmp_path, test, problem):
    with pytest.raises(ClaimsError, match=re.escape(problem)):
        load_claims_file(_write(tmp_path, {**GOOD, "test": test}))
