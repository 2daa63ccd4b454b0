"""A planned path over its scene: the end-effector trace seen from the top and from the side; a held
object (the dual-arm tray) is drawn along the way with the trace of its centre."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from manifoldgen.constraints.balance import convex_hull
from manifoldgen.robot import Robot
from manifoldgen.scene import Scene
from manifoldgen.shapes import Obstacle
from manifoldgen.space import densify
from manifoldgen.io import save_figure

VIEWS = (("top view", 0, 1, "x (m)", "y (m)"), ("side view", 0, 2, "x (m)", "z (m)"))
TOOL_VIEWS = 8  # held-object outlines drawn along the path, start and goal included


def plot_path(path: np.ndarray, robot: Robot, frame: str, scene: Scene, out: str | Path, title: str = "") -> None:
    """Save a PNG: the trace of ``frame`` along ``path (K, n)`` over ``scene``'s obstacles
    (grey), the held tool's outline at start and goal (red) and along the path (light red) with the
    trace of its centre (red), start (green) and goal (blue)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon

    states = densify(path, 0.02)[0] if len(path) else np.stack([scene.start, scene.goal])
    trace = robot.frame_pose(states, frame)[0]
    ends = robot.frame_pose(np.stack([scene.start, scene.goal]), frame)[0]
    shapes = [(o, _world_points(o)) for o in scene.obstacles]
    tools = [_tool_points(scene, robot, q) for q in (scene.start, scene.goal)] if scene.attached else []
    along = (np.array([_tool_points(scene, robot, states[i])
                       for i in np.linspace(0, len(states) - 1, TOOL_VIEWS).astype(int)[1:-1]])
             if scene.attached and len(path) else np.zeros((0, 8, 3)))
    centre = _tool_centres(scene, robot, states) if scene.attached and len(path) else np.zeros((0, 3))
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    for ax, (name, i, j, xlabel, ylabel) in zip(axes, VIEWS):
        for _, points in shapes:
            ax.add_patch(Polygon(convex_hull(points[:, [i, j]]), closed=True, facecolor="0.75", edgecolor="0.35",
                                 alpha=0.6))
        for points in along:
            ax.add_patch(Polygon(convex_hull(points[:, [i, j]]), closed=True, facecolor="none", edgecolor="red",
                                 alpha=0.3, lw=0.8))
        for points in tools:
            ax.add_patch(Polygon(convex_hull(points[:, [i, j]]), closed=True, facecolor="none", edgecolor="red"))
        ax.plot(trace[:, i], trace[:, j], "-", color="m", lw=1.5, label=f"{frame} trace" if len(path) else None)
        if len(centre):
            ax.plot(centre[:, i], centre[:, j], "--", color="red", lw=1.2,
                    label=f"{scene.attached.shape.name} centre trace")
        ax.plot(*ends[0, [i, j]], "o", color="green", label="start")
        ax.plot(*ends[1, [i, j]], "s", color="blue", label="goal")
        everything = np.concatenate([trace[:, [i, j]], *(p[:, [i, j]] for _, p in shapes),
                                     *(p[:, [i, j]] for p in tools)])
        low, high = everything.min(0) - 0.05, everything.max(0) + 0.05
        ax.set_xlim(low[0], high[0])
        ax.set_ylim(low[1], high[1])
        ax.set_aspect("equal")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title(name)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    fig.suptitle(title or (f"{scene.name}: {len(path)} waypoints" if len(path) else f"{scene.name}: no path"))
    save_figure(fig, out)


def _world_points(obstacle: Obstacle) -> np.ndarray:
    pose = obstacle.pose.se3()
    return obstacle.local_points() @ pose.rotation.T + pose.translation


def _tool_centres(scene: Scene, robot: Robot, states: np.ndarray) -> np.ndarray:
    """(M, 3) world positions of the held object's origin at ``states (M, n)``."""
    p, R = robot.frame_pose(states, scene.attached.frame)
    return p + R @ scene.attached.shape.pose.position


def _tool_points(scene: Scene, robot: Robot, q: np.ndarray) -> np.ndarray:
    p, R = robot.frame_pose(q, scene.attached.frame)
    placement = scene.attached.shape.pose.se3()
    local = scene.attached.shape.local_points() @ placement.rotation.T + placement.translation
    return local @ R[0].T + p[0]
