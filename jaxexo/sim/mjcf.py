"""The legs as a MuJoCo model (MJCF text), written from a jaxexo config; no MuJoCo needed to write it.

The thesis's planar exoskeleton in MuJoCo's frame (x forward = jaxexo's y, z up, hinge axes along -y
so that a positive angle flexes like jaxexo's): a pelvis on two slides, two legs with hip, knee and a
level-held ankle, the feet's capsules, the obstacle's convex prisms. The model: docs/safety.md,
"Replayed in a physics engine (MuJoCo)".
"""

from __future__ import annotations

import math

import numpy as np

from jaxexo.sim.pieces import convex_pieces

SWING_LEG, STANCE_LEG = "right", "left"
LEGS = (SWING_LEG, STANCE_LEG)
# qpos layout of the model (every joint one coordinate).
QPOS_NAMES = (
    "pelvis_y",
    "pelvis_z",
    "right_hip",
    "right_knee",
    "right_ankle",
    "left_hip",
    "left_knee",
    "left_ankle",
)
# The actuated joints, in jaxexo's JOINT_NAMES order (hip_swing, knee_swing, hip_stance, knee_stance).
ACTUATED = (f"{SWING_LEG}_hip", f"{SWING_LEG}_knee", f"{STANCE_LEG}_hip", f"{STANCE_LEG}_knee")
FOOT_RADIUS = 0.001  # m
BODY_MASS = 70.0  # kg
MASS_FRACTIONS = {"pelvis": 0.678, "thigh": 0.100, "shin": 0.0465, "foot": 0.0145}
OBSTACLE_DEPTH = 0.30  # m, the prisms' extent across the sagittal plane (either side)
SERVO_KP = 1.0e5  # N m / rad, position actuators' stiffness (critically damped): a stiff drive
TIMESTEP = 0.001  # s, the default physics step
DISTMAX = 1.0  # m: distance sensors report this beyond it (never near a margin)
EQ_SOLREF = (
    "0.002 1"  # the equalities' time constant (s) and damping: stiff (at least 2 physics steps)
)


class SimError(ValueError):
    """A model that cannot be built from these inputs; the message names the bad field."""


def _positive(name: str, v) -> float:
    if (
        isinstance(v, bool)
        or not isinstance(v, (int, float, np.integer, np.floating))
        or not math.isfinite(v)
        or v <= 0
    ):
        raise SimError(f"{name}: must be a finite number > 0, got {v!r}")
    return float(v)


def check_config(config) -> dict:
    """The config's legs and drives as plain numbers, or SimError naming the field that cannot build
    a leg: lengths and device limits finite and > 0, each joint range finite with low < high."""
    k, dev = config.kinematics, config.device
    out = {n: _positive(f"kinematics.{n}", getattr(k, n)) for n in ("thigh", "shin", "foot_length")}
    for n in ("hip_limits", "knee_limits"):
        lim = tuple(getattr(k, n))
        if (
            len(lim) != 2
            or not all(isinstance(x, (int, float)) and math.isfinite(x) for x in lim)
            or not lim[0] < lim[1]
        ):
            raise SimError(
                f"kinematics.{n}: a joint range needs finite (low, high) with low < high (rad), got {lim!r}"
            )
        out[n] = (float(lim[0]), float(lim[1]))
    for n in ("joint_velocity", "joint_acceleration"):
        v = tuple(getattr(dev, n))
        if len(v) != 2:
            raise SimError(f"device.{n}: expected (hip, knee), got {v!r}")
        out[n] = tuple(_positive(f"device.{n}", x) for x in v)
    return out


def forward_leg(hip, q_hip, q_knee, thigh: float, shin: float):
    """Knee and heel (..., 2) of a leg hanging from ``hip`` (..., 2) at hip angle q_hip and knee angle
    q_knee (radians, jaxexo's convention: angles from the downward vertical, flexion hip +, knee -)."""
    hip = np.asarray(hip, dtype=np.float64)
    knee = hip + thigh * np.stack([np.sin(q_hip), -np.cos(q_hip)], axis=-1)
    shank = q_hip + q_knee
    return knee, knee + shin * np.stack([np.sin(shank), -np.cos(shank)], axis=-1)


def pose_qpos(angles, pivot_y: float, thigh: float, shin: float) -> np.ndarray:
    """The model's qpos (..., 8), QPOS_NAMES order, of joint angles (..., 4) in jaxexo's JOINT_NAMES
    order (hip_swing, knee_swing, hip_stance, knee_stance): the pelvis where the stance leg's angles
    put it with the stance heel on the pivot (y = pivot_y, z = 0), both feet level."""
    a = np.asarray(angles, dtype=np.float64)
    _, stance_heel = forward_leg(np.zeros(2), a[..., 2], a[..., 3], thigh, shin)
    hip = np.array([pivot_y, 0.0]) - stance_heel
    cols = (
        hip[..., 0],
        hip[..., 1],
        a[..., 0],
        a[..., 1],
        -(a[..., 0] + a[..., 1]),
        a[..., 2],
        a[..., 3],
        -(a[..., 2] + a[..., 3]),
    )
    return np.stack(cols, axis=-1)


def _f(x) -> str:
    return repr(float(x))


def _v(*xs) -> str:
    return " ".join(_f(x) for x in xs)


def _leg(name: str, c: dict) -> list[str]:
    t, s, L = c["thigh"], c["shin"], c["foot_length"]
    m = {p: BODY_MASS * f for p, f in MASS_FRACTIONS.items()}
    return [
        f'      <body name="{name}_thigh">',
        f'        <joint name="{name}_hip" type="hinge" axis="0 -1 0" range="{_v(*c["hip_limits"])}"/>',
        f'        <geom name="{name}_thigh" type="capsule" fromto="{_v(0, 0, 0, 0, 0, -t)}" size="0.04" '
        f'mass="{_f(m["thigh"])}"/>',
        f'        <body name="{name}_shin" pos="{_v(0, 0, -t)}">',
        f'          <joint name="{name}_knee" type="hinge" axis="0 -1 0" range="{_v(*c["knee_limits"])}"/>',
        f'          <geom name="{name}_shin" type="capsule" fromto="{_v(0, 0, 0, 0, 0, -s)}" size="0.03" '
        f'mass="{_f(m["shin"])}"/>',
        f'          <body name="{name}_foot" pos="{_v(0, 0, -s)}">',
        f'            <joint name="{name}_ankle" type="hinge" axis="0 -1 0"/>',
        f'            <geom name="{name}_foot" type="capsule" fromto="{_v(0, 0, 0, L, 0, 0)}" size="{_f(FOOT_RADIUS)}" '
        f'mass="{_f(m["foot"])}" contype="1" conaffinity="0" rgba="0.2 0.4 0.8 1"/>',
        f'            <site name="{name}_heel" pos="0 0 0"/>',
        f'            <site name="{name}_toe" pos="{_v(L, 0, 0)}"/>',
        "          </body>",
        "        </body>",
        "      </body>",
    ]


def _obstacle(pieces) -> tuple[list[str], list[str]]:
    """The obstacle's convex pieces as mesh assets and as the geoms placing them."""
    assets, geoms = [], []
    for i, p in enumerate(pieces):
        # Vertices about the piece's centre, the centre as the geom's position: MuJoCo keeps mesh
        # vertices in single precision, so they stay small (rounding ~1e-9 m) and the offset double.
        centre = 0.5 * (p.min(axis=0) + p.max(axis=0))
        verts = [
            (y - centre[0], sgn * OBSTACLE_DEPTH, z - centre[1])
            for sgn in (-1.0, 1.0)
            for y, z in p
        ]
        assets.append(f'    <mesh name="obstacle_{i}" vertex="{" ".join(_v(*v) for v in verts)}"/>')
        geoms.append(
            f'    <geom name="obstacle_{i}" type="mesh" mesh="obstacle_{i}" '
            f'pos="{_v(centre[0], 0, centre[1])}" contype="0" conaffinity="1" rgba="0.8 0.3 0.2 1"/>'
        )
    return assets, geoms


def _start_qpos(start_qpos) -> np.ndarray | None:
    """The keyframe's qpos, checked (SimError), or None."""
    if start_qpos is None:
        return None
    q = np.asarray(start_qpos, dtype=np.float64)
    if q.shape != (len(QPOS_NAMES),) or not np.all(np.isfinite(q)):
        raise SimError(
            f"start_qpos: expected {len(QPOS_NAMES)} finite numbers ({', '.join(QPOS_NAMES)}), "
            f"got shape {q.shape}"
        )
    return q


def _head(c: dict, timestep: float, pieces: int, assets: list[str]) -> list[str]:
    """The model's settings: compiler, options, defaults, the custom numbers jaxexo reads back
    (segment lengths, device limits, obstacle pieces) and the assets."""
    vel, acc = c["joint_velocity"], c["joint_acceleration"]
    return [
        '<mujoco model="jaxexo-legs">',
        "  <!-- written by jaxexo (jaxexo.sim.mjcf); units m, rad, s, kg -->",
        '  <compiler angle="radian" autolimits="true"/>',
        f'  <option timestep="{_f(timestep)}" integrator="implicitfast" ccd_tolerance="1e-12" ccd_iterations="200"/>',
        "  <default>",
        '    <geom contype="0" conaffinity="0" rgba="0.7 0.7 0.7 1"/>',
        f'    <position kp="{_f(SERVO_KP)}" dampratio="1"/>',
        "  </default>",
        "  <custom>",
        f'    <numeric name="thigh" data="{_f(c["thigh"])}"/>',
        f'    <numeric name="shin" data="{_f(c["shin"])}"/>',
        f'    <numeric name="foot_length" data="{_f(c["foot_length"])}"/>',
        f'    <numeric name="device_joint_velocity" data="{_v(vel[0], vel[1], vel[0], vel[1])}"/>',
        f'    <numeric name="device_joint_acceleration" data="{_v(acc[0], acc[1], acc[0], acc[1])}"/>',
        f'    <numeric name="obstacle_pieces" data="{pieces}"/>',
        "  </custom>",
        "  <asset>",
        *assets,
        "  </asset>",
    ]


def _world(c: dict, obstacle_geoms: list[str], pivot_y: float) -> list[str]:
    """The ground, the obstacle, the pivot and the pelvis with both legs."""
    return [
        "  <worldbody>",
        f'    <geom name="ground" type="plane" pos="{_v(0, 0, -FOOT_RADIUS)}" size="0 0 0.05" contype="0" '
        'conaffinity="1" rgba="0.9 0.9 0.9 1"/>',
        *obstacle_geoms,
        f'    <site name="pivot" pos="{_v(pivot_y, 0, 0)}"/>',
        '    <light pos="0 -2 2" dir="0 1 -1"/>',
        '    <body name="pelvis">',
        '      <joint name="pelvis_y" type="slide" axis="1 0 0"/>',
        '      <joint name="pelvis_z" type="slide" axis="0 0 1"/>',
        f'      <geom name="pelvis" type="sphere" size="0.06" mass="{_f(BODY_MASS * MASS_FRACTIONS["pelvis"])}"/>',
        *_leg("right", c),
        *_leg("left", c),
        "    </body>",
        "  </worldbody>",
    ]


def _constraints() -> list[str]:
    """Each foot kept level (the tendon of its leg's joints held at its length) and each heel's connection
    to the pivot (off until a replay turns the stance leg's on)."""
    return [
        "  <tendon>",
        *[
            f'    <fixed name="{leg}_level"><joint joint="{leg}_hip" coef="1"/><joint joint="{leg}_knee" coef="1"/>'
            f'<joint joint="{leg}_ankle" coef="1"/></fixed>'
            for leg in LEGS
        ],
        "  </tendon>",
        "  <equality>",
        *[
            f'    <tendon name="{leg}_level" tendon1="{leg}_level" solref="{EQ_SOLREF}"/>'
            for leg in LEGS
        ],
        *[
            f'    <connect name="{leg}_on_pivot" site1="{leg}_heel" site2="pivot" active="false" solref="{EQ_SOLREF}"/>'
            for leg in LEGS
        ],
        "  </equality>",
    ]


def _sensors_and_actuators(c: dict, pieces: int) -> list[str]:
    """Heel and toe positions, the actuated joints' velocities and the swing foot's distance to each
    obstacle piece; a position actuator per actuated joint, within its limits."""
    return [
        "  <sensor>",
        *[
            f'    <framepos name="{leg}_{part}" objtype="site" objname="{leg}_{part}"/>'
            for leg in LEGS
            for part in ("heel", "toe")
        ],
        *[f'    <jointvel name="{j}" joint="{j}"/>' for j in ACTUATED],
        *[
            f'    <distance name="foot_obstacle_{i}" geom1="{SWING_LEG}_foot" geom2="obstacle_{i}" cutoff="{_f(DISTMAX)}"/>'
            for i in range(pieces)
        ],
        "  </sensor>",
        "  <actuator>",
        *[
            f'    <position name="{j}" joint="{j}" ctrlrange="{_v(*c["hip_limits" if j.endswith("hip") else "knee_limits"])}"/>'
            for j in ACTUATED
        ],
        "  </actuator>",
    ]


def legs_mjcf(
    config, outline=None, pivot_y: float = 0.0, start_qpos=None, timestep: float = TIMESTEP
) -> str:
    """MJCF text of the legs of ``config`` (a jaxexo Config), with the ground obstacle ``outline``
    ((K, 2) (y, z) vertices, metres, padded or not; None: no obstacle), the stance heel's place
    ``pivot_y`` and, when given, a keyframe ``start`` at ``start_qpos`` (QPOS_NAMES order). Every
    input is checked first (SimError, or GeometryError for the outline)."""
    c = check_config(config)
    pivot_y = float(pivot_y)
    if not math.isfinite(pivot_y):
        raise SimError(f"pivot_y: must be finite (m), got {pivot_y!r}")
    _positive("timestep", timestep)
    pieces = [] if outline is None else convex_pieces(outline)
    q = _start_qpos(start_qpos)
    assets, obstacle_geoms = _obstacle(pieces)
    lines = [
        *_head(c, timestep, len(pieces), assets),
        *_world(c, obstacle_geoms, pivot_y),
        *_constraints(),
        *_sensors_and_actuators(c, len(pieces)),
    ]
    if q is not None:
        lines += ["  <keyframe>", f'    <key name="start" qpos="{_v(*q)}"/>', "  </keyframe>"]
    lines.append("</mujoco>")
    return "\n".join(lines) + "\n"


def scene_mjcf(config, scene) -> str:
    """The MJCF of a config's legs on a scene (jaxexo.physics.scene.Scene): its obstacle, the
    stance heel on its pivot and a keyframe ``start`` with the swing heel at its start."""
    from jaxexo.config import scalar_params
    from jaxexo.swing.timing import leg_angles

    check_config(config)
    sp = scalar_params(config)
    angles = leg_angles(sp, scene.pivot_y, np.array([[scene.start_y, 0.0]]))[0]
    q = pose_qpos(angles, scene.pivot_y, sp.thigh, sp.shin)
    return legs_mjcf(config, scene.outline, scene.pivot_y, start_qpos=q)
