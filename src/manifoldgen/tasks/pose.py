"""The paper's end-effector pose task (Section V-A) on three robots.

The end effector keeps a fixed world orientation; its height z is the condition y,
sampled at six values 0.1 m apart, like the paper's 0.5-1.0 m.
"""

from __future__ import annotations

import numpy as np

from manifoldgen.constraints import PoseConstraint, project
from manifoldgen.robot import Robot
from manifoldgen.tasks import Task, register

PANDA_ARM = [f"panda_joint{i}" for i in range(1, 8)]
PR2_GROUP = ["torso_lift_joint", "r_shoulder_pan_joint", "r_shoulder_lift_joint", "r_upper_arm_roll_joint",
             "r_elbow_flex_joint", "r_forearm_roll_joint", "r_wrist_flex_joint", "r_wrist_roll_joint"]
CENTAURO_GROUP = ["torso_yaw"] + [f"j_arm1_{i}" for i in range(1, 7)]


def _pose_task(robot: Robot, frame: str, rotation: np.ndarray, heights: np.ndarray,
               guess: np.ndarray, home_height: float, notes: str) -> Task:
    constraint = PoseConstraint(robot, frame, rotation, heights[:, None])
    home = project(constraint, guess, [home_height]).q[0]
    return Task("pose", robot, constraint, home, np.array([home_height]), notes)


@register("pose", "panda")
def panda_pose() -> Task:
    """Panda arm (7 joints), gripper pointing straight down, tool-centre height 0.2-0.7 m."""
    robot = Robot.load("panda", PANDA_ARM)
    ready = np.array([0.0, -0.785398, 0.0, -2.35619, 0.0, 1.5707, 0.785398])  # SRDF "default"
    _, down = robot.frame_pose(ready, "panda_hand_tcp")
    return _pose_task(robot, "panda_hand_tcp", down[0], np.round(np.arange(0.2, 0.75, 0.1), 2),
                      ready, 0.45, "gripper pointing down (a cup carried upright, grasped from above)")


@register("pose", "pr2")
def pr2_pose() -> Task:
    """PR2 torso lift + right arm (8 joints), gripper level and pointing forward, 0.5-1.0 m."""
    robot = Robot.load("pr2", PR2_GROUP)
    guess = np.array([0.15, -0.3, 0.2, 0.0, -1.2, 0.0, -0.4, 0.0])
    return _pose_task(robot, "r_gripper_tool_frame", np.eye(3), np.round(np.arange(0.5, 1.05, 0.1), 2),
                      guess, 0.8, "tool frame level, x forward: the paper's tool-holding pose")


@register("pose", "centauro")
def centauro_pose() -> Task:
    """Centauro torso yaw + left arm (7 joints), hand upright, height -0.2-0.3 m above the pelvis.

    The right arm is locked abducted with the elbow bent, clear of the pelvis.
    """
    robot = Robot.load("centauro", CENTAURO_GROUP,
                       reference={"j_arm2_1": 0.3, "j_arm2_2": -0.6, "j_arm2_4": -2.0})
    guess = np.array([0.0, -0.5, 0.3, 0.0, -1.2, 0.0, 0.0])
    return _pose_task(robot, "arm1_8", np.eye(3), np.round(np.arange(-0.2, 0.35, 0.1), 2),
                      guess, -0.05, "hand upright (the paper's drink can); heights relative to the pelvis")
