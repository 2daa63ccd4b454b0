"""What the physics check takes and what it reports: :class:`PhysicsSettings`, :class:`PhysicsResult`, and its
terminal summary and JSON."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field

import numpy as np

from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import GENERATOR


GAP = 0.005  # m: a foot further above the ground at the start is reported as not touching it


@dataclass(frozen=True)
class PhysicsSettings:
    """How the path is played back, and the verdict's thresholds."""

    seconds_per_rad: float = 2.0  # s per rad of a segment's largest angle change: at most 0.5 rad/s
    seconds_per_m: float = 10.0  # s per m of a segment's base translation: at most 0.1 m/s
    max_acceleration_rad: float = 1.0  # rad/s^2, each joint and base angle (a segment lasts long enough for it) ...
    max_acceleration_m: float = 0.1  # m/s^2 of the base (its CoM's ground projection moves ~ a h / g: 1 cm for talos)
    settle_s: float = 0.5  # s holding the first state before moving
    hold_s: float = 1.0  # s holding the last state after moving
    timestep: float = 0.001  # s, physics step
    control_period: float = 0.005  # s between servo target updates (and measurements)
    frequency_hz: float = 25.0  # natural frequency of every joint servo ...
    stance_frequency_hz: float = 5.0  # ... and of a joint with a standing foot beyond it, on the robot it carries
    damping_ratio: float = 1.0
    armature: float = 0.01  # kg m^2 added to every joint (a geared motor's rotor)
    friction: float = 0.8  # sliding friction coefficient of foot-ground contacts (rubber on concrete ~0.8)
    contact_timeconst_s: float = 0.005  # foot-ground contact stiffness (MuJoCo solref time constant; at least 2 steps)
    tilt_threshold_deg: float = 10.0  # upright: the base tilts less than this from the plan, throughout
    fall_tilt_deg: float = 45.0  # fell: the base tilts more than this ...
    fall_drop_m: float = 0.25  # ... or sinks this far below the plan
    slip_threshold_m: float = 0.02  # stable: upright and no foot slides further than this
    servo_wheels: bool = True  # locked wheels under the feet servoed not to roll (False: welded, as other locked joints)

    def __post_init__(self):
        for name, value in asdict(self).items():
            if not np.isfinite(value) or value < 0 or (value == 0 and name not in ("settle_s", "hold_s", "armature", "servo_wheels")):
                raise ManifoldgenError(f"physics setting {name} must be a positive number, got {value}")
        if self.contact_timeconst_s < 2 * self.timestep:
            raise ManifoldgenError(f"contact_timeconst_s ({self.contact_timeconst_s} s) must be at least two timesteps "
                                   f"({2 * self.timestep} s)")
        if self.control_period < self.timestep:
            raise ManifoldgenError(f"control_period ({self.control_period} s) must be at least the timestep "
                                   f"({self.timestep} s)")


@dataclass
class PhysicsResult:
    """What the robot did when the path was executed in the physics engine."""

    upright: bool  # never fell and max_tilt_deg < tilt_threshold_deg
    stable: bool  # upright and max_slip_m <= slip_threshold_m
    fell: bool
    fell_at_s: float | None  # simulated time of the fall (the run stops there)
    max_tilt_deg: float  # largest angle between the simulated and the planned base z axes
    max_slip_m: float  # largest horizontal displacement of a foot from where it started
    foot_slip_m: dict[str, float]  # per foot frame
    base_drift_m: float  # largest distance between the simulated and the planned base origin
    final_drift_m: float  # the same at the end
    max_tracking_error_rad: float  # largest |joint - servo target| (how well the servos held the path)
    max_effort_ratio: float  # largest |servo torque| / the URDF's effort limit of its joint (> 1: beyond the motor)
    effort_joint: str | None  # the joint where that ratio peaked
    start_foot_gap_m: dict[str, float]  # per foot: its distance to the ground at the first state
    simulated_s: float
    wall_s: float
    cpu_s: float
    engine: dict  # engine name and version, model facts (mass, bodies, contact geometries, what was dropped)
    settings: dict = field(default_factory=dict)  # PhysicsSettings, thresholds included
    path_file: str | None = None

    def to_dict(self) -> dict:
        return asdict(self)


def summary(result: PhysicsResult) -> str:
    """A few lines for the terminal."""
    s = result.settings
    verdict = ("FELL" + (f" at {result.fell_at_s:.2f} s" if result.fell_at_s is not None else "") if result.fell
               else "upright" if result.upright else "tilted")
    lines = [f"{result.path_file or 'path'}: {verdict}; {'stable' if result.stable else 'not stable'} "
             f"(upright: tilt < {s['tilt_threshold_deg']} deg; stable: slip <= {s['slip_threshold_m']} m; fell: tilt > "
             f"{s['fall_tilt_deg']} deg or base {s['fall_drop_m']} m below plan)",
             f"  max base tilt {result.max_tilt_deg:.2f} deg, base drift {result.base_drift_m:.4f} m "
             f"(final {result.final_drift_m:.4f} m), joint tracking error {result.max_tracking_error_rad:.4f} rad",
             f"  largest servo torque {result.max_effort_ratio:.2f} x its joint's URDF effort limit"
             + (f" ({result.effort_joint}; limits not applied)" if result.effort_joint else " (no limits in the URDF)"),
             "  foot slip " + ", ".join(f"{f} {v * 1000:.1f} mm" for f, v in result.foot_slip_m.items()),
             "  foot gap at start " + ", ".join(f"{f} {v * 1000:.1f} mm" for f, v in result.start_foot_gap_m.items())
             + "".join(f"; {f} does not touch the ground: the first state is not a stance on these feet"
                       for f, v in result.start_foot_gap_m.items() if v > GAP),
             f"  {result.engine['engine']} {result.engine['version']}: {result.engine['mass_kg']:.2f} kg, "
             f"{len(result.engine['contact_geoms'])} contact geometries, {result.engine['dropped_geoms']} other "
             f"collision geometries dropped; {result.simulated_s:.2f} s simulated in {result.wall_s:.2f} s wall, "
             f"{result.cpu_s:.2f} s CPU"]
    if wheels := result.engine.get("wheel_joints"):
        lines.append(f"  wheels servoed not to roll: {', '.join(wheels)}")
    return "\n".join(lines)


def to_json(result: PhysicsResult) -> str:
    return json.dumps({"generator": GENERATOR, "kind": "physics", **result.to_dict()}, indent=2)
