"""The names from before "reading" meant only a sensor measurement keep working for one release: the old module
paths warn once on import and give the same objects, old attribute and keyword names warn, the CLI takes the old
option, and an old notebook parameter is refused in one line naming the new one."""
import importlib
import sys

import pytest

from locbook.errors import ParameterError
from locbook.suite.params import RENAMED_PARAMETERS
from locbook.suite.spec import load_suite

# the module (locbook.reproduce.interpretations is also the function the package exports)
new = importlib.import_module("locbook.reproduce.interpretations")


@pytest.mark.parametrize("old, home", [("locbook.reproduce.readings", "locbook.reproduce.interpretations"),
                                       ("locbook.scenarios.ozkaya_readings",
                                        "locbook.scenarios.ozkaya_interpretations")])
def test_an_old_module_path_warns_and_gives_the_new_objects(old, home, monkeypatch):
    monkeypatch.delitem(sys.modules, old, raising=False)
    with pytest.warns(DeprecationWarning, match=f"{old} is deprecated: use {home}") as caught:
        module = importlib.import_module(old)
    assert caught[0].filename == __file__          # the warning points at the importing line, not the machinery
    if old.endswith("reproduce.readings"):
        assert (module.Reading, module.ReadingsError, module.readings, module.load_reading_file,
                module.READING_COLUMNS, module.READINGS_DIR) == (
            new.Interpretation, new.InterpretationsError, new.interpretations, new.load_interpretation_file,
            new.INTERPRETATION_COLUMNS, new.INTERPRETATIONS_DIR)
    else:
        assert module.sim_readings is importlib.import_module(home).sim_interpretations


def test_old_names_of_the_package_and_the_scenarios_warn_and_are_the_new_ones():
    import locbook.reproduce as rp
    from locbook.scenarios import dogan, ozkaya
    from locbook.suite import bracket
    from locbook.tracking import fusion
    for module, old, now in [(rp, "Reading", "Interpretation"), (rp, "readings_for", "interpretations_for"),
                             (dogan, "NOISE_READINGS", "NOISE_INTERPRETATIONS"),
                             (dogan, "readings_summary", "interpretations_summary"),
                             (ozkaya, "SIM_READINGS", "SIM_INTERPRETATIONS"),
                             (ozkaya, "settling_reading", "settling_interpretation"),
                             (bracket, "experiment_readings", "experiment_interpretations"),
                             (fusion, "FUSION_READINGS", "FUSION_INTERPRETATIONS")]:
        with pytest.warns(DeprecationWarning, match=f"{old} is deprecated: use .*{now}"):
            assert getattr(module, old) is getattr(module, now)
    with pytest.raises(AttributeError):
        dogan.NO_SUCH_READING


def test_an_old_keyword_warns_and_gives_the_same_result():
    from locbook.scenarios import dogan
    with pytest.warns(DeprecationWarning, match=r"calibrated_from_text\(noise_reading='sigma_acc'\) is deprecated"):
        old = dogan.calibrated_from_text("rest", noise_reading="sigma_acc")
    assert old == dogan.calibrated_from_text("rest", noise_interpretation="sigma_acc") != ""


def test_an_old_notebook_parameter_is_refused_naming_the_new_one():
    exp = next(e for e in load_suite().experiments if e.id == "dogan2015-tracking")
    assert set(RENAMED_PARAMETERS.values()) <= set(exp.declared_parameters())
    with pytest.raises(ParameterError, match=r"parameter 'noise_reading' was renamed 'noise_interpretation'") as err:
        exp.parameters("quick", {"noise_reading": "printed"})
    assert "\n" not in str(err.value) and "-p noise_interpretation=..." in str(err.value)
    assert exp.parameters("quick", {"noise_interpretation": "sigma_acc"})["noise_interpretation"] == "sigma_acc"


def test_the_bracket_takes_the_old_option_hidden_from_its_help(capsys, tmp_path):
    from locbook.suite.cli import main
    with pytest.raises(SystemExit):
        main(["bracket", "--help"])
    help_text = capsys.readouterr().out
    assert "--interpretations CSV" in help_text and "--readings" not in help_text
    # both spellings at once is refused in one line (exit status 2) before anything runs
    mine = tmp_path / "mine.csv"
    mine.write_text("x", encoding="utf-8")
    assert main(["bracket", "george-tracking", "--interpretations", str(mine), "--readings", str(mine)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "give --interpretations only" in err
