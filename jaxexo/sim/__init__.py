"""The legs in a physics engine (MuJoCo): the MJCF model of a config's legs and obstacle
(``jaxexo.sim.mjcf``, plain text, no MuJoCo needed), and a timed swing replayed in MuJoCo,
kinematically and driven at the device's limits (``jaxexo.sim.replay``, needs the ``sim`` extra:
``pip install -e ".[sim]"``; MuJoCo itself is imported by ``jaxexo.sim.legs`` alone). Neither
``import jaxexo`` nor ``jaxexo.inference`` imports this package, and this module imports no MuJoCo."""

from jaxexo.sim.mjcf import SimError, legs_mjcf, scene_mjcf

__all__ = ["SimError", "legs_mjcf", "scene_mjcf"]
