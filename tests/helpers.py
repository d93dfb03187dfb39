"""Small builders shared by tests: minimal valid scene dicts."""
import copy

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
