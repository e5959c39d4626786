"""The MuJoCo model of a config's legs on one scene, with the lookups the replays need (sites,
geoms, actuators, joint columns). The one module that imports MuJoCo (the ``sim`` extra), on use;
the replays built on it are jaxexo.sim.replay and jaxexo.sim.driven (docs/safety.md, "Replayed in a
physics engine")."""

from __future__ import annotations

import numpy as np

from jaxexo.sim.mjcf import (
    ACTUATED,
    DISTMAX,
    FOOT_RADIUS,
    LEGS,
    QPOS_NAMES,
    STANCE_LEG,
    SWING_LEG,
    SimError,
    legs_mjcf,
    pose_qpos,
)


def require_mujoco():
    """The mujoco module, or SimError saying how to install it."""
    try:
        import mujoco
    except ImportError:
        raise SimError(
            'MuJoCo is not installed; install the sim extra: pip install -e ".[sim]" '
            '(or pip install "mujoco>=4.0")'
        ) from None
    return mujoco


class Legs:
    """The MuJoCo model of a config's legs on one scene (the obstacle and the stance heel's pivot)."""

    def __init__(self, config, scene):
        mujoco = self.mujoco = require_mujoco()
        self.config = config
        self.scene = scene
        k = config.kinematics
        self.thigh, self.shin, self.foot_length = (
            float(k.thigh),
            float(k.shin),
            float(k.foot_length),
        )
        self.xml = legs_mjcf(config, scene.outline, scene.pivot_y)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        gid = lambda n: mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_GEOM, n)  # noqa: E731
        self.foot = gid(f"{SWING_LEG}_foot")
        self.pieces = [
            gid(f"obstacle_{i}") for i in range(int(self.model.numeric("obstacle_pieces").data[0]))
        ]
        adr = [
            int(self.model.jnt_qposadr[mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, n)])
            for n in QPOS_NAMES
        ]
        if adr != list(range(len(QPOS_NAMES))):  # pose_qpos writes the columns in this order
            raise RuntimeError(f"the model's qpos layout {adr} is not QPOS_NAMES")
        self.site = {
            n: mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, n)
            for n in (f"{leg}_{p}" for leg in LEGS for p in ("heel", "toe"))
        }
        self.stance_eq = mujoco.mj_name2id(
            self.model, mujoco.mjtObj.mjOBJ_EQUALITY, f"{STANCE_LEG}_on_pivot"
        )
        self.actuators = [
            mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in ACTUATED
        ]
        self.actuated_dofs = self.dofs(ACTUATED)  # the actuated joints' columns of qvel

    def dofs(self, names) -> list[int]:
        """The qvel columns of the named joints, in ``names``' order."""
        mujoco, m = self.mujoco, self.model
        return [
            int(m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)]) for n in names
        ]

    @property
    def rollout(self):
        """mujoco.rollout, imported on first use (only the driven replay needs it)."""
        from mujoco import rollout

        return rollout

    def qpos(self, angles) -> np.ndarray:
        """qpos (..., nq) of joint angles (..., 4) in JOINT_NAMES order (jaxexo.sim.mjcf.pose_qpos)."""
        return pose_qpos(angles, self.scene.pivot_y, self.thigh, self.shin)

    def foot_distance(self, distmax: float = DISTMAX) -> float:
        """MuJoCo's smallest distance (m) between the swing foot's heel-toe segment and the obstacle
        at the data's current pose (negative: penetration); ``distmax`` when farther (or no obstacle)."""
        d = distmax
        for g in self.pieces:
            d = min(
                d,
                self.mujoco.mj_geomDistance(self.model, self.data, self.foot, g, distmax, None)
                + FOOT_RADIUS,
            )
        return d

    def set_pose(self, qpos) -> None:
        self.data.qpos[:] = qpos
        self.mujoco.mj_kinematics(self.model, self.data)

    def site_yz(self, name: str) -> np.ndarray:
        """A site's (y, z) in jaxexo's frame (MuJoCo's x, z)."""
        p = self.data.site_xpos[self.site[name]]
        return np.array([p[0], p[2]])
