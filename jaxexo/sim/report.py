"""One scene's swings replayed in MuJoCo and reported, as ``jaxexo replay`` prints and writes them:
the kinematic replay, and with ``driven`` the driven replays at the [device] limits (and at half of
them), per generator; the command line only parses, calls and prints. Method: docs/safety.md."""

from __future__ import annotations

import dataclasses

from jaxexo.sim.driven import DrivenReplay
from jaxexo.sim.replay import KinematicReplay, Legs, driven_replay, kinematic_replay

HALF_LIMITS = 0.5  # the --half-limits replay's share of the [device] velocity and acceleration


@dataclasses.dataclass(frozen=True)
class SwingReplay:
    """One generator's swing replayed: the generator's ``name`` (rl, cfftg), its TimedSwing, the
    kinematic replay and the driven replays by label ("driven", "driven_half_limits"), SI units."""

    name: str
    timed: object
    kinematic: KinematicReplay
    driven: dict[str, DrivenReplay]

    @property
    def ok(self) -> bool:
        """MuJoCo agrees with jaxexo's verdict: a swing flagged ok keeps the margin in the kinematic
        replay and, driven at the full limits, touches nothing."""
        full = self.driven.get("driven")
        return not self.kinematic.flagged_ok_but_within_margin and not (
            full is not None and self.timed.ok and full.figures.contact
        )

    def lines(self) -> list[str]:
        """The report's lines: the swing and its kinematic replay, then one per driven replay."""
        t, k = self.timed, self.kinematic
        out = [
            f"{self.name}: {t.duration:.2f} s swing at {t.rate:g} Hz, jaxexo {'ok' if t.ok else 'FAILED'} "
            f"(guaranteed clearance {100 * t.checks.min_clearance:.2f} cm); MuJoCo kinematic replay: smallest "
            f"distance {100 * k.mujoco_min_distance_m:.2f} cm over {k.poses} poses, largest difference from "
            f"jaxexo at the samples {1e6 * k.max_disagreement_m:.3f} um, {1e3 * k.seconds:.1f} ms"
        ]
        for label, d in self.driven.items():
            f = d.figures
            out.append(
                f"  {label.replace('_', ' ')}: heel error max {100 * f.heel_error_max_m:.2f} cm, toe "
                f"{100 * f.toe_error_max_m:.2f} cm; smallest distance {100 * f.mujoco_min_distance_m:.2f} "
                f"cm; {'CONTACT' if f.contact else 'no contact'}; "
                f"{'a limit saturates' if f.saturated else 'no limit saturates'}; {1e3 * d.seconds:.0f} ms"
            )
        return out

    def to_dict(self) -> dict:
        """The swing's entry of the JSON report."""
        t = self.timed
        return {
            "flagged_ok": bool(t.ok),
            "duration_s": t.duration,
            "rate_hz": t.rate,
            "kinematic": self.kinematic.to_dict(),
            **{label: d.to_dict() for label, d in self.driven.items()},
        }


def replay_swing(
    name: str, traj, config, *, rate=None, driven=False, half_limits=False, **drive
) -> SwingReplay:
    """A generator's swing ``traj`` timed for the device at ``rate`` Hz (default: the config's
    control_rate) and replayed: kinematically, and with ``driven`` at the [device] limits (also at
    HALF_LIMITS of them with ``half_limits``); ``drive``: ``driven_replay``'s controller, reference
    and reference_rate."""
    from jaxexo.swing.timing import DeviceLimits, time_swing

    timed = time_swing(traj, config, rate=rate)
    legs = Legs(config, timed.scene)
    kinematic = kinematic_replay(timed, config, legs=legs)
    scales = (("driven", 1.0), ("driven_half_limits", HALF_LIMITS))[: 2 if half_limits else 1]
    limits = DeviceLimits.from_config(config)
    figures = {
        label: driven_replay(timed, config, limits=limits.scaled(s, s), legs=legs, **drive)
        for label, s in (scales if driven else ())
    }
    return SwingReplay(name, timed, kinematic, figures)


def replay_document(scene, replays) -> dict:
    """The JSON report of a scene's replays (a list of SwingReplay)."""
    return {
        "units": {"length": "m", "angle": "rad", "time": "s"},
        "scene": {
            "obstacle": scene.obstacle.kind,
            "pivot_y": scene.pivot_y,
            "start_y": scene.start_y,
            "goal_y": scene.goal_y,
        },
        "replays": {r.name: r.to_dict() for r in replays},
    }
