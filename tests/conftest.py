"""One Taichi session for the whole test run, on the CPU (f32 default, f64 fields available)."""
import os

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

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
