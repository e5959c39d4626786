"""Configuration layer: the typed, validated schema (``schema``) and its TOML writer (``toml_io``).

Everything here is NumPy-only. Importers use ``jaxexo.config`` as the public face of both modules."""

from jaxexo.config.schema import (  # noqa: F401
    COLLISION_MODES, CONTROLS, HYPER_FIELDS, OBS_MODES, OBS_PROFILES, PIVOT_CONDITIONS, TARGETS,
    TRACE_KINDS, TRACE_VIEWS, Config, ConfigError, EnvConfig, KinematicsConfig, LayoutConfig,
    ObstacleSpec, RewardConfig, TrainConfig, DeviceConfig, config_from_dict, default_obstacles, load_config,
    named_spec, num_updates, static_settings, validate,
)
