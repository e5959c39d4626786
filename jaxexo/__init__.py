"""jaxexo: swing-foot trajectories for lower-limb exoskeletons over low obstacles, by TD(lambda).

Importing ``jaxexo`` needs only NumPy. The JAX parts (``jaxexo.env``, the trainer) are
imported on demand and need the ``train`` extra."""

__version__ = "0.1.0"

from jaxexo.config import Config, ConfigError, load_config  # noqa: E402
from jaxexo.physics.geometry import GeometryError, Obstacle  # noqa: E402

__all__ = ["Config", "ConfigError", "load_config", "Obstacle", "GeometryError", "__version__"]
