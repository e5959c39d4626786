"""Configuration layer: a TOML file becomes a validated, frozen ``Config``.

``checks`` parse single values, ``declarations`` declare each field once (its check, unit and role),
``sections`` hold the declared sections and the whole Config, ``obstacles`` the [layout] mixture and
terrain, ``loading`` reads files and tables, ``consistency`` refuses fields that cannot work together,
``views`` turns a Config into the environment's parameters, ``toml_io`` writes it back and
``memory`` refuses runs the machine cannot hold.

Everything here is NumPy-only. Importers use ``jaxexo.config`` as the public face of these modules."""

from jaxexo.config.checks import ConfigError  # noqa: F401
from jaxexo.config.consistency import validate  # noqa: F401
from jaxexo.config.declarations import FieldSpec, declared_fields  # noqa: F401
from jaxexo.config.loading import config_from_dict, load_config, packaged_config  # noqa: F401
from jaxexo.config.obstacles import ObstacleSpec, TerrainSpec, default_obstacles, named_spec  # noqa: F401
from jaxexo.config.sections import (  # noqa: F401
    COLLISION_MODES,
    CONTROLS,
    ENV_SECTIONS,
    EQUAL_WEIGHTS,
    HYPER_FIELDS,
    INT32_MAX,
    MAX_CONTROL_RATE,
    MAX_SEED,
    MAX_SWING_DURATION,
    MAX_TRACKING_HEADROOM,
    MIN_CONTROL_RATE,
    OBS_MODES,
    OBS_PROFILES,
    SECTION_CLASSES,
    SECTIONS,
    TARGETS,
    THESIS_JOINT_LIMITS,
    TRACE_KINDS,
    TRACE_VIEWS,
    Config,
    DeviceConfig,
    EnvConfig,
    KinematicsConfig,
    LayoutConfig,
    RewardConfig,
    TrainConfig,
    check_seed,
    num_updates,
    static_settings,
    to_toml_values,
    with_population,
)
from jaxexo.config.views import numpy_params, param_values, scalar_params, test_config  # noqa: F401
