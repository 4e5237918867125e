"""The walkthroughs in module docstrings run as written (scikit-fem's habit): each module's examples, in one
namespace per module, under the suite's strict numerics."""

import doctest
import importlib

import pytest

MODULES = [
    "jaxbpm",
    "jaxbpm.physics.blocks",
    "jaxbpm.physics.bond",
    "jaxbpm.physics.bond2d",
    "jaxbpm.physics.contact",
    "jaxbpm.physics.params",
    "jaxbpm.physics.tangent",
]


@pytest.mark.parametrize("name", MODULES)
def test_module_examples_run(name):
    module = importlib.import_module(name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    tests = finder.find(module, name)
    for test in tests:
        runner.run(test)
    results = runner.summarize(verbose=False)
    assert results.attempted > 0, f"{name} has no examples to run"
    assert results.failed == 0, f"{results.failed} of {results.attempted} examples of {name} failed (see the output)"
