"""The README's Python blocks run as written (each in a fresh namespace, in a temporary folder)."""

import os
import re

import matplotlib
import pytest

from conftest import REPO_ROOT

BLOCKS = re.findall(r"```python\n(.*?)```", (REPO_ROOT / "README.md").read_text(encoding="utf-8"), flags=re.S)


def test_readme_has_python_blocks():
    assert len(BLOCKS) >= 4


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_block_runs(index, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    matplotlib.use("Agg")
    code = compile(BLOCKS[index], f"README.md python block {index + 1}", "exec")
    namespace = {"__name__": "__readme__"}
    exec(code, namespace)  # noqa: S102 - the README's own examples; an exception fails the test
    import matplotlib.pyplot as plt

    plt.close("all")
    if "save" in BLOCKS[index]:  # what a block saves lands in the working folder
        assert os.listdir(tmp_path)
    assert len(namespace) > 1
