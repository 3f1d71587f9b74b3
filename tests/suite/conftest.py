"""The toy suite's fixtures (the helpers they use are in tests/toy_suite.py)."""
import pytest

from toy_suite import PARAMS, STUDY_BODY, STUDY_PARAMS, TOY_STUDY, _notebook, experiment_toml, suite_toml


@pytest.fixture
def toy(tmp_path):
    """A repository at tmp_path/repo with two toy notebooks, and tmp_path/shared/data beside it."""
    (tmp_path / "shared" / "data").mkdir(parents=True)
    (tmp_path / "shared" / "data" / "offset.csv").write_text("offset\n0.0\n")
    tmp_path = tmp_path / "repo"
    nbdir = tmp_path / "notebooks"
    nbdir.mkdir(parents=True)
    # a clone: notebooks/ beside a locbook package, so the suite knows its repository (git checks, default reports)
    (tmp_path / "locbook").mkdir()
    (tmp_path / "locbook" / "__init__.py").write_text("")
    params = PARAMS
    _notebook(nbdir / "one.ipynb", params)
    _notebook(nbdir / "two.ipynb", params)
    (nbdir / "experiments.toml").write_text("\n" + suite_toml(
        experiment_toml("george-one", "one.ipynb", title="one", section="Table 1", quick={"n": 5}, full={"n": 50}),
        experiment_toml("george-two", "two.ipynb", title="two", section="Table 2"),
        rules={"n": {"ge": 1}, "sleep_s": {"ge": 0}}))
    return tmp_path


@pytest.fixture
def stoy(toy):
    _notebook(toy / "notebooks" / "study.ipynb", STUDY_PARAMS, body=STUDY_BODY)
    with open(toy / "notebooks" / "experiments.toml", "a") as fh:
        fh.write(TOY_STUDY)
    return toy
