"""Examples double as tests: each one computes at module level."""

import runpy
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).parents[1] / "examples").glob("*.py"))


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_runs(path):
    pytest.importorskip("matplotlib")
    namespace = runpy.run_path(str(path), run_name="example")
    assert "summary" in namespace
