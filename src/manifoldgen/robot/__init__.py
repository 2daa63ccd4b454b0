"""Robot models: the robots that load by name (:mod:`.catalogue`), the :class:`Robot` with its planning group and
limits (:mod:`.model`), and its batched kinematics in numpy (:mod:`.steps`) and torch (:mod:`.kinematics_torch`).
"""

from manifoldgen.robot.catalogue import find_robot, known_robots, resolve_robot, robots_dir
from manifoldgen.robot.model import BASE_JOINTS, Robot
from manifoldgen.robot.steps import as_batch, is_tensor, is_traced

__all__ = ["BASE_JOINTS", "Robot", "as_batch", "find_robot", "is_tensor", "is_traced", "known_robots",
           "resolve_robot", "robots_dir"]
