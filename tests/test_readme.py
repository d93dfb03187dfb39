"""The README's Python examples run as written (each in a file: Taichi reads kernel source)."""
import os
import re
import subprocess
import sys

import pytest

from test_cli import ENV, ROOT


def python_blocks():
    text = open(os.path.join(ROOT, "README.md"), encoding="utf-8").read()
    return re.findall(r"```python\n(.*?)```", text, re.S)


def test_readme_has_python_examples():
    assert len(python_blocks()) >= 2


@pytest.mark.slow
@pytest.mark.parametrize("k", range(len(python_blocks())))
def test_readme_python_example_runs(k, tmp_path):
    # one test per block: pytest-xdist spreads them over its workers. Slow (CI runs them, as it
    # runs every documented command in test_commands.py): each block is a fresh process that
    # compiles its scene's kernels, ~1 min of the default run's 5 (the first, crates, 40 s cold)
    code = python_blocks()[k]
    script = tmp_path / f"readme_{k}.py"
    script.write_text(code)
    r = subprocess.run([sys.executable, str(script)], cwd=ROOT, env=ENV, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, f"README block {k} failed:\n{code}\n{r.stderr[-2000:]}"
    assert r.stdout.strip(), f"README block {k} printed nothing"
