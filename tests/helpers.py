"""Small builders shared by tests: minimal valid scene dicts, and a probe run on 1 and 2 threads."""
import copy
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

BASE = {
    "seed": 1,
    "fps": 30,
    "frames": 10,
    "solver": {"integrator": "symplectic_euler", "h": 1 / 120},
    "forces": {"gravity": [0.0, 0.0, 0.0]},
    "render": {"width": 64, "height": 36},
    "emitters": [{"rate": 100.0, "lifetime": 100.0, "speed": [1.0, 1.0]}],
}


def scene_dict(**changes):
    d = copy.deepcopy(BASE)
    for key, value in changes.items():
        node = d
        parts = key.split("__")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    return d


def quick(values, keep):
    """Parametrize values where only those in ``keep`` run by default and the rest under
    ``-m slow`` (CI runs both): the default suite stays within its time budget while every case
    still runs in CI."""
    import pytest

    return [v if v in keep else pytest.param(v, marks=pytest.mark.slow) for v in values]


def on_thread_counts(source: str, *args, counts=(1, 2), timeout: float = 600):
    """Run the Python ``source`` in a fresh process once per CPU thread count (``sys.argv[1]``,
    then ``args``), in the checkout with it on the path; returns each run's stdout split into
    words. A run that fails fails the test with its stderr's tail (a fresh process per count:
    Taichi's thread count is fixed at ``ti.init``). The source runs from a file, not ``-c``:
    Taichi reads a ``ti.func``'s source from its file."""
    env = dict(os.environ, TI_SKIP_VERSION_CHECK="ON", PYTHONPATH=ROOT)
    out = []
    with tempfile.TemporaryDirectory() as d:
        script = os.path.join(d, "probe.py")
        with open(script, "w") as fh:
            fh.write(source)
        for n in counts:
            r = subprocess.run([sys.executable, script, str(n), *map(str, args)], cwd=ROOT, env=env,
                               capture_output=True, text=True, timeout=timeout)
            assert r.returncode == 0, r.stderr[-2000:]
            out.append(r.stdout.split())
    return out


def one_line(e):
    """The text of a caught exception (``pytest.raises``' info), asserted to be one short line."""
    text = str(e.value)
    assert "\n" not in text and len(text) < 400, text
    return text


def sim_scene(cfg):
    """A scene from a config (dict or path) that only steps: no renderer."""
    from engine.config.load import load_config
    from engine.scene import Scene

    return Scene(load_config(cfg), render=False)


def drawn_scene(path: str, frames: int = 20, size=(160, 90), **render):
    """A shipped config's scene (``path`` relative to the checkout) with its renderer at ``size``
    and these ``render.*`` overrides, advanced ``frames`` frames."""
    from engine.config.load import load_config
    from engine.scene import Scene

    s = Scene(load_config(os.path.join(ROOT, path), {f"render.{k}": v for k, v in render.items()}),
              width=size[0], height=size[1])
    run_frames(s, frames)
    return s


def run_frames(scene, frames: int) -> None:
    for _ in range(frames):
        scene.advance_frame()


def other_schedule(scene, schedule: str):
    """A second renderer of ``scene`` (an ``engine.scene.Scene``), built as the scene builds its
    own (soft and rigid bodies both drawn), with this schedule ("tiles" or "pixels")."""
    from engine.render.renderer import Renderer

    p = scene.particles
    meshes = scene.bodies + ([scene.rigid] if scene.rigid is not None else [])
    return Renderer(p.state if p else None, scene.cfg.emitters, scene.colliders, scene.cfg.render,
                    bodies=meshes, rows=p.emitters.count if p else 0, schedule=schedule)
