"""NumPy-only swing trajectory generation: an exported policy in, a checked trajectory out, e.g.
``TrajectoryGenerator.load("run/policy.npz").generate(Obstacle.named("triangle"), pivot="obstacle")``.
The public face of generation: the swing's records and, loaded on first use, device timing and
walks. Units: metres, radians, seconds. See docs/generation.md.
"""

from jaxexo.inference.generator import TrajectoryGenerator
from jaxexo.physics.geometry import Obstacle
from jaxexo.physics.scene import Scene
from jaxexo.storage.policy_file import PolicyFileError
from jaxexo.swing.export import CSV_COLUMNS, JOINT_NAMES
from jaxexo.swing.options import GenerateOptions, SwingOptions
from jaxexo.swing.trajectory import (
    Trajectory,
    TrajectoryBatch,
    TrajectoryChecks,
    TrajectoryError,
    assemble,
)

_LAZY = {
    "DeviceLimits": "jaxexo.swing.timing",
    "TimedSwing": "jaxexo.swing.timing",
    "time_swing": "jaxexo.swing.timing",
    "time_swings": "jaxexo.swing.timing",
    "plan_course": "jaxexo.course",
    "Course": "jaxexo.course",
    "CourseError": "jaxexo.course",
    "footholds": "jaxexo.course",
    "Terrain": "jaxexo.course",
    "read_terrain": "jaxexo.course",
    "TerrainUpdate": "jaxexo.course",
}


def __getattr__(name):
    # Device timing and walks are imported on first use: generating needs neither, and the import
    # time budget is 0.3 s.
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'jaxexo.inference' has no attribute {name!r}")


__all__ = [
    "TrajectoryGenerator",
    "GenerateOptions",
    "SwingOptions",
    "Trajectory",
    "TrajectoryBatch",
    "TrajectoryChecks",
    "TrajectoryError",
    "Obstacle",
    "Scene",
    "PolicyFileError",
    "assemble",
    "CSV_COLUMNS",
    "JOINT_NAMES",
    "DeviceLimits",
    "TimedSwing",
    "time_swing",
    "time_swings",
    "plan_course",
    "Course",
    "CourseError",
    "footholds",
    "Terrain",
    "read_terrain",
    "TerrainUpdate",
]
