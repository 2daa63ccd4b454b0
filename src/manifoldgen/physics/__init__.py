"""Physics check of a planned path: does a floating-base robot stay upright when it executes it?

The path is played back quasi-statically in MuJoCo: the robot's own URDF, the floating base
free (a free joint, not fixed), gravity on, a ground plane under its feet, every joint
position-controlled towards the path's values linearly interpolated between waypoints, slowly,
then held. What the base and the feet do is measured: base tilt from the planned orientation,
foot slip along the ground, base drift from the planned position. This is the paper's Gazebo
test made a number.

Why MuJoCo (not pybullet): about 25 MB of wheels with no build step; a URDF importer (``MjSpec``) whose
model we edit before compiling (free joint, ground, servos, contact filters, foot sites) instead of
rewriting the URDF text; servo damping integrated implicitly (``implicitfast``), so stiff position servos
run at a 1 ms step; ``mj_geomDistance`` to set the feet on the ground. It reads centauro's and talos's
example-robot-data URDFs and meshes as they are.

The model (see docs/physics.md):

- links, joints and inertias from the URDF (``inertiafromgeom=false``: the URDF's inertials only,
  as pinocchio; the total mass is checked against pinocchio's); visual geometry is discarded;
- contacts: the feet only. A foot is a frame of the balance constraint; its collision geometry is
  every collision geometry rigidly attached to that frame's link in the plan (through no joint, or down
  through locked joints: centauro's contact frames are on the ankle links, the wheels hang from them on
  locked joints). Every other collision geometry is dropped (the planner already checked self-collision).
  A foot mesh in a format MuJoCo cannot read is rebuilt from the vertices pinocchio (coal) loaded; a foot
  mesh with a flat sole becomes a box, its sole's outline; the contacts are stiffer than MuJoCo's default
  (``contact_timeconst_s``);
- joints: each one a critically damped PD servo (MuJoCo ``general`` actuator, damping integrated
  implicitly, the target taken kv/kp ahead on the plan) whose stiffness is ``(2 pi f)^2 M_jj`` with
  ``M_jj`` the joint's diagonal of the joint-space inertia at the first state (armature included): every joint
  has natural frequency ``f``; a joint with a standing foot beyond it (knee, ankle) carries the rest of the
  robot, and is as stiff as that inertia about its axis at ``stance_frequency_hz`` where that is stiffer. Joints
  outside the planning group are welded at their locked values (their mimic equalities dropped), except
  wheels;
- wheels (``servo_wheels``, on by default): a locked hinge whose child body is part of a foot's contact
  geometry and whose axle is within 15 deg of horizontal at the first state. A disc's angle about its axle
  changes no geometry the plan checks, but welded, a wheel turns with its leg and rolls along the ground.
  Each wheel is servoed instead (same gains) to its locked value plus the angle, about the axle, from the
  world's down direction seen from the wheel's parent link at the first state to the same at the planned
  state (pinocchio's kinematics of the plan): the rim point that touched the ground stays the lowest, the
  wheel does not roll. ``engine["wheel_joints"]`` names them;
- time: segment k gets a nominal duration, the larger of ``seconds_per_rad`` times its largest angle change
  (joints and base angles) and ``seconds_per_m`` times its base translation; each segment is run on a quintic
  ease-in/ease-out from rest to rest (zero velocity and acceleration at both of its waypoints), lasting long
  enough that its peak speed is the nominal one and its peak accelerations stay within ``max_acceleration_rad``
  and ``max_acceleration_m``: no velocity jumps at the waypoints (whose kicks tipped talos over on long paths when
  the whole path was eased as one), and no sharp starts and stops on short segments (whose inertial forces move
  the zero-moment point by about a h / g). The first state is held ``settle_s`` before, the last ``hold_s`` after.

Parts: :mod:`.settings` (what the check takes and reports), :mod:`.mjcf` (the MuJoCo model from the URDF),
:mod:`.simulate` (running a path), :mod:`.check` (the entry points). Shapes: a path is ``(K, n)`` in the planning
group's coordinates (floating base first).
"""

from manifoldgen.physics.check import balance_feet, check_path, check_path_file
from manifoldgen.physics.settings import PhysicsResult, PhysicsSettings, summary, to_json

__all__ = ["PhysicsResult", "PhysicsSettings", "balance_feet", "check_path", "check_path_file", "summary", "to_json"]
