# The Python the documentation shows runs: every ```python block of README.md and of
# examples/python/README.md, from the top folder (where its paths lead).
import os
import re

import pytest

from conftest import SCENES

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(SCENES)))


def blocks(path):
    with open(os.path.join(ROOT, path)) as f:
        return re.findall(r"```python\n(.*?)```", f.read(), re.S)


@pytest.mark.parametrize("path", ["README.md", "examples/python/README.md"])
def test_python_blocks_run(path, monkeypatch, capsys):
    found = blocks(path)
    assert found, f"no python block in {path}"
    monkeypatch.chdir(ROOT)
    for code in found:
        exec(compile(code, path, "exec"), {})
