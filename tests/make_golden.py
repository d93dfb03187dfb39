"""Regenerate tests/golden/*.png after an intended change to how effects look (look at them!)."""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

from PIL import Image  # noqa: E402

from engine import runtime  # noqa: E402
from test_effects import GOLDEN, GOLDEN_SHOTS, render_small  # noqa: E402

if __name__ == "__main__":
    runtime.init("cpu")
    os.makedirs(GOLDEN, exist_ok=True)
    for name, frames in sorted(GOLDEN_SHOTS.items()):
        path = os.path.join(GOLDEN, f"{name}.png")
        Image.fromarray(render_small(name, frames)).save(path)
        print(path)
