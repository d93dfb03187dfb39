"""The config schema exported as JSON Schema (``particles schema``): every shipped config validates
against it with the ``jsonschema`` library, it refuses what the loader refuses (an unknown key, a
wrong type, a value out of range), and the copy the checkout's ``.taplo.toml`` points editors at
is the one the code generates today."""
import glob
import json
import os
import subprocess
import sys

import pytest

from engine.config.export import json_schema, schema_text
from engine.config.load import ConfigError, read_toml, validate

jsonschema = pytest.importorskip("jsonschema")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIGS = sorted(glob.glob(os.path.join(ROOT, "configs", "*.toml")))


@pytest.fixture(scope="module")
def validator():
    s = json_schema()
    jsonschema.Draft202012Validator.check_schema(s)
    return jsonschema.Draft202012Validator(s)


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: os.path.basename(p))
def test_shipped_config_validates_against_the_exported_schema(validator, path):
    errors = [f"{'/'.join(map(str, e.path))}: {e.message}" for e in validator.iter_errors(read_toml(path))]
    assert errors == []


@pytest.mark.parametrize("change", [
    {"emitterz": []},                                  # unknown key
    {"fps": "thirty"},                                 # wrong type
    {"fps": 0},                                        # out of range
    {"solver": {"integrator": "leapfrog"}},            # not one of the names
    {"colliders": [{"type": "plane", "normal": [0, 1]}]},  # a vector of two
    {"bodies": [{"type": "cloth", "strands": 40}]},     # a key of another body type
    {"bodies": [{"type": "jelly", "resolution": [4, 4], "size": [1, 1, 1]}]},  # a lattice needs 3
])
def test_schema_refuses_what_the_loader_refuses(validator, change):
    data = dict(read_toml(os.path.join(ROOT, "configs", "sparks.toml")), **change)
    assert list(validator.iter_errors(data)), change
    with pytest.raises(ConfigError):
        validate(data)


def test_committed_schema_is_current():
    """The checkout's particles.schema.json (what .taplo.toml gives editors) is today's schema:
    regenerate with `particles schema --out particles.schema.json`."""
    with open(os.path.join(ROOT, "particles.schema.json"), encoding="utf-8") as fh:
        assert fh.read() == schema_text()


def test_schema_command_prints_the_schema():
    r = subprocess.run([sys.executable, "-m", "engine", "schema"], capture_output=True, text=True,
                       cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["title"] == json_schema()["title"]


@pytest.mark.parametrize("path", CONFIGS, ids=os.path.basename)
def test_a_validated_config_round_trips_through_its_data(path):
    # ParticleScene(validated_config) re-validates config_data(cfg): the keys given, not every
    # default (every default written out once made sand, water and galaxy refuse their own
    # interact table: friction "given" to a fluid)
    from engine.config import config_data, load_config

    cfg = load_config(path)
    assert load_config(config_data(cfg)) == cfg
