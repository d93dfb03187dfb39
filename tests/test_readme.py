"""The README's Python examples run as written (each in a file: Taichi reads kernel source)."""
import os
import re
import subprocess
import sys

from test_cli import ENV, ROOT


def python_blocks():
    text = open(os.path.join(ROOT, "README.md"), encoding="utf-8").read()
    return re.findall(r"```python\n(.*?)```", text, re.S)


def test_readme_python_examples_run(tmp_path):
    blocks = python_blocks()
    assert len(blocks) >= 2
    for k, code in enumerate(blocks):
        script = tmp_path / f"readme_{k}.py"
        script.write_text(code)
        r = subprocess.run([sys.executable, str(script)], cwd=ROOT, env=ENV, capture_output=True,
                           text=True, timeout=300)
        assert r.returncode == 0, f"README block {k} failed:\n{code}\n{r.stderr[-2000:]}"
        assert r.stdout.strip(), f"README block {k} printed nothing"
