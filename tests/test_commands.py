"""Every command the README documents runs to exit 0 as a real process (slow; CI runs it).

Each command here is a real ``python -m engine`` process, so a crash is an exit code below zero
(``particles chart`` once died of a segmentation fault with nothing printed: its whole run is
tests/test_charts.py's shared fixture), and a failure must print exactly one error line. The commands run in
their quick or small forms (the same code paths, fewer points).
"""
import os
import shutil
import subprocess
import sys

import pytest

from runhelp import ENV, ROOT

pytestmark = pytest.mark.slow


def particles(*argv, timeout=2400):
    return subprocess.run([sys.executable, "-m", "engine", *map(str, argv)], cwd=ROOT, env=ENV,
                          capture_output=True, text=True, timeout=timeout)


def ok(r):
    assert r.returncode == 0, f"exit {r.returncode}: {r.stderr[-2000:]}"
    return r


def test_list_validate_schema_ode(tmp_path):
    assert "sparks.toml" in ok(particles("list")).stdout
    cfgs = sorted(os.path.join("configs", f) for f in os.listdir(os.path.join(ROOT, "configs"))
                  if f.endswith(".toml"))
    ok(particles("validate", *cfgs))
    assert '"title"' in ok(particles("schema")).stdout
    ok(particles("ode", "decay", "--method", "rk4", "--h", "0.1"))


def test_run_profile_gallery(tmp_path):
    ok(particles("run", "configs/hair.toml", "--size", "96x54", "--out", tmp_path / "hair", "--quiet"))
    assert len([f for f in os.listdir(tmp_path / "hair") if f.endswith(".png")]) == 120
    assert "ms" in ok(particles("profile", "configs/sparks.toml", "--frames", "3", "--size", "64x36")).stdout
    some = tmp_path / "some"  # the gallery's whole path on two of its configs (all 18 take minutes)
    some.mkdir()
    for name in ("sparks", "crates"):
        shutil.copy(os.path.join(ROOT, "configs", f"{name}.toml"), some)
    ok(particles("gallery", "--out", tmp_path / "gallery", "--configs", some, "--quiet"))
    assert sorted(f for f in os.listdir(tmp_path / "gallery") if f.endswith(".png")) == ["crates.png", "sparks.png"]


def test_bench_quick(tmp_path):
    ok(particles("bench", "--quick", "--quiet", "--only", "step,ode"))
