"""Record what the simulation does (not how it looks) as fixtures for tests/test_behaviour.py.

    python tests/make_behaviour.py [NAME ...]   # rewrite tests/behaviour/*.npz (say why in the commit)

* ``frames_<config>.npz``: the live particles of a shipped config after a few frames (positions,
  velocities, ages, emitter ids in pool order) — the particle pipeline's result, independent of
  the renderer.
* ``cloth_fixed.npz``: node positions of configs/cloth.toml after 40 frames (XPBD) and of a small
  symplectic-Euler and RK4 cloth.
* ``h_particles.npz`` / ``h_cloth.npz``: every accepted step size of an adaptive particle scene
  (RK4 step doubling with collisions, drag and emission) and of an adaptive cloth, frame by frame,
  with the rejection counts and the final state.
"""
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.dirname(HERE))
os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

from behaviour_scenes import (FRAME_SHOTS, adaptive_cloth, adaptive_particles,  # noqa: E402
                              fixed_cloths, particle_frames)
from engine import runtime  # noqa: E402

OUT = os.path.join(HERE, "behaviour")


def fixtures():
    """{fixture name: function returning its arrays}."""
    out = {f"frames_{name}": (lambda name=name, n=n: particle_frames(name, n)) for name, n in FRAME_SHOTS.items()}
    out.update(cloth_fixed=fixed_cloths, h_particles=adaptive_particles, h_cloth=adaptive_cloth)
    return out


def main(names=()):
    runtime.init("cpu")
    os.makedirs(OUT, exist_ok=True)
    todo = fixtures()
    unknown = sorted(set(names) - set(todo))
    if unknown:
        raise SystemExit(f"unknown fixture(s) {', '.join(unknown)}; known: {', '.join(todo)}")
    for name in names or todo:
        path = os.path.join(OUT, f"{name}.npz")
        np.savez_compressed(path, **todo[name]())
        print(path, os.path.getsize(path), "bytes")


if __name__ == "__main__":
    main(sys.argv[1:])
