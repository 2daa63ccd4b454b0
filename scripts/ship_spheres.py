"""Fit the sphere models of the robots that the package's tasks and the held-out tasks name, into the package.

    python scripts/ship_spheres.py

Writes ``src/manifoldgen/data/spheres/ROBOT-DIGEST.npz`` (the cache's file format and names,
:mod:`manifoldgen.spheres.cache`) for each robot that has none there yet, from the robot files installed here;
a robot whose geometries or mesh files differ on another machine is fitted there as any user's robot.
"""

import os
import shutil
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TASK_FILES = sorted((ROOT / "src" / "manifoldgen" / "tasks").glob("*.toml")) + sorted(
    (ROOT / "benchmarks" / "heldout").glob("*.toml"))


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="ship-spheres-") as cache:
        os.environ["MANIFOLDGEN_CACHE"] = cache  # fit into an empty cache: nothing read from the user's
        from manifoldgen.spheres import cache_path, cache_stamp, sphere_model
        from manifoldgen.spheres.cache import SHIPPED
        from manifoldgen.tasks import load_task_file

        SHIPPED.mkdir(parents=True, exist_ok=True)
        done = set()
        for file in TASK_FILES:
            robot = load_task_file(file).robot
            path = cache_path(robot, cache_stamp(robot))
            if path.name in done:
                continue
            done.add(path.name)
            shipped = SHIPPED / path.name
            if shipped.exists():
                print(f"{robot.name}: {shipped.name} shipped already")
                continue
            model = sphere_model(robot)
            shutil.copy(path, shipped)
            print(f"{robot.name}: {len(model.radius)} spheres -> {shipped.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
