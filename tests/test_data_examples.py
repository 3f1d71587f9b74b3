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
