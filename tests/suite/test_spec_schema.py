# ruff: noqa: E501  (each expected message is quoted whole, one line as the user reads it)
"""notebooks/experiments.toml's schema (locbook.suite.spec_schema): every broken file is refused with one line
naming the file, the table or experiment, the key and the value.

TODAY holds the messages of the hand-written checks the schema replaced, copied from their output (the same file,
the same line); TYPES the files those checks let through or answered with a raw TypeError / AttributeError (the
comment says which): a wrong type anywhere is a one-line refusal too."""
import pytest

from locbook.errors import ParameterError
from locbook.suite import SuiteError, load_suite
from locbook.suite.params import ParameterRule

DOC = '[documents.george]\ntitle = "G"\nauthors = "A"\nyear = "2015"\nsource = "s"\n'
EXP = 'id = "george-one"\ndocument = "george"\ntitle = "t"\nsection = "s"\nnotebook = "toy.ipynb"\n'
PROF = '[experiment.profiles.quick]\n[experiment.profiles.full]\n'


def exp(extra="", head=EXP, prof=PROF):
    """One [[experiment]]: its keys (``head``), ``extra`` keys, its profiles."""
    return "[[experiment]]\n" + head + extra + "\n" + prof


def _suite(tmp_path, text):
    folder = tmp_path / "notebooks"
    folder.mkdir()
    (folder / "toy.ipynb").write_text("{}")      # the list only checks that a notebook exists
    (folder / "experiments.toml").write_text(text)
    return folder / "experiments.toml"


TODAY = [
    pytest.param(DOC.replace("george", "georgy") + exp(),
                 "<FILE>: unknown document key 'georgy'; expected one of ('dogan2015', 'gudipati2017', 'palvai2008', 'george', 'ozkaya2011', 'measured', 'benchmark')", id='doc-unknown-key'),
    pytest.param(DOC.replace('source = "s"\n', '') + exp(),
                 "<FILE>: document 'george' lacks ['source']", id='doc-missing-field'),
    pytest.param(DOC.replace('source = "s"\n', '').replace('title = "G"\n', '') + exp(),
                 "<FILE>: document 'george' lacks ['source', 'title']", id='doc-missing-two'),
    pytest.param(DOC + 'pages = 3\n' + exp(),
                 "<FILE>: document 'george' has unknown fields ['pages']; expected ['authors', 'source', 'title', 'year']", id='doc-unknown-field'),
    pytest.param(DOC.replace('source = "s"\n', 'pages = 3\n') + exp(),
                 "<FILE>: document 'george' lacks ['source']", id='doc-missing-and-unknown'),
    pytest.param(DOC + exp(head=EXP.replace('id = "george-one"\n', '')),
                 "<FILE>: experiment '?' lacks ['id']", id='exp-missing-id'),
    pytest.param(DOC + exp(head=EXP.replace('title = "t"\n', '').replace('section = "s"\n', '')),
                 "<FILE>: experiment 'george-one' lacks ['section', 'title']", id='exp-missing-two'),
    pytest.param(DOC + exp(prof=""),
                 "<FILE>: experiment 'george-one' lacks ['profiles']", id='exp-missing-profiles'),
    pytest.param(DOC + exp(head=EXP.replace("george-one", "George_One")),
                 "<FILE>: experiment id 'George_One' must be lower-case letters, digits and hyphens ([a-z0-9-], e.g. 'george-tracking'); it names a folder under reports/", id='exp-bad-id'),
    pytest.param(DOC + exp(head=EXP.replace('"george-one"', '3')),
                 "<FILE>: experiment id 3 must be lower-case letters, digits and hyphens ([a-z0-9-], e.g. 'george-tracking'); it names a folder under reports/", id='exp-int-id'),
    pytest.param(DOC + exp(head=EXP.replace('document = "george"', 'document = "ozkaya2011"')),
                 "<FILE>: experiment 'george-one' names undeclared document 'ozkaya2011'", id='exp-undeclared-doc'),
    pytest.param(DOC + exp(head=EXP.replace("george-one", "geo-one")),
                 "<FILE>: experiment id 'geo-one' must start with its document key 'george-'", id='exp-wrong-prefix'),
    pytest.param(DOC + exp() + exp(),
                 "<FILE>: duplicate experiment id 'george-one'", id='exp-duplicate'),
    pytest.param(DOC + exp(prof='[experiment.profiles.quick]\n'),
                 "<FILE>: experiment 'george-one' must define exactly the profiles ('quick', 'full')", id='exp-profiles-missing-full'),
    pytest.param(DOC + exp(prof=PROF + '[experiment.profiles.slow]\n'),
                 "<FILE>: experiment 'george-one' must define exactly the profiles ('quick', 'full')", id='exp-profiles-extra'),
    pytest.param(DOC + exp('profiles = "quickfull"\n', prof=""),
                 "<FILE>: experiment 'george-one' must define exactly the profiles ('quick', 'full')", id='exp-profiles-string'),
    pytest.param(DOC + exp(head=EXP.replace("toy.ipynb", "nope.ipynb")),
                 "<FILE>: experiment 'george-one': notebook nope.ipynb does not exist", id='exp-missing-notebook'),
    pytest.param('parameter_rules = 3\n' + DOC + exp(),
                 '<FILE>: [parameter_rules] must be a table of rules by parameter name', id='rules-not-table'),
    pytest.param('parameter_rules = [1]\n' + DOC + exp(),
                 '<FILE>: [parameter_rules] must be a table of rules by parameter name', id='rules-list'),
    pytest.param(DOC + '[parameter_rules]\nn = 3\n' + exp(),
                 "<FILE>: [parameter_rules]: the rule for 'n' must be a table such as { ge = 0 }, got 3", id='rule-not-table'),
    pytest.param(DOC + '[parameter_rules]\nn = { minimum = 1, ge = 0 }\n' + exp(),
                 "<FILE>: [parameter_rules]: the rule for 'n' has unknown key(s) ['minimum']; allowed: ge, gt, le, lt, allow_inf, min_items, max_items", id='rule-unknown-key'),
    pytest.param(DOC + '[parameter_rules]\nn = { zz = 1, aa = 0 }\n' + exp(),
                 "<FILE>: [parameter_rules]: the rule for 'n' has unknown key(s) ['aa', 'zz']; allowed: ge, gt, le, lt, allow_inf, min_items, max_items", id='rule-unknown-keys'),
    pytest.param(DOC + '[parameter_rules]\nn = { ge = "1" }\n' + exp(),
                 "<FILE>: [parameter_rules]: the rule for 'n' needs ge to be a number, got '1'", id='rule-bad-ge'),
    pytest.param(DOC + '[parameter_rules]\nn = { ge = true }\n' + exp(),
                 "<FILE>: [parameter_rules]: the rule for 'n' needs ge to be a number, got True", id='rule-bool-ge'),
    pytest.param(DOC + '[parameter_rules]\nn = { allow_inf = 1 }\n' + exp(),
                 "<FILE>: [parameter_rules]: the rule for 'n' needs allow_inf to be true or false, got 1", id='rule-bad-allow-inf'),
    pytest.param(DOC + '[parameter_rules]\nn = { min_items = 1.5 }\n' + exp(),
                 "<FILE>: [parameter_rules]: the rule for 'n' needs min_items to be a whole number, got 1.5", id='rule-bad-min-items'),
    pytest.param(DOC + '[parameter_rules]\nn = { max_items = 1.5, ge = "x" }\n' + exp(),
                 "<FILE>: [parameter_rules]: the rule for 'n' needs max_items to be a whole number, got 1.5", id='rule-two-bad-raw-order'),
    pytest.param(DOC + '[parameter_rules]\nm = { ge = 0 }\nn = { ge = "x" }\n' + exp(),
                 "<FILE>: [parameter_rules]: the rule for 'n' needs ge to be a number, got 'x'", id='rule-second-bad'),
    pytest.param(DOC + exp('parameter_rules = 3\n'),
                 "<FILE>: experiment 'george-one' must be a table of rules by parameter name", id='exp-rules-not-table'),
    pytest.param(DOC + exp('parameter_rules = { n = { lt = "x" } }\n'),
                 "<FILE>: experiment 'george-one': the rule for 'n' needs lt to be a number, got 'x'", id='exp-rule-bad'),
    pytest.param(DOC + exp('parameter_rules = { n = { big = 1 } }\n'),
                 "<FILE>: experiment 'george-one': the rule for 'n' has unknown key(s) ['big']; allowed: ge, gt, le, lt, allow_inf, min_items, max_items", id='exp-rule-unknown'),
    pytest.param(DOC + exp('bracket = 3\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] takes a table 'parameters', a string 'reason', a list 'factorial' of interpretation names, and 'largest_error_m' (a positive number) with 'largest_error_reason'", id='bracket-not-table'),
    pytest.param(DOC + exp('bracket = { colour = 1 }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] takes a table 'parameters', a string 'reason', a list 'factorial' of interpretation names, and 'largest_error_m' (a positive number) with 'largest_error_reason'", id='bracket-unknown-key'),
    pytest.param(DOC + exp('bracket = { parameters = 3, reason = "r" }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] takes a table 'parameters', a string 'reason', a list 'factorial' of interpretation names, and 'largest_error_m' (a positive number) with 'largest_error_reason'", id='bracket-params-not-table'),
    pytest.param(DOC + exp('bracket = { factorial = ["a"] }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] factorial must list two or more distinct interpretation names, got ['a']", id='bracket-factorial-one'),
    pytest.param(DOC + exp('bracket = { factorial = ["a", "a"] }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] factorial must list two or more distinct interpretation names, got ['a', 'a']", id='bracket-factorial-dup'),
    pytest.param(DOC + exp('bracket = { factorial = "ab" }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] factorial must list two or more distinct interpretation names, got 'ab'", id='bracket-factorial-string'),
    pytest.param(DOC + exp('bracket = { factorial = ["a", ""] }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] factorial must list two or more distinct interpretation names, got ['a', '']", id='bracket-factorial-empty-name'),
    pytest.param(DOC + exp('bracket = { factorial = [1, 2] }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] factorial must list two or more distinct interpretation names, got [1, 2]", id='bracket-factorial-ints'),
    pytest.param(DOC + exp('bracket = { largest_error_m = -1, largest_error_reason = "r" }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] largest_error_m must be a positive number of metres, got -1", id='bracket-largest-negative'),
    pytest.param(DOC + exp('bracket = { largest_error_m = "9", largest_error_reason = "r" }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] largest_error_m must be a positive number of metres, got '9'", id='bracket-largest-string'),
    pytest.param(DOC + exp('bracket = { largest_error_m = true, largest_error_reason = "r" }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] largest_error_m must be a positive number of metres, got True", id='bracket-largest-bool'),
    pytest.param(DOC + exp('bracket = { largest_error_m = inf, largest_error_reason = "r" }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] largest_error_m must be a positive number of metres, got inf", id='bracket-largest-inf'),
    pytest.param(DOC + exp('bracket = { largest_error_m = nan, largest_error_reason = "r" }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] largest_error_m must be a positive number of metres, got nan", id='bracket-largest-nan'),
    pytest.param(DOC + exp('bracket = { largest_error_m = 9.4 }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] largest_error_m and largest_error_reason go together (the reason says where the area is printed)", id='bracket-largest-no-reason'),
    pytest.param(DOC + exp('bracket = { largest_error_m = 9.4, largest_error_reason = "  " }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] largest_error_m and largest_error_reason go together (the reason says where the area is printed)", id='bracket-largest-blank-reason'),
    pytest.param(DOC + exp('bracket = { largest_error_reason = "r" }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] largest_error_m and largest_error_reason go together (the reason says where the area is printed)", id='bracket-reason-no-largest'),
    pytest.param(DOC + exp('bracket = { reason = 3 }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] reason must be a string", id='bracket-reason-int'),
    pytest.param(DOC + exp('bracket = { parameters = { a = 1 } }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] sets parameters without a 'reason'", id='bracket-params-no-reason'),
    pytest.param(DOC + exp('bracket = { parameters = { a = 1 }, reason = " " }\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] sets parameters without a 'reason'", id='bracket-params-blank-reason'),
    pytest.param(DOC + exp('data_run = 3\n'),
                 "<FILE>: experiment 'george-one': [experiment.data_run] must be a table with the keys needs, parameters", id='data-run-not-table'),
    pytest.param(DOC + exp('data_run = { needs = ["track"], wants = 1 }\n'),
                 "<FILE>: experiment 'george-one': [experiment.data_run] has unknown key 'wants'; expected needs, parameters", id='data-run-unknown'),
    pytest.param(DOC + exp('data_run = {}\n'),
                 "<FILE>: experiment 'george-one': [experiment.data_run] needs must list one or more distinct kinds of calibration, static, track, scored, got None", id='data-run-no-needs'),
    pytest.param(DOC + exp('data_run = { needs = [] }\n'),
                 "<FILE>: experiment 'george-one': [experiment.data_run] needs must list one or more distinct kinds of calibration, static, track, scored, got []", id='data-run-needs-empty'),
    pytest.param(DOC + exp('data_run = { needs = "track" }\n'),
                 "<FILE>: experiment 'george-one': [experiment.data_run] needs must list one or more distinct kinds of calibration, static, track, scored, got 'track'", id='data-run-needs-string'),
    pytest.param(DOC + exp('data_run = { needs = ["track", "track"] }\n'),
                 "<FILE>: experiment 'george-one': [experiment.data_run] needs must list one or more distinct kinds of calibration, static, track, scored, got ['track', 'track']", id='data-run-needs-dup'),
    pytest.param(DOC + exp('data_run = { needs = [1] }\n'),
                 "<FILE>: experiment 'george-one': [experiment.data_run] needs must list one or more distinct kinds of calibration, static, track, scored, got [1]", id='data-run-needs-int'),
    pytest.param(DOC + exp('data_run = { needs = ["track", "walking"] }\n'),
                 "<FILE>: experiment 'george-one': [experiment.data_run] needs: unknown kind 'walking'; expected one of calibration, static, track, scored", id='data-run-needs-unknown'),
    pytest.param(DOC + exp('data_run = { needs = ["track"], parameters = 3 }\n'),
                 "<FILE>: experiment 'george-one': [experiment.data_run] parameters must be a table of parameter values", id='data-run-params-not-table'),
    pytest.param(DOC + exp('data_run = { needs = ["track"], parameters = { data = "x" } }\n'),
                 "<FILE>: experiment 'george-one': [experiment.data_run] parameters cannot set 'data' (the run's data set sets it)", id='data-run-params-data'),
    pytest.param(DOC + exp(head=EXP.replace("george-one", "Bad"), prof=""),
                 "<FILE>: experiment 'Bad' lacks ['profiles']", id='order-id-and-profiles'),
    pytest.param(DOC + exp() + exp(head=EXP.replace('document = "george"', 'document = "x"')),
                 "<FILE>: experiment 'george-one' names undeclared document 'x'", id='order-dup-and-undeclared'),
    pytest.param(DOC + exp('bracket = 3\n', head=EXP.replace("toy.ipynb", "nope.ipynb")),
                 "<FILE>: experiment 'george-one': notebook nope.ipynb does not exist", id='order-notebook-and-bracket'),
    pytest.param(DOC + exp('bracket = 3\ndata_run = 3\n'),
                 "<FILE>: experiment 'george-one': [experiment.bracket] takes a table 'parameters', a string 'reason', a list 'factorial' of interpretation names, and 'largest_error_m' (a positive number) with 'largest_error_reason'", id='order-bracket-and-data-run'),
    pytest.param(DOC.replace('source = "s"\n', '') + '[parameter_rules]\nn = 3\n' + exp(),
                 "<FILE>: document 'george' lacks ['source']", id='order-doc-and-rules'),
    pytest.param(DOC + '[parameter_rules]\nn = 3\n' + exp(head=EXP.replace("george-one", "Bad")),
                 "<FILE>: [parameter_rules]: the rule for 'n' must be a table such as { ge = 0 }, got 3", id='order-rules-and-exp'),
    pytest.param(DOC + exp('bracket = 3\n') + exp(head=EXP.replace("george-one", "Bad")),
                 "<FILE>: experiment 'george-one': [experiment.bracket] takes a table 'parameters', a string 'reason', a list 'factorial' of interpretation names, and 'largest_error_m' (a positive number) with 'largest_error_reason'", id='order-exp1-and-exp2'),
    pytest.param(DOC + exp(head=EXP.replace('"george-one"', '"""george\none"""')),
                 "<FILE>: experiment id 'george\\none' must be lower-case letters, digits and hyphens ([a-z0-9-], e.g. 'george-tracking'); it names a folder under reports/", id='multiline-id'),
]
TYPES = [
    pytest.param('documents = { george = 3 }\n' + exp(),   # was: TypeError
                 "<FILE>: document 'george' must be a table of title, authors, year, source, got 3", id='doc-not-table'),
    pytest.param('documents = { george = "x" }\n' + exp(),   # was: "lacks" all four fields
                 "<FILE>: document 'george' must be a table of title, authors, year, source, got 'x'", id='doc-string'),
    pytest.param('documents = "x"\n' + exp(),   # was: AttributeError
                 "<FILE>: [documents.<key>] must be tables of title, authors, year, source, got 'x'", id='documents-string'),
    pytest.param(DOC.replace('title = "G"', 'title = 3') + exp(),   # was: accepted
                 "<FILE>: document 'george': title must be a string, got 3", id='doc-int-title'),
    pytest.param(DOC + exp('colour = "red"\n'),   # was: accepted
                 "<FILE>: experiment 'george-one' has unknown key(s) ['colour']; allowed: id, document, title, section, profiles, notebook, parameter_rules, bracket, data_run", id='exp-unknown-field'),
    pytest.param(DOC + exp(head=EXP.replace('document = "george"', 'document = ["george"]')),   # was: TypeError
                 "<FILE>: experiment 'george-one' names undeclared document ['george']", id='exp-list-doc'),
    pytest.param(DOC + exp('profiles = 3\n', prof=""),   # was: TypeError
                 "<FILE>: experiment 'george-one' must define exactly the profiles ('quick', 'full')", id='exp-profiles-int'),
    pytest.param(DOC + exp('profiles = { quick = 3, full = {} }\n', prof=""),   # was: TypeError
                 "<FILE>: experiment 'george-one': [experiment.profiles.quick] must be a table of parameter values, got 3", id='exp-profile-not-table'),
    pytest.param(DOC + exp(head=EXP.replace('"toy.ipynb"', '3')),   # was: TypeError
                 "<FILE>: experiment 'george-one': notebook must be a path relative to the experiment list, got 3", id='exp-int-notebook'),
    pytest.param(DOC + exp(head=EXP.replace('"toy.ipynb"', '["toy.ipynb"]')),   # was: TypeError
                 "<FILE>: experiment 'george-one': notebook must be a path relative to the experiment list, got ['toy.ipynb']", id='exp-list-notebook'),
    pytest.param(DOC + exp(head=EXP.replace('title = "t"', 'title = 3')),   # was: accepted
                 "<FILE>: experiment 'george-one': title must be a string, got 3", id='exp-int-title'),
    pytest.param(DOC + exp(head=EXP.replace('section = "s"', 'section = { a = 1 }')),   # was: accepted
                 "<FILE>: experiment 'george-one': section must be a string, got {'a': 1}", id='exp-table-section'),
    pytest.param(DOC + '[experiment]\n' + EXP,   # was: AttributeError
                 "<FILE>: experiments are [[experiment]] tables (an array of tables), got {'id': 'george-one', 'document': 'george', 'title': 't', 'section': 's', 'notebook': 'toy.ipynb'}", id='experiment-table'),
    pytest.param('experiment = "x"\n' + DOC,   # was: AttributeError
                 "<FILE>: experiments are [[experiment]] tables (an array of tables), got 'x'", id='experiment-string'),
    pytest.param('experiment = ["x"]\n' + DOC,   # was: AttributeError
                 "<FILE>: experiment 1 must be a table ([[experiment]]), got 'x'", id='experiment-item-string'),
    pytest.param(DOC + exp('bracket = { largest_error_m = 9.4, largest_error_reason = 3 }\n'),   # was: accepted
                 "<FILE>: experiment 'george-one': [experiment.bracket] largest_error_reason must be a string, got 3", id='bracket-largest-reason-int'),
    pytest.param(DOC + exp('bracket = { largest_error_m = 9.4, largest_error_reason = ["r"] }\n'),   # was: accepted
                 "<FILE>: experiment 'george-one': [experiment.bracket] largest_error_reason must be a string, got ['r']", id='bracket-largest-reason-list'),
]


@pytest.mark.parametrize("text, message", TODAY + TYPES)
def test_a_broken_experiment_list_is_one_line_naming_the_file_and_the_key(tmp_path, text, message):
    path = _suite(tmp_path, text)
    with pytest.raises(SuiteError) as info:
        load_suite(path)
    assert str(info.value) == message.replace("<FILE>", str(path))
    assert isinstance(info.value, ParameterError)     # as a broken rule was before (ParameterRule.from_toml)


def test_a_well_formed_list_keeps_its_values_as_written(tmp_path):
    text = ('[parameter_rules]\nn = { ge = 2, le = 7.5 }\nm = {}\n' + DOC.replace('"2015"', '2015')
            + exp('parameter_rules = { n = { ge = 3 } }\n'
                  'bracket = { parameters = { a = 1 }, reason = " why ", factorial = ["a", "b"], largest_error_m = 9, '
                  'largest_error_reason = " r " }\ndata_run = { needs = ["track", "static"], parameters = { n = 4 } }\n',
                  prof='[experiment.profiles.quick]\nn = 2\n[experiment.profiles.full]\nn = 5\n')
            + exp(head=EXP.replace("george-one", "george-two")))
    suite = load_suite(_suite(tmp_path, text))
    one, two = suite.experiments
    assert suite.documents["george"].year == "2015"
    assert one.rules["n"] == ParameterRule(ge=3) and type(one.rules["n"].ge) is int    # an int bound stays an int
    assert two.rules == {"n": ParameterRule(ge=2, le=7.5), "m": ParameterRule()}
    assert one.profiles == {"quick": {"n": 2}, "full": {"n": 5}} and two.profiles == {"quick": {}, "full": {}}
    assert (one.bracket_parameters, one.bracket_reason, one.bracket_factorial) == ({"a": 1}, "why", ("a", "b"))
    assert (one.largest_error_m, one.largest_error_reason) == (9.0, "r") and type(one.largest_error_m) is float
    assert one.data_run.needs == ("track", "static") and one.data_run.parameters == {"n": 4}
    assert two.data_run is None and two.bracket_parameters == {} and two.largest_error_m is None
    assert one.notebook == (tmp_path / "notebooks" / "toy.ipynb").resolve()


def test_the_schema_leaves_the_studies_and_other_top_level_keys_alone(tmp_path):
    # [[study]] is locbook.suite.study's to check; a broken one does not stop the experiment list
    text = 'colour = 1\n' + DOC + exp() + '[[study]]\nname = "Not A Name"\nbogus = 1\n'
    assert [e.id for e in load_suite(_suite(tmp_path, text)).experiments] == ["george-one"]


def test_the_first_broken_rule_is_reported_in_the_order_the_file_is_read(tmp_path):
    # a document before the rules before the experiments, and a later experiment after an earlier one
    text = ('[parameter_rules]\nn = 3\n' + DOC.replace('source = "s"\n', '')
            + exp('bracket = 3\n') + exp(head=EXP.replace("george-one", "Bad")))
    path = _suite(tmp_path, text)
    with pytest.raises(SuiteError, match=r"document 'george' lacks \['source'\]$"):
        load_suite(path)
    path.write_text(text.replace('authors = "A"', 'authors = "A"\nsource = "s"'))
    with pytest.raises(SuiteError, match=r"\[parameter_rules\]: the rule for 'n' must be a table"):
        load_suite(path)
    path.write_text(text.replace('authors = "A"', 'authors = "A"\nsource = "s"').replace("n = 3", "n = {}"))
    with pytest.raises(SuiteError, match=r"experiment 'george-one': \[experiment.bracket\] takes a table"):
        load_suite(path)


@pytest.mark.parametrize("raw, message", [
    ({"minimum": 1}, r"where: the rule for 'n' has unknown key\(s\) \['minimum'\]; allowed: ge, gt, le, lt, allow_inf, "
                     "min_items, max_items$"),
    ({"max_items": 1.5, "ge": "x"}, "where: the rule for 'n' needs max_items to be a whole number, got 1.5$"),
    ({"ge": "x", "max_items": 1.5}, "where: the rule for 'n' needs ge to be a number, got 'x'$"),
    ({"zz": 1, "ge": "x"}, r"where: the rule for 'n' has unknown key\(s\) \['zz'\]"),
    ([1], r"where: the rule for 'n' must be a table such as \{ ge = 0 \}, got \[1\]$"),
])
def test_a_rule_reports_its_table_then_unknown_keys_then_the_first_bad_value_as_written(raw, message):
    with pytest.raises(ParameterError, match="^" + message):
        ParameterRule.from_toml("n", raw, "where")
