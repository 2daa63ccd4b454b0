"""Robot snapshots along a path, like the paper's Figs. 3-6: a strip of ``count`` 3-D views (t0 ...
t5) rendered with matplotlib (no display), for any task.

Each view draws the robot's collision geometry (each part reduced to the convex hull of at most
``HULL_POINTS`` of its vertices, shaded by a fixed light), the scene's obstacles (grey), the held
tool (red) and the traced frames' path (magenta) with their position at that time: the frames of
the scene's end-effector targets, else those the task's constraint names. For a balance task
(paper Fig. 6) each view also draws the support polygon on the ground (green) and the centre of
mass with its ground projection (a dot: green inside the polygon, red outside; the title gives its
depth inside, in cm).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import check_output_path
from manifoldgen.query import read_path_file
from manifoldgen.scene import Scene
from manifoldgen.space import densify
from manifoldgen.stability import balance_part
from manifoldgen.tasks import Task, task_from_meta
from manifoldgen.viewer.meshes import Part, part_poses, robot_parts, scene_parts
from manifoldgen.viewer.source import traced_frames
from manifoldgen.io import save_figure

HULL_POINTS = 60
LIGHT = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])


def write_snapshots(path: str | Path | np.ndarray, out: str | Path, meta: dict | None = None,
                    count: int = 6) -> Path:
    """Save the strip for a path file, or for ``path (K, n)`` with its file's ``meta``; returns ``out``."""
    if meta is None:
        meta, path, task = read_path_file(path)
        return draw_snapshots(path, task, Scene.from_meta(meta), out, count)
    return draw_snapshots(path, task_from_meta(meta), Scene.from_meta(meta), out, count)


def draw_snapshots(path: np.ndarray, task: Task, scene: Scene, out: str | Path, count: int = 6) -> Path:
    """Save the strip of ``count`` views along ``path (K, n)`` of ``task`` in ``scene``; returns ``out``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    out, path = check_output_path(out), np.asarray(path, float)
    if path.ndim != 2 or len(path) == 0:
        raise ManifoldgenError(f"snapshots need a non-empty path (K, n), got shape {path.shape}")
    robot = task.robot
    parts = [_reduced(p) for p in robot_parts(robot, visual=False)[0] + scene_parts(scene, robot)]
    states = densify(path, 0.01)[0]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(states, axis=0), axis=1))])
    picks = np.searchsorted(s, np.linspace(0, s[-1], count)).clip(0, len(states) - 1)
    poses = part_poses(robot, parts, states[picks])
    frames = list(dict.fromkeys(t["frame"] for t in scene.targets.values() if t.get("frame"))) or traced_frames(task)
    traces = [robot.frame_pose(states, f)[0] for f in frames]
    world = [[(p.vertices @ T[:3, :3].T + T[:3, 3]) for p, T in zip(parts, poses[i])] for i in range(count)]
    balance = balance_part(task.constraint)
    if balance is not None:
        polygon = np.column_stack([balance.hull, np.full(len(balance.hull), balance.ground)])
        com, depth = robot.com(states[picks]), balance.com_depth(states[picks])
    points = np.concatenate([v for views in world for v in views] + traces
                            + ([polygon] if balance is not None else []))
    low, high = points.min(0), points.max(0)
    fig = plt.figure(figsize=(3.2 * count, 3.6))
    for i in range(count):
        ax = fig.add_subplot(1, count, i + 1, projection="3d", computed_zorder=False)
        triangles = np.concatenate([v[p.faces] for p, v in zip(parts, world[i])])
        colors = np.concatenate([np.repeat(p.color[None], len(p.faces), 0) for p in parts])
        normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
        light = np.abs(normals @ LIGHT) / np.maximum(np.linalg.norm(normals, axis=1), 1e-12)
        colors[:, :3] *= (0.45 + 0.55 * light)[:, None]
        ax.add_collection3d(Poly3DCollection(triangles, facecolors=colors, edgecolors="none"))
        for trace in traces:
            ax.plot(*trace.T, color="m", lw=1.0)
            ax.plot(*trace[picks[i]], "o", color="m", ms=4)
        title = f"t{i}: {s[picks[i]] / max(s[-1], 1e-12):.0%} of the path"
        if balance is not None:
            _draw_balance(ax, polygon, com[i], balance.ground, depth[i])
            title += f"\nCoM {100 * depth[i]:.1f} cm inside" if depth[i] >= 0 else f"\nCoM {-100 * depth[i]:.1f} cm OUTSIDE"
        ax.set_xlim(low[0], high[0])
        ax.set_ylim(low[1], high[1])
        ax.set_zlim(low[2], high[2])
        ax.set_box_aspect(np.maximum(high - low, 1e-3))
        ax.view_init(elev=22, azim=-60)
        ax.set_axis_off()
        ax.set_title(title, fontsize=9)
    fig.suptitle(f"{robot.name} {task.name}, scene {scene.name}: {len(path)} waypoints, {s[-1]:.2f} rad", fontsize=10)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.88 if balance is None else 0.8, wspace=0)
    save_figure(fig, out)
    return Path(out)


def _draw_balance(ax, polygon: np.ndarray, com: np.ndarray, ground: float, depth: float) -> None:
    """The support polygon ``(H, 3)`` on the ground, the CoM ``(3,)`` and its ground projection."""
    closed = np.vstack([polygon, polygon[:1]])
    ax.plot(*closed.T, color="green", lw=1.5, zorder=5)
    color = "green" if depth >= 0 else "red"
    ax.plot([com[0], com[0]], [com[1], com[1]], [com[2], ground], ":", color=color, lw=1.0, zorder=6)
    ax.plot(*com, "o", color="k", ms=4, zorder=6)
    ax.plot(com[0], com[1], ground, "o", color=color, ms=6, zorder=6)


def _reduced(part: Part) -> Part:
    """The part as the convex hull of at most HULL_POINTS of its vertices (evenly picked)."""
    from scipy.spatial import ConvexHull, QhullError

    vertices = part.vertices[np.unique(np.linspace(0, len(part.vertices) - 1, HULL_POINTS).astype(int))]
    try:
        faces = ConvexHull(vertices).simplices
    except QhullError:  # a flat or degenerate vertex set: keep the part as it is
        return part
    return Part(part.name, part.joint, part.placement, vertices, faces, part.color.copy())
