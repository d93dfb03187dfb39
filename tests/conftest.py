"""One Taichi session for the whole test run, on the CPU (f32 default, f64 fields available)."""
import os

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")
# Taichi's offline cache for this checkout only (this process, xdist workers and every `particles`
# subprocess a test starts inherit it). The shared ~/.cache/taichi/ticache of a machine where
# several checkouts run tests holds every variant of every kernel and its lock is contended:
# measured side by side at load 4.7 on 2 cores, the five divergence tests of test_cli.py took
# 53 s against it and 22 s with this one warm.
os.environ.setdefault("PARTICLES_TI_CACHE", os.path.join(
    os.path.dirname(os.path.dirname(os.path.abspath(__file__))), ".pytest_cache", "ticache"))

import pytest  # noqa: E402

from engine import runtime  # noqa: E402


@pytest.fixture(scope="session", autouse=True)
def taichi_session():
    runtime.init("cpu")
    yield


@pytest.fixture(scope="module", autouse=True)
def fresh_program_per_module():
    """A fresh Taichi program after each test module: the LLVM backend holds at most 512 SNode
    trees (and 2048 SNodes) per program, and a whole session of scenes would pass that (it
    segfaulted in CI). The offline cache keeps recompilation cheap."""
    yield
    runtime.reset()
    runtime.init("cpu")
