"""A walk over a course: a measured ground profile in, footholds and both legs' joint trajectories out,
timed for the device (NumPy only).

The course (jaxexo.storage.terrain_file.Terrain) is the ground's height along the walk; every
stretch where it rises above the floor is an obstacle. The walk starts with both feet together at
``start_y`` and ends with both feet together at the goal. Swings alternate legs, the left first:
swing k moves one foot from its last foothold over the terrain between to the next, with the other
foot standing as its pivot (``pivot_y``), as the thesis's single swing does.

1. Footholds (``footholds``), before any swing is planned. A foothold is a point of a 1 cm grid
   where the foot (heel and toe) stands on flat ground (z = 0) with ``STAND_MARGIN`` or the asked
   clearance + 5 mm to spare from any obstacle, widened by the goal tolerance (env.goal_tolerance:
   the swing may end that far from its goal, and the foot must stand clear wherever it lands).
   A swing from a to c with pivot b is allowed when its length c - a lies in the config's step
   range (the terrain layout's when it trains on terrain), a <= b <= c, every obstacle under it fits
   in the policy's profile (geometry.MAX_PROFILE_VERTICES) and the heel held the mid-goal box's
   bottom above each of its vertices is within reach and joint limits for every pivot within the
   goal tolerance of b (kinematics.swing_heel_unreachable, the rule jaxexo.config checks a config's
   obstacles by). Among the walks allowed, a shortest path on the states (trailing foot, leading
   foot) picks the one of least cost: one per swing plus the squared deviations, in half step
   ranges, of each swing's length from the nominal (the middle of the range) and of its pivot from
   the middle of the swing (a steady gait; the first and last swings start and end with the feet
   together). A course no walk crosses is refused (``CourseError``) with the position of what
   stops it: an obstacle no swing clears, one wider than the longest step, a gap with no flat
   foothold in reach.
2. Swings, in order (each starts where the last swing of its leg landed): the generator's swing
   (``generate`` with ``pivot_y``) over the obstacles between its start and goal as one
   ``Obstacle.profile``; on flat ground, over a low virtual obstacle (``FLAT_OBSTACLE``) so the
   foot lifts off. The RL generator falls back on CFFTG per step unless ``fallback=None``; the
   step's method says which planned it. Every safe swing ends with the foot on the floor: CFFTG's by
   construction, the RL swing's because its descent to the floor is part of the smoothed and checked
   path (jaxexo.swing.finish.landed). A swing that fails (short of the goal, maybe above the
   floor) stops the walk, as it fails a single swing.
3. Timing (jaxexo.swing.timing.time_swings): every swing rest-to-rest at the [device] limits, sampled at
   the control rate. At a landing both legs are straight with the hip between the heels (the hip
   model of jaxexo.physics.kinematics), so the landing pose of one swing is the lift-off pose of
   the next with the legs' roles swapped, and both are at rest: q, q-dot and q-double-dot are
   continuous (checked at every junction: ``Course.junction_jump``). A double-support dwell of
   ``double_support`` s can be held at each landing (default 0: none is needed).

Units: metres, radians, seconds.

The package's rooms: ``ground`` (the terrain's obstacles, the numbers a walk is bound by,
CourseError), ``search`` (the shortest-path search over footholds), ``placement`` (``footholds``:
1.), ``record`` (``Course``, its steps and the walk's table) and ``plan`` (``plan_course``: 2. and 3.).
"""

from jaxexo.course.ground import CourseError, FootholdRules, flat_obstacle, obstacles_of
from jaxexo.course.placement import Footholds, footholds
from jaxexo.course.plan import plan_course
from jaxexo.course.record import WALK_COLUMNS, Course, CourseStep
from jaxexo.storage.terrain_file import Terrain, read_terrain

__all__ = [
    "Course",
    "CourseError",
    "CourseStep",
    "Footholds",
    "FootholdRules",
    "Terrain",
    "WALK_COLUMNS",
    "footholds",
    "obstacles_of",
    "plan_course",
    "flat_obstacle",
    "read_terrain",
]
