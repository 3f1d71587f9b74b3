"""The Examples sections of the data entry points run as written (doctest): their printed values are the data's."""
import doctest

import pytest

from locbook.data.dataset import load_dataset
from locbook.data.measured import read_readings


@pytest.mark.parametrize("function", [load_dataset, read_readings])
def test_the_examples_of_the_entry_points_run_and_print_what_they_show(function):
    tests = doctest.DocTestFinder().find(function, function.__name__, globs={})
    assert tests and sum(len(t.examples) for t in tests) >= 3, "no Examples section"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    for test in tests:
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0 and result.attempted >= 3, result


def test_the_manifest_schema_holds_exactly_the_keys_its_documentation_lists():
    """The module docstring of locbook.data.manifest lists every key of dataset.toml, table by table; the pydantic
    models are the schema the loader checks: the two name the same keys."""
    import re

    from locbook.data import manifest as mf
    documented, table = {}, ""
    for line in mf.__doc__.splitlines():
        header = re.match(r"^    \[{1,2}(\w+)\]{1,2}", line)
        key = re.match(r"^    (\w+) = ", line)
        if header:
            table = header.group(1)
        elif key:
            documented.setdefault(table, set()).add(key.group(1))
    models = {"": mf.Manifest, "units": mf.Units, "readings": mf.ReadingsOptions, "geometry": mf.Geometry,
              "epochs": mf.EpochsSection, "run": mf.Run, "recording": mf.RecordingEntry, "method": mf.MethodEntry}
    schema = {table: set(model.model_fields) - (set(models) if table == "" else set())
              for table, model in models.items()}
    assert documented == schema
