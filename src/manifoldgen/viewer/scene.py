"""The viser scene of a :class:`ViewSource`: robot meshes, obstacles, held tool, traces, controls.

- path: the robot animated along the path (densified every ``FRAME_STEP`` rad) with a play
  checkbox and a time slider, the traced frames' paths, and the constraint's worst
  ``|F_i| / tol_i`` along the path as a plot;
- dataset / samples: every row's end-effector position coloured by its condition (rows
  outside tolerance in red), end-effector frames for up to ``MAX_AXES`` rows, and a slider
  that puts the robot at any row;
- scene / task: the robot at start and (translucent) at goal, with the obstacles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from manifoldgen.robot import Robot
from manifoldgen.space import densify
from manifoldgen.viewer.meshes import Part, joint_poses, robot_parts, scene_parts
from manifoldgen.viewer.source import ViewSource, traced_frames

FRAME_STEP = 0.02  # rad between animation frames of a path
FPS = 30
MAX_AXES = 400
GOAL_OPACITY = 0.35
INVALID_COLOR = (230, 30, 30)
TRACE_COLORS = ((200, 0, 200), (0, 150, 200))


class RobotNodes:
    """One robot drawn in a viser scene under ``prefix``: a frame per pinocchio joint carrying its
    parts (``<prefix>/<joint>/<part>``); :meth:`show` moves the frames to a configuration ``q (n,)``."""

    def __init__(self, server, prefix: str, robot: Robot, parts: list[Part], opacity: float | None = None):
        self.server, self.robot = server, robot
        self.joints = sorted({p.joint for p in parts})
        names = {j: f"{prefix}/{robot.model.names[j]}" for j in self.joints}
        self.frames = [server.scene.add_frame(names[j], show_axes=False) for j in self.joints]
        for part in parts:
            _add_mesh(server, f"{names[part.joint]}/{part.name}", part, opacity)

    def show(self, q: np.ndarray) -> None:
        poses = joint_poses(self.robot, np.asarray(q, float)[None], self.joints)[0]
        with self.server.atomic():
            for frame, pose in zip(self.frames, poses):
                frame.position = pose[:3, 3]
                frame.wxyz = _wxyz(pose[:3, :3])


@dataclass
class Viewer:
    """A built scene: ``frames (F, n)`` are the configurations the slider steps through
    (path states, dataset rows, or start); ``note``: what could not be drawn as asked."""

    server: object
    source: ViewSource
    frames: np.ndarray
    robot: RobotNodes
    slider: object = None
    play: object = None
    note: str = ""

    def show(self, i: int) -> None:
        """Put the robot at frame ``i``."""
        self.robot.show(self.frames[int(i) % len(self.frames)])


def build_scene(server, source: ViewSource) -> Viewer:
    """Add ``source`` to the viser ``server``'s scene and GUI."""
    task, scene = source.task, source.scene
    parts, note = robot_parts(task.robot)
    extras = scene_parts(scene, task.robot)
    tool = [p for p in extras if p.joint != 0]
    obstacles = [p for p in extras if p.joint == 0]
    for i, part in enumerate(obstacles):
        _add_mesh(server, f"/obstacles/{i}_{part.name}", part)
    server.gui.add_markdown(f"**{source.title}**  \n{source.file.name}" + (f"  \n_{note}_" if note else ""))
    robot = RobotNodes(server, "/robot", task.robot, parts + tool)
    if source.kind == "path":
        viewer = _path(server, source, robot)
    elif source.kind == "dataset":
        viewer = _dataset(server, source, robot)
    else:
        viewer = Viewer(server, source, source.q[:1], robot)
        if len(source.q) > 1:
            RobotNodes(server, "/goal", task.robot, parts + tool, opacity=GOAL_OPACITY).show(source.q[1])
    viewer.note = note
    viewer.show(0)
    _camera(server, task.robot, viewer.frames, extras)
    return viewer


def _path(server, source: ViewSource, robot: RobotNodes) -> Viewer:
    task, y = source.task, source.y[0]
    frames = densify(source.q, FRAME_STEP)[0]
    for k, frame in enumerate(traced_frames(task)):
        p = task.robot.frame_pose(frames, frame)[0]
        server.scene.add_line_segments(f"/trace/{frame}", np.stack([p[:-1], p[1:]], axis=1),
                                       colors=TRACE_COLORS[k % 2], thickness=0.004)
        server.scene.add_icosphere(f"/trace/{frame}_start", radius=0.015, color=(0, 170, 0), position=p[0])
        server.scene.add_icosphere(f"/trace/{frame}_goal", radius=0.015, color=(0, 60, 220), position=p[-1])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(frames, axis=0), axis=1))])
    use = task.constraint.violation(frames, y)
    server.gui.add_uplot((s, use, np.ones_like(s)),
                         ({"label": "path (rad)"}, {"label": "worst |F|/tol", "stroke": "red", "width": 1.5},
                          {"label": "tolerance", "stroke": "gray", "dash": [4, 4]}),
                         title="constraint along the path", scales={"x": {"time": False}}, aspect=1.6)
    play = server.gui.add_checkbox("play", initial_value=False)
    slider = server.gui.add_slider("time", min=0, max=len(frames) - 1, step=1, initial_value=0)
    viewer = Viewer(server, source, frames, robot, slider, play)
    slider.on_update(lambda _: viewer.show(slider.value))
    return viewer


def _dataset(server, source: ViewSource, robot: RobotNodes) -> Viewer:
    import matplotlib

    task, q, y = source.task, source.q, source.y
    traced = traced_frames(task, 1)
    frame = traced[0] if traced else task.robot.model.frames[-1].name
    p, R = task.robot.frame_pose(q, frame)
    valid = task.constraint.satisfied(q, y)
    c = y[:, 0] if y.shape[1] else np.zeros(len(q))
    shade = (c - c.min()) / (np.ptp(c) or 1.0)
    colors = (255 * matplotlib.colormaps["viridis"](shade)[:, :3]).astype(np.uint8)
    server.scene.add_point_cloud("/rows/valid", p[valid], colors[valid], point_size=0.008, point_shape="circle")
    if not valid.all():
        server.scene.add_point_cloud("/rows/invalid", p[~valid], INVALID_COLOR, point_size=0.016,
                                     point_shape="diamond")
    pick = np.unique(np.linspace(0, len(q) - 1, min(len(q), MAX_AXES)).astype(int))
    server.scene.add_batched_axes("/rows/frames", np.stack([_wxyz(r) for r in R[pick]]), p[pick],
                                  axes_length=0.03, axes_radius=0.002)
    names = ", ".join(task.condition.names)
    server.gui.add_markdown(f"colour: {names} from {c.min():.3g} (purple) to {c.max():.3g} (yellow); red: "
                            f"{int((~valid).sum())} of {len(q)} rows outside tolerance or limits")
    info = server.gui.add_markdown("")
    slider = server.gui.add_slider("row", min=0, max=len(q) - 1, step=1, initial_value=0)
    viewer = Viewer(server, source, q, robot, slider)

    def pick_row(_=None) -> None:
        i = int(slider.value)
        viewer.show(i)
        info.content = f"row {i}: {names} = {np.round(y[i], 4).tolist()}, {'valid' if valid[i] else 'INVALID'}"

    slider.on_update(pick_row)
    pick_row()
    return viewer


def _camera(server, robot: Robot, frames: np.ndarray, extras: list[Part]) -> None:
    """Look at the robot's and obstacles' bounding box from its front left (-y), above; a ground
    grid (10 cm cells) under it."""
    points = [robot.frame_pose(frames[[0, -1]], f.name)[0] for f in robot.model.frames[1:]]
    points += [(p.vertices @ p.placement[:3, :3].T + p.placement[:3, 3]) for p in extras if p.joint == 0]
    points = np.concatenate(points)
    low, high = points.min(0), points.max(0)
    center, size = (low + high) / 2, max(float(np.max(high - low)), 0.5)
    server.initial_camera.look_at = center
    server.initial_camera.position = center + size * np.array([0.5, -1.3, 0.7])
    server.scene.add_grid("/ground", width=2 * size, height=2 * size, cell_size=0.1, section_size=0.5,
                          position=(center[0], center[1], low[2]))


def _add_mesh(server, name: str, part: Part, opacity: float | None = None) -> None:
    """A mesh node at the part's placement in its parent node (``opacity`` overrides the part's alpha)."""
    alpha = float(part.color[3] if opacity is None else opacity)
    server.scene.add_mesh_simple(name, part.vertices, part.faces,
                                 color=tuple(int(c) for c in np.round(255 * part.color[:3])),
                                 opacity=None if alpha >= 1 else alpha, position=part.placement[:3, 3],
                                 wxyz=_wxyz(part.placement[:3, :3]))


def _wxyz(rotation: np.ndarray) -> np.ndarray:
    x, y, z, w = pin.Quaternion(np.asarray(rotation, float)).coeffs()
    return np.array([w, x, y, z])
