"""Scene configs: strict schema (``schema``: the scene, with one module per kind: ``emitters``,
``colliders``, ``bodies``, ``rigid``) and loading with one-line errors (``load``)."""
from .load import ConfigError, config_data, load_config, read_toml, validate
from .emitters import Emitter
from .schema import INTEGRATORS, Scene

__all__ = ["ConfigError", "config_data", "load_config", "read_toml", "validate", "Scene", "Emitter", "INTEGRATORS"]
