"""Scene configs: strict schema (``schema``) and loading with one-line errors (``load``)."""
from .load import ConfigError, config_data, load_config, read_toml, validate
from .schema import INTEGRATORS, Emitter, Scene

__all__ = ["ConfigError", "config_data", "load_config", "read_toml", "validate", "Scene", "Emitter", "INTEGRATORS"]
