"""docs/functional.md's example runs as written (its asserts check what it says)."""

import re
from pathlib import Path

DOC = Path(__file__).resolve().parents[1] / "docs" / "functional.md"


def test_the_functional_docs_example_runs():
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)
    assert len(blocks) == 1
    exec(compile(blocks[0], str(DOC), "exec"), {})
