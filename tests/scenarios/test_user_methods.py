"""Your own method beside the battery: registered in the manifest (``[[method]]``) or on the command line
(``--method`` / ``--tracker``), run on the same epochs as the battery, scored by the same rows and bound, and failing
alone.

The methods are the helpers of tests/user_method_examples.py (a power-weighted centroid, a smoothed one as a tracker,
one that raises, outputs that break the rule). The fast tests call the measured-data protocol directly on a small
example data set (given settings: no motion fit) and check the command line up to where notebooks would run; the
slow one runs ``locbook run --data`` end to end, twice.
"""
from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import locbook as lb
from builders import TESTS_DIR
from locbook.data.dataset import load_dataset
from locbook.data.example import write_example_dataset
from locbook.data.measured import DataFormatError
from locbook.errors import ParameterError
from locbook.scenarios import measured as me
from locbook.suite import cachekey, runner
from locbook.suite import run as suite_run
from locbook.user_methods import (
    MethodFailure,
    UserMethod,
    check_output,
    method_name_problem,
    parse_method_option,
    registered_methods,
    run_method,
)

HERE = TESTS_DIR                     # user_method_examples.py's folder
EXAMPLES = HERE / "user_method_examples.py"
CENTROID = f"{EXAMPLES}:weighted_centroid"
STATS = ("mean_m", "median_m", "p90_m", "ce95_m", "rmse_m", "coverage")


def example(folder: Path, name: str = "mine") -> Path:
    return write_example_dataset(folder, np.random.default_rng(3), name=name, walk_s=30.0)


def with_methods(folder: Path, tables: str) -> Path:
    """The data set at ``folder`` with ``tables`` ([[method]] TOML) appended to its manifest."""
    manifest = folder / "dataset.toml"
    manifest.write_text(manifest.read_text() + "\n" + tables)
    return folder


# -- registering -------------------------------------------------------------------------------------------------

def test_a_manifest_registers_methods_by_file_and_module(tmp_path):
    folder = example(tmp_path / "set")
    shutil.copy(EXAMPLES, folder / "mine.py")
    with_methods(folder, '[[method]]\nname = "centroid"\nfunction = "mine.py:weighted_centroid"\nkind = "static"\n'
                         '[[method]]\nname = "Smooth-1"\nfunction = "user_method_examples:smoothed_centroid"\n'
                         'kind = "tracker"\n')
    ds = load_dataset(folder)
    a, b = ds.methods
    assert (a.name, a.kind, a.path, a.module, a.attribute, a.source) == (
        "centroid", "static", (folder / "mine.py").resolve(), None, "weighted_centroid", "manifest")
    assert (b.name, b.kind, b.path, b.module) == ("Smooth-1", "tracker", None, "user_method_examples")
    assert (folder / "mine.py") in ds.files                    # its folder is a data root; the report depends on it
    assert a.described.startswith("user method mine.py:weighted_centroid (sha256 ")
    assert b.described == "user method user_method_examples:smoothed_centroid"


@pytest.mark.parametrize("table, needles", [
    ('name = "x"\nfunction = "m:f"\nkind = "static"\ncolour = 1\n', ["[[method]] 'x': unknown key(s)", "colour"]),
    ('name = "x"\nfunction = "m:f"\nkind = "smoother"\n', ["[[method]] 'x': kind must be one of", "'smoother'"]),
    ('name = "x"\nkind = "static"\n', ["[[method]] 'x': 'function' is required"]),
    ('name = "x"\nfunction = 3\nkind = "static"\n', ["[[method]] 'x': 'function' must be a non-empty string, got 3"]),
    ('function = "m:f"\nkind = "static"\n', ["[[method]] 1: 'name' is required"]),
    ('name = "ekf"\nfunction = "m:f"\nkind = "static"\n', ["method name 'ekf' is a battery method's"]),
    ('name = "LLS"\nfunction = "m:f"\nkind = "tracker"\n', ["method name 'LLS' is a battery method's"]),
    ('name = "crlb"\nfunction = "m:f"\nkind = "static"\n', ["method name 'crlb' is reserved"]),
    ('name = "my method"\nfunction = "m:f"\nkind = "static"\n', ["method name 'my method' must be letters"]),
    ('name = "x"\nfunction = "m.f"\nkind = "static"\n', ["function must be package.module:function"]),
    ('name = "x"\nfunction = "m:1f"\nkind = "static"\n', ["'1f' after the last ':'"]),
    ('name = "x"\nfunction = "gone.py:f"\nkind = "static"\n',
     ["[[method]] 'x': function: file 'gone.py' does not exist"]),
    ('name = "x"\nfunction = "../out.py:f"\nkind = "static"\n', ["must be a file inside the data set's folder"]),
])
def test_a_bad_method_table_is_one_line_naming_the_key(tmp_path, table, needles):
    folder = with_methods(example(tmp_path / "set"), "[[method]]\n" + table)
    (tmp_path / "out.py").write_text("def f(inp):\n    return None\n")
    with pytest.raises(DataFormatError) as info:
        load_dataset(folder)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(folder / "dataset.toml"))
    for needle in needles:
        assert needle in message, message


def test_a_name_twice_is_refused_in_the_manifest_and_between_manifest_and_command_line(tmp_path):
    twice = '[[method]]\nname = "c"\nfunction = "m:f"\nkind = "static"\n'
    folder = with_methods(example(tmp_path / "set"), twice + twice.replace('"static"', '"tracker"'))
    with pytest.raises(DataFormatError, match=r"\[\[method\]\] 'c': the name appears twice"):
        load_dataset(folder)
    folder = with_methods(example(tmp_path / "other"), twice)
    with pytest.raises(ParameterError, match="method name 'C' is given twice .*static, manifest: m:f; tracker, "
                                             "command line"):
        registered_methods(load_dataset(folder), trackers=[f"C={CENTROID}"])


@pytest.mark.parametrize("text, kind, message", [
    ("centroid", "static", "--method expects NAME=SPEC"),
    (f"ekf={CENTROID}", "tracker", "--tracker ekf=.*: method name 'ekf' is a battery method's"),
    (f"9lives={CENTROID}", "static", "method name '9lives' must be letters"),
    ("c=nowhere.py:f", "static", "method 'c': no file 'nowhere.py' .not found at "),
    ("c=a b:f", "static", "'a b' is neither a .py file nor a dotted module name"),
    ("c=mod", "static", "function must be package.module:function"),
])
def test_a_bad_command_line_method_is_one_line(text, kind, message):
    with pytest.raises(ParameterError, match=message) as info:
        parse_method_option(text, kind)
    assert "\n" not in str(info.value)


def test_a_file_spec_is_relative_to_the_current_folder_on_the_command_line(tmp_path, monkeypatch):
    (tmp_path / "m.py").write_text("def f(inp):\n    return None\n")
    monkeypatch.chdir(tmp_path)
    m = parse_method_option("mine=m.py:f", "tracker")
    assert (m.path, m.attribute, m.option()) == ((tmp_path / "m.py").resolve(), "f",
                                                 f"mine={(tmp_path / 'm.py').resolve()}:f")
    assert method_name_problem("my_method-2") == ""


# -- the output rule --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("output, needle", [
    (np.zeros((4, 3)), "returned positions of shape (4, 3)"),
    (np.zeros(8), "returned positions of shape (8,)"),
    ([[0, 0], [1, 1], [np.inf, 0], [0, 0]], "returned inf at epoch 2"),
    ([[0, 0], [np.nan, 1], [0, 0], [0, 0]], "returned half a position at epoch 1"),
    (np.zeros((4, 2), complex), "returned complex values"),
    (None, "returned None"),
    ("here", "returned a str ('here')"),
    ({"x": 1}, "returned a dict"),
    ([[0, 0], [1]], "that is no array"),
    (np.zeros((4, 2), bool), "of bool"),
    ((np.zeros((4, 2)), np.zeros((4, 2))), "returned covariances of shape (4, 2)"),
    ((np.zeros((4, 2)), np.full((4, 2, 2), np.nan)), "a non-finite covariance at epoch 0"),
    ((np.zeros((4, 2)), np.broadcast_to([[1.0, 0.5], [0.0, 1.0]], (4, 2, 2))), "not symmetric at epoch 0"),
    ((np.zeros((4, 2)), np.broadcast_to(np.diag([1.0, -1.0]), (4, 2, 2))), "not positive semi-definite at epoch 0"),
])
def test_an_output_that_breaks_the_rule_is_one_line_naming_the_method_and_what_it_returned(output, needle):
    with pytest.raises(ValueError) as info:
        check_output("mine", output, 4)
    message = str(info.value)
    assert "\n" not in message and message.startswith("user method 'mine' returned") and needle in message, message
    assert "it returns positions (4, 2)" in message


def test_the_rule_takes_lists_whole_numbers_nan_rows_and_covariances_where_there_is_no_fix():
    p, c = check_output("mine", [[0, 1], [2, 3], [np.nan, np.nan]], 3)
    assert p.dtype == float and np.array_equal(p[:2], [[0, 1], [2, 3]]) and np.isnan(p[2]).all() and c is None
    cov = np.stack([np.eye(2), 2 * np.eye(2), np.full((2, 2), np.nan)])
    p, c = check_output("mine", ([[0, 1], [2, 3], [np.nan, np.nan]], cov), 3)
    assert c.shape == (3, 2, 2) and np.array_equal(c[:2], cov[:2])
    p, c = check_output("mine", ((0.0, 1.0), (2.0, 3.0)), 2)       # a tuple of two positions is positions
    assert np.array_equal(p, [[0, 1], [2, 3]]) and c is None


# -- running one --------------------------------------------------------------------------------------------------

def _input(n=5):
    ds_like = lb.MethodInput(rss_dbm=np.full((n, 3), -60.0), time_s=np.arange(n, dtype=float), recording="points",
                             kind="static", tag_height_m=1.0, anchors_m=np.array([[0.0, 0, 2], [4, 0, 2], [0, 4, 2]]),
                             channel=lb.PathLossModel(-40.0, 2.0, 3.0), model=None,
                             outline_m=np.array([[0.0, 0], [4, 0], [4, 4], [0, 4]]))
    return ds_like


def test_a_raising_method_fails_with_its_own_traceback_and_not_locbooks():
    got = run_method(UserMethod.parse("b", f"{EXAMPLES}:boom", "static", base=HERE), {"points": _input()})
    assert isinstance(got, MethodFailure)
    assert (got.name, got.recording, got.error) == ("b", "points", "ZeroDivisionError: division by zero")
    lines = got.traceback.splitlines()
    assert lines[0] == "Traceback (most recent call last):" and lines[-1] == "ZeroDivisionError: division by zero"
    assert ('user_method_examples.py", line' in got.traceback and "in boom" in got.traceback
            and "in _divide" in got.traceback)
    assert "locbook" not in got.traceback.replace(str(HERE), "")         # no frame of locbook's (the tests path aside)
    assert got.line().startswith(f"user method 'b' (static, user method {EXAMPLES}:boom (sha256 ")
    assert got.line().endswith(") failed on points: ZeroDivisionError: division by zero")


@pytest.mark.parametrize("spec, error", [
    ("no_such_module_48:f", "ModuleNotFoundError: No module named 'no_such_module_48'"),
    ("user_method_examples:missing", "AttributeError: user_method_examples has no 'missing'"),
    ("user_method_examples:NOT_A_FUNCTION", "TypeError: user_method_examples:NOT_A_FUNCTION is not a function: "
                                            "NOT_A_FUNCTION is of type int"),
    ("broken.py:f", "SyntaxError"),
])
def test_a_method_that_does_not_import_fails_on_no_recording(tmp_path, spec, error):
    (tmp_path / "broken.py").write_text("def f(inp)\n    return 1\n")
    got = run_method(UserMethod.parse("m", spec, "static", base=tmp_path), {"points": _input()})
    assert isinstance(got, MethodFailure) and got.recording == "" and got.error.startswith(error), got.error
    if spec.startswith("broken"):
        assert "broken.py" in got.traceback and "line 1" in got.traceback


def test_a_method_cannot_change_what_it_is_given(measured):
    ds, model, _proto = measured
    rss = ds.epochs("points").rss_dbm
    before = rss.copy()
    inp = me.method_input(ds, model, "points", rss, ds.epochs("points").time_s, None)
    assert not any(a.flags.writeable for a in (inp.rss_dbm, inp.time_s, inp.anchors_m, inp.outline_m))
    assert inp.channel is not model and inp.model.channel is inp.channel and inp.kind == "static"
    got = run_method(UserMethod.parse("m", "user_method_examples:mutates", "static", base=HERE), {"points": inp})
    assert isinstance(got, MethodFailure) and "read-only" in got.error
    assert np.array_equal(rss, before, equal_nan=True)


def test_the_code_a_method_ran_joins_the_reports_cache_record(tmp_path, monkeypatch):
    """Under `locbook run` the kernel logs the file it executed with the hash of what it ran (the audit hook skips
    .py files), so run.json records it and an edit makes the cached report stale."""
    log = tmp_path / ".data-read.log"
    monkeypatch.setenv("LOCBOOK_DATA_LOG", str(log))
    source = tmp_path / "m.py"
    source.write_text("import numpy as np\n\ndef f(inp):\n    return np.zeros((inp.n_epochs, 2))\n")
    got = run_method(UserMethod.parse("m", "m.py:f", "static", base=tmp_path), {"points": _input()})
    assert not isinstance(got, MethodFailure)
    hashes, _links, changed = cachekey.data_hashes(tmp_path)
    assert list(hashes) == [str(source.resolve())] and not changed
    assert cachekey.data_unchanged(hashes)
    source.write_text(source.read_text().replace("zeros", "ones"))
    assert not cachekey.data_unchanged(hashes)                 # edited: the report that ran it is not served cached
    # a module spec records its module's source the same way
    log.unlink()
    got = run_method(UserMethod.parse("m", "user_method_examples:weighted_centroid", "static", base=HERE),
                     {"points": _input()})
    assert list(cachekey.data_hashes(tmp_path)[0]) == [str(EXAMPLES)]


# -- scored by the protocol ----------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    """The example data set, its channel and given settings (no motion fit: fast)."""
    folder = example(tmp_path_factory.mktemp("set") / "set")
    ds = me.load(folder)
    model = me.channel(me.calibrate(ds))
    proto = me.protocol(ds, model, grid_spacing_m=0.4, knn_k=4, q=0.05, spread_m=0.4)
    return ds, model, proto


RUN = dict(seed=11, n_bootstrap=30, block_s=10.0)
TRACK_RUN = dict(seed=11, n_particles=100, particle_runs=2, n_bootstrap=30, block_s=10.0)


@pytest.fixture(scope="module")
def results(measured):
    ds, model, proto = measured
    good = registered_methods(methods=[f"centroid={CENTROID}"],
                              trackers=["smooth=user_method_examples:smoothed_centroid"])
    bad = registered_methods(methods=[f"centroid={CENTROID}", "boom=user_method_examples:boom"],
                             trackers=["smooth=user_method_examples:smoothed_centroid",
                                       "shape=user_method_examples:wrong_shape"])
    out = {}
    for key, user in (("none", ()), ("good", good), ("bad", bad)):
        out[key] = (me.static_results(ds, model, proto, user_methods=user, **RUN),
                    me.tracking_results(ds, model, proto, user_methods=user, **TRACK_RUN))
    return out


def _rows(res, method=None):
    return [r for r in res["rows"] if method is None or r["method"] == method]


def test_a_user_method_is_scored_like_the_battery_and_equals_its_own_output_scored_by_locbook_metrics(
        measured, results):
    ds, model, proto = measured
    import user_method_examples as ex
    st, tr = results["good"]
    rows = {r["recording"]: r for r in _rows(st, "centroid")}
    assert set(rows) == {"pooled", *st["recordings"]} and list(st["fixes"][st["recordings"][0]])[-1] == "centroid"
    # independently: the function on each scored recording's epochs (the data set read again), scored by lb.metrics
    errors = {}
    for name in st["recordings"]:
        ep = ds.epochs(name)
        known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
        inp = lb.MethodInput(rss_dbm=ep.rss_dbm[known], time_s=ep.time_s[known], recording=name, kind="static",
                             tag_height_m=ds.tag_height_m, anchors_m=ds.anchors_m, channel=model, model=None,
                             outline_m=ds.outline_m)
        errors[name] = lb.position_error_m(ex.weighted_centroid(inp), ep.position_m[known, :2])
    for label, e in [("pooled", np.concatenate(list(errors.values()))), *errors.items()]:
        r = rows[label]
        ok = e[np.isfinite(e)]
        direct = {"mean_m": lb.mean_error_m(ok), "median_m": lb.median_error_m(ok),
                  "p90_m": lb.percentile_error_m(ok, 90),
                  "ce95_m": lb.percentile_error_m(ok, 95), "rmse_m": lb.rmse_m(ok), "coverage": ok.size / e.size}
        for k in STATS:
            assert r[k] == round(direct[k], 3), (label, k, r[k], direct[k])
        bound = np.concatenate([st["bounds"][n][0] for n in (errors if label == "pooled" else [label])])
        both = np.isfinite(bound) & np.isfinite(e)            # the ratio's pairs: an error and a defined bound
        assert r["ratio"] == round(lb.rmse_m(e[both]) / np.sqrt(np.mean(bound[both] ** 2)), 3)
        assert r["settings"].startswith(f"user method {EXAMPLES}:weighted_centroid (sha256 ") and r["failure"] == ""
        assert r["bound"] == "CRLB (fitted channel, anchors heard)" and r["ratio"] is not None
    # the tracker: every track, in time order on its clock, against the same PCRLB as the battery's trackers
    rows = {r["recording"]: r for r in _rows(tr, "smooth")}
    assert set(rows) == {"pooled", "walk_a", "walk_b"}
    for name, (sc, est, flags, bound) in tr["tracks"].items():
        inp = lb.MethodInput(rss_dbm=sc.measured_rss_dbm, time_s=sc.time_s, recording=name, kind="track",
                             tag_height_m=ds.tag_height_m, anchors_m=ds.anchors_m, channel=model, model=None,
                             outline_m=ds.outline_m)
        mine = ex.smoothed_centroid(inp)
        assert np.array_equal(est["smooth"][0], mine, equal_nan=True) and "smooth" not in flags
        steps = sc.scored_steps
        e = lb.position_error_m(mine[steps], sc.truth_m[steps])
        assert rows[name]["mean_m"] == round(lb.mean_error_m(e[np.isfinite(e)]), 3)
        assert rows[name]["rmse_m"] == round(lb.rmse_m(e[np.isfinite(e)]), 3)
        assert np.allclose(np.diff(sc.time_s), sc.dt_s) and len(sc.time_s) == len(sc.truth_m)


def test_user_methods_leave_the_batterys_numbers_as_they_were(results):
    for i in (0, 1):
        none, good = results["none"][i], results["good"][i]
        battery = [r for r in good["rows"] if "failure" not in r]
        assert battery == none["rows"]                        # the same rows, in the same order, the same numbers
        assert [r for r in good["rows"] if "failure" in r] and all(r["method"] in ("centroid", "smooth")
                                                                 for r in good["rows"] if "failure" in r)
    st_none, st_good = results["none"][0], results["good"][0]
    for name in st_none["recordings"]:
        for method, e in st_none["errors"][name].items():
            assert np.array_equal(st_good["errors"][name][method], e, equal_nan=True)


def test_a_failing_method_says_so_in_its_rows_and_leaves_every_other_row_and_figure_input_as_it_was(results):
    for i, failed in ((0, "boom"), (1, "shape")):
        good, bad = results["good"][i], results["bad"][i]
        assert [r for r in bad["rows"] if r["method"] != failed] == good["rows"]
        rows = _rows(bad, failed)
        assert rows and all(r["mean_m"] is None and r["ratio"] is None and r["failure"].startswith("failed: ")
                            for r in rows)
        assert me.scored_methods(bad) == me.scored_methods(good)          # what the figures draw
        assert list(bad["failures"]) == [failed]
    st_good, st_bad = results["good"][0], results["bad"][0]
    assert st_bad["failures"]["boom"].error == "ZeroDivisionError: division by zero"
    for name in st_good["recordings"]:
        assert st_bad["fixes"][name].keys() == st_good["fixes"][name].keys()
    tr_bad = results["bad"][1]
    assert tr_bad["failures"]["shape"].error.startswith("returned positions of shape (")
    assert all("shape" not in est for sc, est, flags, bound in tr_bad["tracks"].values())
    table = me.user_method_rows(st_bad, tr_bad)
    assert [(r["method"], r["status"]) for r in table] == [("centroid", "ok"), ("boom", "failed"), ("smooth", "ok"),
                                                          ("shape", "failed")]
    assert "in boom" in table[1]["traceback"] and table[3]["traceback"] == ""


def test_the_benchmark_cells_of_a_data_set_carry_the_user_methods(results):
    st, tr = results["bad"]
    cells = me.benchmark_rows(_ds(st), st, tr)
    mine = {(c["kind"], c["method"]): c for c in cells if "failure" in c}
    assert set(mine) == {("static", "centroid"), ("static", "boom"), ("tracking", "smooth"), ("tracking", "shape")}
    assert mine["static", "centroid"]["rmse_m"] == next(r["rmse_m"] for r in _rows(st, "centroid")
                                                        if r["recording"] == "pooled")
    assert mine["static", "boom"]["rmse_m"] is None and mine["static", "boom"]["failure"].startswith("failed: ")


def _ds(st):
    class Named:                       # benchmark_rows reads the data set's name only
        name = st["scenario"].document
    return Named()


# -- the command line, without executing a notebook ---------------------------------------------------------------

@pytest.fixture
def no_execution(monkeypatch):
    """run_tasks replaced by a stand-in that records the tasks and writes, for each, a report folder holding the
    user_methods table a notebook would (every user method ok, or failed where ``seen["fail"]`` names it)."""
    seen = {"fail": set()}

    def run_tasks(suite, tasks, profile, report_dir, *, write_reports, progress="plain", **_kwargs):
        seen["tasks"], seen["report_dir"] = {t.key: t.parameters for t in tasks}, report_dir
        for t in tasks:
            folder = report_dir / t.key
            folder.mkdir(parents=True, exist_ok=True)
            names = [o.partition("=")[0] for k in ("methods", "trackers") for o in t.parameters.get(k, [])]
            if names:
                with open(folder / suite_run.USER_METHODS_TABLE, "w", newline="", encoding="utf-8") as fh:
                    writer = csv.DictWriter(fh, ["method", "kind", "function", "status", "error"])
                    writer.writeheader()
                    for n in names:
                        failed = n in seen["fail"]
                        writer.writerow({"method": n, "kind": "static", "function": f"user method {n}",
                                         "status": "failed" if failed else "ok",
                                         "error": "ZeroDivisionError: division by zero" if failed else ""})
        outcomes = [runner.Outcome(t.key, "ok", 0.0) for t in tasks]
        return runner.SuiteRun(outcomes, report_dir)

    monkeypatch.setattr(runner, "run_tasks", run_tasks)
    return seen


def test_the_command_line_passes_each_method_to_the_reports_that_take_its_kind(tmp_path, no_execution, capsys,
                                                                               monkeypatch):
    from locbook.suite.cli import main
    folder = example(tmp_path / "set")
    shutil.copy(EXAMPLES, tmp_path / "m.py")
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--data", str(folder), "--reports", str(tmp_path / "r"), "--quiet",
                 "--method", "centroid=m.py:weighted_centroid", "--tracker",
                 "smooth=user_method_examples:smoothed_centroid"]) == 0
    tasks = no_execution["tasks"]
    file = (tmp_path / "m.py").resolve()
    assert tasks["measured-localization"]["methods"] == [f"centroid={file}:weighted_centroid"]
    assert "trackers" not in tasks["measured-localization"] and "methods" not in tasks["measured-tracking"]
    assert tasks["measured-tracking"]["trackers"] == ["smooth=user_method_examples:smoothed_centroid"]
    assert (tasks["benchmark-cross-document"]["methods"], tasks["benchmark-cross-document"]["trackers"]) == (
        [f"centroid={file}:weighted_centroid"], ["smooth=user_method_examples:smoothed_centroid"])
    assert not {"methods", "trackers"} & set(tasks["measured-calibration"])
    assert no_execution["report_dir"] == tmp_path / "r" / "quick" / "data-mine"      # the data run's own folder
    assert capsys.readouterr().err == ""
    # a method that failed: one line naming it and where its traceback is, and exit 1 (the reports are complete)
    no_execution["fail"] = {"centroid"}
    assert main(["run", "--data", str(folder), "--reports", str(tmp_path / "r"), "--quiet",
                 "--method", "centroid=m.py:weighted_centroid"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(
        "locbook: user method 'centroid' (static, user method centroid) failed in measured-localization, "
        "benchmark-cross-document: ZeroDivisionError: division by zero; its traceback: ")
    assert str(tmp_path / "r" / "quick" / "data-mine" / "measured-localization" / "report.html") in err


@pytest.mark.parametrize("argv, message", [
    (["--method", "ekf=m.py:f"], "locbook: error: --method ekf=m.py:f: method name 'ekf' is a battery method's"),
    (["--tracker", "x=m.py"], "locbook: error: --tracker x=m.py: method 'x': function must be"),
    (["--method", "x=gone.py:f"], "locbook: error: --method x=gone.py:f: method 'x': no file 'gone.py'"),
    (["--method", "x=m.py:f", "--tracker", "x=m.py:f"], "locbook: error: method name 'x' is given twice"),
    (["-p", 'methods=["x=m.py:f"]'], "locbook: error: -p methods: give methods of your own with --method"),
    (["--method", "fromfile=m.py:f"], "locbook: error: method name 'fromfile' is given twice"),
])
def test_a_bad_method_on_the_command_line_is_one_line_and_exit_2(tmp_path, no_execution, capsys, monkeypatch,
                                                                 argv, message):
    from locbook.suite.cli import EXIT_BAD_INPUT, main
    folder = with_methods(example(tmp_path / "set"),
                          '[[method]]\nname = "fromfile"\nfunction = "m.py:f"\nkind = "static"\n')
    for where in (tmp_path, folder):
        (where / "m.py").write_text("def f(inp):\n    return None\n")
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--data", str(folder), "--reports", str(tmp_path / "r"), *argv]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(message), err
    assert "tasks" not in no_execution


def test_methods_need_a_data_run(tmp_path, no_execution, capsys):
    from locbook.suite.cli import main
    assert main(["run", "measured-localization", "--reports", str(tmp_path / "r"), "--method",
                 f"c={CENTROID}"]) == 2
    assert capsys.readouterr().err == ("locbook: error: --method and --tracker run beside the battery on a data set: "
                                       "give one with --data DIR (a shipped one by name: --data kolakowski2021)\n")


def test_data_check_lists_the_registered_methods_and_whether_each_imports(tmp_path, capsys):
    from locbook.suite.cli import main
    folder = example(tmp_path / "set")
    shutil.copy(EXAMPLES, folder / "mine.py")
    with_methods(folder, '[[method]]\nname = "centroid"\nfunction = "mine.py:weighted_centroid"\nkind = "static"\n')
    assert main(["data", "check", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "methods of your own (1; they run beside the battery's):" in out
    assert "  centroid (static, [[method]]): user method mine.py:weighted_centroid (sha256 " in out
    assert out.rstrip().endswith(": imports")
    assert main(["data", "check", str(folder), "--tracker", "gone=no_such_module_48:f"]) == 1
    out = capsys.readouterr().out
    assert ("  gone (tracker, --tracker): user method no_such_module_48:f: does not import: ModuleNotFoundError: "
            "No module named 'no_such_module_48'") in out


def test_the_data_page_shows_a_failed_method_as_failed():
    from locbook.suite.site_data import _result_table
    cells, _notes = _result_table([{"method": "boom", "recording": "pooled", "mean_m": "", "ratio": "",
                                    "failure": "failed: ZeroDivisionError: division by zero"},
                                   {"method": "lls", "recording": "pooled", "mean_m": "1.2", "ratio": "1.1"}])
    assert (cells[0]["mean (m)"], cells[0]["mean interval (m)"]) == ("failed",
                                                                     "failed: ZeroDivisionError: division by zero")
    assert cells[1]["mean (m)"] == "1.2"


# -- end to end ----------------------------------------------------------------------------------------------------

def _csv(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.slow
@pytest.mark.notebooks
def test_a_data_run_scores_a_users_methods_in_every_report_and_a_failing_one_fails_alone(tmp_path, capsys,
                                                                                         monkeypatch):
    """`locbook run --data` with a static method on the command line and a tracker in the manifest: their rows are in
    every report that scores methods (measured-localization, measured-tracking, the benchmark's data column), equal
    to their own output scored by locbook.metrics; a second, raising static method changes no other row and no
    figure, its rows say it failed, the command line names it and exits 1."""
    import user_method_examples as ex
    from locbook.suite.cli import main
    folder = example(tmp_path / "set", name="users")
    shutil.copy(EXAMPLES, folder / "mine.py")
    with_methods(folder, '[[method]]\nname = "smooth"\nfunction = "mine.py:smoothed_centroid"\nkind = "tracker"\n')
    shutil.copy(EXAMPLES, tmp_path / "cli.py")
    monkeypatch.chdir(tmp_path)
    base = ["run", "--data", str(folder), "--profile", "quick", "--quiet", "-j", "1", "-p", "n_bootstrap=30"]
    assert main([*base, "--reports", str(tmp_path / "a"), "--method", "centroid=cli.py:weighted_centroid"]) == 0
    capsys.readouterr()
    assert main([*base, "--reports", str(tmp_path / "b"), "--method", "centroid=cli.py:weighted_centroid",
                 "--method", "boom=cli.py:boom"]) == 1
    err = capsys.readouterr().err
    assert err.count("locbook: user method") == 1 and "user method 'boom' (static, " in err
    assert "failed in measured-localization, benchmark-cross-document: ZeroDivisionError: division by zero" in err
    a, b = (next((tmp_path / r).glob("quick-*/data-users")) for r in ("a", "b"))
    ds = load_dataset(folder)
    model = me.channel(me.calibrate(ds))
    # measured-localization: the centroid's rows, equal to its own output scored by locbook.metrics
    loc = {r["recording"]: r for r in _csv(a / "measured-localization" / "results.csv") if r["method"] == "centroid"}
    pooled = []
    for name in me.scored_recordings(ds):
        ep = ds.epochs(name)
        known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
        inp = lb.MethodInput(rss_dbm=ep.rss_dbm[known], time_s=ep.time_s[known], recording=name, kind="static",
                             tag_height_m=ds.tag_height_m, anchors_m=ds.anchors_m, channel=model, model=None,
                             outline_m=ds.outline_m)
        e = lb.position_error_m(ex.weighted_centroid(inp), ep.position_m[known, :2])
        pooled.append(e)
        assert float(loc[name]["mean_m"]) == round(lb.mean_error_m(e), 3)
        assert float(loc[name]["p90_m"]) == round(lb.percentile_error_m(e, 90), 3)
    e = np.concatenate(pooled)
    assert float(loc["pooled"]["rmse_m"]) == round(lb.rmse_m(e), 3) and loc["pooled"]["ratio"] not in ("", None)
    assert float(loc["pooled"]["median_m"]) == round(lb.median_error_m(e), 3)
    settings = _csv(a / "measured-localization" / "settings.csv")
    assert any(r["method"] == "centroid" and r["value"].startswith(
        f"user method {(tmp_path / 'cli.py').resolve()}:weighted_centroid (sha256 ") for r in settings)
    # measured-tracking: the manifest's tracker, against the PCRLB
    trk = {r["recording"]: r for r in _csv(a / "measured-tracking" / "results.csv") if r["method"] == "smooth"}
    assert set(trk) == {"pooled", "walk_a", "walk_b"} and trk["pooled"]["ratio"] not in ("", None)
    assert trk["pooled"]["settings"].startswith("user method mine.py:smoothed_centroid (sha256 ")
    # the benchmark's data column: both, equal to the reports' pooled rows
    bench = {(r["kind"], r["method"]): r for r in _csv(a / "benchmark-cross-document" / "benchmark.csv")}
    assert bench["static", "centroid"]["rmse_m"] == loc["pooled"]["rmse_m"]
    assert bench["tracking", "smooth"]["rmse_m"] == trk["pooled"]["rmse_m"]
    # the raising method: its rows say it failed, every other row and every figure as in the run without it
    for eid, table in (("measured-localization", "results.csv"), ("measured-tracking", "results.csv"),
                       ("benchmark-cross-document", "benchmark.csv")):
        rows_a, rows_b = _csv(a / eid / table), _csv(b / eid / table)
        assert [r for r in rows_b if r["method"] != "boom"] == rows_a, eid
        failed = [r for r in rows_b if r["method"] == "boom"]
        assert bool(failed) == (eid != "measured-tracking")
        assert all(r["failure"] == "failed: ZeroDivisionError: division by zero" and r["mean_m"] == "" for r in failed)
        for png in sorted((a / eid).glob("*.png")):
            assert png.read_bytes() == (b / eid / png.name).read_bytes(), (eid, png.name)
    shown = _csv(b / "measured-localization" / "user_methods.csv")
    boom = next(r for r in shown if r["method"] == "boom")
    assert boom["status"] == "failed" and "in boom" in boom["traceback"] and "in _divide" in boom["traceback"]
    assert "locbook/scenarios" not in boom["traceback"] and "locbook/user_methods" not in boom["traceback"]
    page = (b / "index.md").read_text()
    assert "| boom |" in page and "failed" in page
    # the code a report ran is in its cache record: unchanged, everything is cached (and the failure said again);
    # an edit to the command line's file reruns the reports that run its methods, and only those
    cli = str((tmp_path / "cli.py").resolve())
    run = json.loads((b / "measured-localization" / "run.json").read_text())
    assert run["data"][cli] == cachekey.sha256_file(Path(cli))
    assert cli not in json.loads((b / "measured-tracking" / "run.json").read_text())["data"]
    again = [*base, "--reports", str(tmp_path / "b"), "--method", "centroid=cli.py:weighted_centroid",
             "--method", "boom=cli.py:boom"]
    assert main(again) == 1
    out, err = capsys.readouterr()
    assert "done: 0 executed, 4 cached, 0 failed" in out and "user method 'boom' (static, " in err
    with open(tmp_path / "cli.py", "a") as fh:
        fh.write("\n# edited\n")
    assert main(again) == 1
    out = capsys.readouterr().out
    assert "done: 2 executed, 2 cached, 0 failed" in out
    status = json.loads((b / "status.json").read_text())
    assert {k: v["status"] for k, v in status.items()} == {
        "measured-calibration": "cached", "measured-localization": "ok", "measured-tracking": "cached",
        "benchmark-cross-document": "ok"}


def test_the_entry_points_examples_run_as_printed():
    """MethodInput's and UserMethod's Examples sections (numpydoc, ``>>>``) give exactly the output they show."""
    import doctest

    import locbook.user_methods as um
    finder = doctest.DocTestFinder()
    for obj in (um.MethodInput, um.UserMethod):
        (test,) = [t for t in finder.find(obj, obj.__name__, module=um) if t.name == obj.__name__]
        assert test.examples, obj.__name__
        result = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS).run(test)
        assert result.failed == 0 and result.attempted == len(test.examples), obj.__name__
