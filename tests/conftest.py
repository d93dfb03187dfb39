"""One Taichi session for the whole test run, on the CPU (f32 default, f64 fields available)."""
import os

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

import pytest  # noqa: E402

from engine import runtime  # noqa: E402


@pytest.fixture(scope="session", autouse=True)
def taichi_session():
    runtime.init("cpu")
    yield
