"""Sphere models: spheres per robot, cost per state of the batched numpy sphere check vs coal, and its
false-positive rate (sphere says collision, coal says free) on the scenes' states.

    python benchmarks/bench_spheres.py [--states 2000] [--robots panda pr2 talos centauro] [--draw PNG]

States are the task's manifold at the scene's condition (uniform seeds projected by damped least
squares: what a constrained planner checks) and, beside them, uniform states in the joint limits; for
the whole-body robots (self-collision only), seeds around the task's home projected onto its manifold.
Every state coal finds in collision must be in collision for the spheres too (the script fails
otherwise).
The sphere checker finds its tight pairs (self pairs sent to coal) on a second half of the manifold
states, not on those measured. Costs are CPU microseconds per state (process time), one batch of all
states and batches of 32; wall time beside them. ``--draw PNG`` only draws panda's spheres over its
meshes at the pose task's home.
"""

import argparse
import time

import numpy as np

from manifoldgen.constraints import project
from manifoldgen.runtime import set_threads
from manifoldgen.scene import get_scene, task_checker
from manifoldgen.spheres import SphereChecker, fit_model
from manifoldgen.tasks import get_task

ROBOTS = {"panda": ("pose", "panda"), "pr2": ("dualarm", "pr2"), "talos": ("balance", "talos"),
          "centauro": ("balance", "centauro")}
NEAR_HOME = 0.3  # rad (m for a floating base's position): spread of the seeds around home, self-only table
SCENES = [("pose", "panda", "maze"), ("pose", "panda", "wall"), ("dualarm", "pr2", "tray-over")]


def timed(fn, *args):
    """(result, CPU seconds, wall seconds)."""
    cpu, wall = time.process_time(), time.perf_counter()
    out = fn(*args)
    return out, time.process_time() - cpu, time.perf_counter() - wall


def models(robots: list[str]) -> dict:
    print("| robot (group) | geometries | spheres | per geometry (max) | solid volume added | fit CPU s (wall) |")
    print("|---|---|---|---|---|---|")
    out = {}
    for name in robots:
        task = get_task(*ROBOTS[name])
        geom = task.robot.collision_model
        model, cpu, wall = timed(fit_model, geom)
        out[name] = model
        counts = model.counts()
        added = model.union_volume.sum() / model.solid_volume.sum() - 1
        note = f", {len(model.unfitted)} without spheres" if model.unfitted else ""
        print(f"| {name} ({task.name}, {task.robot.n} joints) | {len(geom.geometryObjects)} | {len(model)}{note} | "
              f"{np.median(counts[counts > 0]):.0f} ({counts.max()}) | +{added:.0%} | {cpu:.1f} ({wall:.1f}) |")
    return out


def states(task, condition: np.ndarray, count: int, rng) -> np.ndarray:
    """(count', n) states on the task's manifold at ``condition`` (converged projections of uniform seeds)."""
    result = project(task.constraint, task.robot.sample_uniform(count, rng), condition)
    return result.q[result.converged]


def per_state(check, q: np.ndarray, batch: int) -> tuple[np.ndarray, float, float]:
    """Results, CPU and wall microseconds per state, checking ``q`` in batches of ``batch``."""
    cpu, wall = time.process_time(), time.perf_counter()
    out = np.concatenate([check(q[i:i + batch]) for i in range(0, len(q), batch)])
    return out, (time.process_time() - cpu) / len(q) * 1e6, (time.perf_counter() - wall) / len(q) * 1e6


def scenes(count: int, fitted: dict) -> None:
    print()
    print("| scene | states | coal: in collision | spheres: false positives (of coal-free) | missed | "
          "coal µs/state CPU (wall) | spheres µs/state CPU (wall), batch all / 32 |")
    print("|---|---|---|---|---|---|---|")
    for task_name, robot, scene_name in SCENES:
        task = get_task(task_name, robot)
        scene = get_scene(task, scene_name)
        checker = scene.checker(task.robot)
        rng = np.random.default_rng(0)
        manifold = states(task, scene.condition, 2 * count, rng)
        # tight pairs found on other states than those measured (the second half)
        fast = SphereChecker(checker, fitted.get(robot), typical=manifold[len(manifold) // 2:])
        for kind, q in (("manifold", manifold[:len(manifold) // 2]),
                        ("uniform", task.robot.sample_uniform(count, rng))):
            exact, coal_cpu, coal_wall = per_state(checker.in_collision, q, len(q))
            sphere, cpu, wall = per_state(fast.in_collision, q, len(q))
            _, cpu32, wall32 = per_state(fast.in_collision, q, 32)
            missed = int(np.sum(exact & ~sphere))
            free = ~exact
            print(f"| {robot} {scene_name}, {kind} | {len(q)} | {exact.mean():.1%} | {np.mean(sphere[free]):.1%} | "
                  f"{missed} | {coal_cpu:.1f} ({coal_wall:.1f}) | {cpu:.1f} ({wall:.1f}) / "
                  f"{cpu32:.1f} ({wall32:.1f}) |")
            if missed:
                raise SystemExit(f"{missed} states in collision for coal are free for the spheres: not conservative")


def self_only(robots: list[str], count: int, fitted: dict) -> None:
    print()
    print("| robot, self-collision only | states | coal: in collision | spheres: false positives (of coal-free) | "
          "missed | coal µs/state CPU (wall) | spheres µs/state CPU (wall), batch all |")
    print("|---|---|---|---|---|---|---|")
    for name in robots:
        if name in {r for _, r, _ in SCENES}:
            continue
        task = get_task(*ROBOTS[name])
        checker = task_checker(task)
        rng = np.random.default_rng(0)
        seeds = np.clip(task.home + rng.normal(0, NEAR_HOME, (2 * count, task.robot.n)), task.robot.lower,
                        task.robot.upper)
        near = project(task.constraint, seeds, task.home_condition)
        near = near.q[near.converged]
        # tight pairs found on other states than those measured (the first half)
        fast = SphereChecker(checker, fitted.get(name), typical=near[len(near) // 2:])
        uniform = task.robot.sample_uniform(count, rng)
        for kind, q in (("manifold near home", near[:len(near) // 2]), ("uniform", uniform)):
            exact, coal_cpu, coal_wall = per_state(checker.in_collision, q, len(q))
            sphere, cpu, wall = per_state(fast.in_collision, q, len(q))
            missed = int(np.sum(exact & ~sphere))
            print(f"| {name}, {kind} | {len(q)} | {exact.mean():.1%} | {np.mean(sphere[~exact]):.1%} | {missed} | "
                  f"{coal_cpu:.1f} ({coal_wall:.1f}) | {cpu:.1f} ({wall:.1f}) |")
            if missed:
                raise SystemExit(f"{name}: {missed} states in collision for coal are free for the spheres")


def draw(path: str) -> None:
    """Panda's meshes (grey) and spheres (translucent) at the pose task's home, two views, to ``path``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pinocchio as pin
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from manifoldgen.spheres import sphere_model, triangles_of

    task = get_task("pose", "panda")
    robot = task.robot
    model = sphere_model(robot)
    data, geom = robot.model.createData(), robot.collision_model
    gdata = pin.GeometryData(geom)
    full = robot.to_pinocchio(task.home)[0]
    pin.forwardKinematics(robot.model, data, full)
    pin.updateGeometryPlacements(robot.model, data, geom, gdata)
    meshes = [triangles_of(g.geometry) @ gdata.oMg[i].rotation.T + gdata.oMg[i].translation
              for i, g in enumerate(geom.geometryObjects)]
    centers = np.array([data.oMi[int(j)].act(c) for j, c in zip(model.joint, model.center)])
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 14), np.linspace(0, np.pi, 8))
    unit = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], -1)
    fig = plt.figure(figsize=(10, 5.5))
    for k, (elev, azim) in enumerate(((20, -60), (10, 30))):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        for tris in meshes:
            ax.add_collection3d(Poly3DCollection(tris, facecolor="0.25", edgecolor="none", alpha=0.35))
        for c, r in zip(centers, model.radius):
            ball = c + r * unit
            ax.plot_surface(ball[..., 0], ball[..., 1], ball[..., 2], color="tab:orange", alpha=0.18, linewidth=0)
        middle, half = (centers.max(0) + centers.min(0)) / 2, (centers.max(0) - centers.min(0)).max() / 2 + 0.08
        ax.set(xlim=middle[0] + [-half, half], ylim=middle[1] + [-half, half], zlim=middle[2] + [-half, half],
               box_aspect=(1, 1, 1))
        ax.view_init(elev, azim)
        ax.set_axis_off()
    fig.suptitle(f"panda: {len(model)} spheres cover its {len(geom.geometryObjects)} collision geometries "
                 f"(home of the pose task)")
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.93, wspace=0)
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--states", type=int, default=2000)
    parser.add_argument("--robots", nargs="*", default=list(ROBOTS), choices=list(ROBOTS))
    parser.add_argument("--draw", metavar="PNG", help="only draw panda's spheres over its meshes to PNG")
    args = parser.parse_args()
    set_threads()  # as every command: torch's and numpy's BLAS threads sized for this machine
    if args.draw:
        draw(args.draw)
        return
    fitted = models(args.robots)
    scenes(args.states, fitted)
    self_only(args.robots, args.states, fitted)


if __name__ == "__main__":
    main()
