"""A walk over a course: a measured ground profile in, footholds and both legs' joint trajectories
out, timed for the device (NumPy only). The method (footholds, swings, timing): docs/walking.md.

The package's rooms: ``ground`` (the terrain's obstacles, the numbers a walk is bound by,
CourseError), ``search`` (the shortest path over footholds), ``placement`` (``footholds``),
``record`` (``Course``, its steps and the walk's table) and ``plan`` (``plan_course``).
"""

from jaxexo.course.ground import CourseError, FootholdRules, flat_obstacle, obstacles_of
from jaxexo.course.placement import Footholds, footholds
from jaxexo.course.plan import plan_course
from jaxexo.course.record import WALK_COLUMNS, Course, CourseStep, TerrainUpdate
from jaxexo.storage.terrain_file import Terrain, read_terrain

__all__ = [
    "Course",
    "CourseError",
    "CourseStep",
    "Footholds",
    "FootholdRules",
    "Terrain",
    "TerrainUpdate",
    "WALK_COLUMNS",
    "footholds",
    "obstacles_of",
    "plan_course",
    "flat_obstacle",
    "read_terrain",
]
