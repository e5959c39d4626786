"""Configuration layer: the declared, validated schema (``schema``), its TOML writer (``toml_io``) and
the memory estimate that refuses runs the machine cannot hold (``memory``) and the parameter views
of a config (``views``).

Everything here is NumPy-only. Importers use ``jaxexo.config`` as the public face of these modules."""

from jaxexo.config.schema import (  # noqa: F401
    COLLISION_MODES, CONTROLS, ENV_SECTIONS, HYPER_FIELDS, INT32_MAX, OBS_MODES, OBS_PROFILES,
    SECTION_CLASSES, SECTIONS, TARGETS, TRACE_KINDS, TRACE_VIEWS, Config, ConfigError,
    EnvConfig, FieldSpec, KinematicsConfig, LayoutConfig, ObstacleSpec, RewardConfig, TrainConfig,
    DeviceConfig, config_from_dict, declared_fields, default_obstacles, load_config, named_spec, num_updates,
    packaged_config, static_settings, validate, with_population,
)
from jaxexo.config.views import numpy_params, param_values, scalar_params, test_config  # noqa: F401
