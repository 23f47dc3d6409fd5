"""The scripts in docs/examples/ run as the documentation shows them, and check themselves.

Each script ends in asserts on its own result (a Dice, a volume, an exact k_eff), so a
script that stops being right fails here; each runs in a fresh folder, as a reader would
run it, and writes only there.
"""

import runpy
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "docs" / "examples").glob("*.py"))


def test_every_example_is_on_the_examples_page():
    page = (EXAMPLES[0].parents[1] / "examples.md").read_text()
    assert len(EXAMPLES) >= 4
    for script in EXAMPLES:
        assert f"examples/{script.name}" in page, f"{script.name} is not on docs/examples.md"


@pytest.mark.parametrize("script", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_runs(script, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    runpy.run_path(str(script), run_name="__main__")
    assert Path.cwd() == tmp_path           # the script wrote (if at all) where it ran
    assert not any(p.name.startswith(".") for p in tmp_path.iterdir())   # no temporaries
