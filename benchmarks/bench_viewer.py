"""The viewer's figures: how fast ``manifoldgen view`` is ready, and what ``manifoldgen trajectory`` gives.

For a panda path (maze scene, held tool) and a centauro path (a scene made here: two configurations
of the pose task at y = 0 and a box), it times ``manifoldgen view FILE`` from launch to the printed
URL (scene built, server up) and to the robot drawn in headless Chromium (software WebGL: no GPU),
the exported page drawn offline, and the trajectory's duration beside the path length with the share
of time-parameterised states within tolerance.

    python benchmarks/bench_viewer.py [--repeats 3] [--out bench-viewer/]
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CLI = str(Path(sys.executable).with_name("manifoldgen"))
MODEL = ROOT / "src/manifoldgen/data/pretrained/panda-pose-cvae"


def run(*args: str) -> str:
    done = subprocess.run([CLI, *args], capture_output=True, text=True, check=True)
    return done.stdout


def centauro_scene(out: Path) -> Path:
    """Start: the first collected row at y = 0; goal: the fifth nearest to it (rows far apart may lie on
    pieces of the manifold that no path joins); a box beside the robot."""
    rows = out / "centauro-rows.npz"
    run("collect", "pose", "--robot", "centauro", "--per-condition", "20", "--condition", "0.0", "--seed", "0",
        "-o", str(rows))
    q = np.load(rows)["q"]
    goal = q[np.argsort(np.linalg.norm(q - q[0], axis=1))[5]]
    scene = {"name": "box", "robot": "centauro", "start": q[0].tolist(), "goal": goal.tolist(), "condition": [0.0],
             "obstacles": [{"name": "box", "type": "box", "pose": {"position": [1.2, 0.8, 0.3]},
                            "size": [0.2, 0.2, 0.2]}]}
    (out / "centauro-box.json").write_text(json.dumps(scene))
    return out / "centauro-box.json"


def view_ready(path: Path, browser) -> tuple[float, float]:
    """Seconds from launching ``view`` to its URL and to the scene drawn in the browser."""
    start = time.monotonic()
    process = subprocess.Popen([CLI, "view", str(path), "--port", "8780"], stdout=subprocess.PIPE, text=True)
    try:
        for line in process.stdout:
            if "http://" in line:
                break
        url_s = time.monotonic() - start
        browser.open(re.search(r"http://\S+", line).group(0))
        browser.settled_canvas(minimum=0.03)
        return url_s, time.monotonic() - start
    finally:
        process.send_signal(2)
        process.wait(30)


def main() -> None:
    from manifoldgen.viewer.browser import CHROMIUM, Browser

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path("bench-viewer"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    paths = {"panda maze": args.out / "panda-maze.npz", "centauro box": args.out / "centauro-box.npz"}
    run("plan", "pose", "--robot", "panda", "--scene", "maze", "--sampler", f"cvae:{MODEL}", "--seed", "0",
        "-o", str(paths["panda maze"]))
    run("plan", "pose", "--robot", "centauro", "--scene", str(centauro_scene(args.out)), "--sampler", "project",
        "--seed", "0", "-o", str(paths["centauro box"]))
    rows = []
    with Browser() as browser:
        for name, path in paths.items():
            times = [view_ready(path, browser) for _ in range(args.repeats)]
            page = args.out / f"{path.stem}.html"
            run("view", str(path), "--export", str(page))
            browser.open(page.as_uri())
            _, page_s = browser.settled_canvas(minimum=0.03)
            offline = all(u.startswith(("file:", "data:", "blob:")) for u in browser.requests())
            traj = trajectory_info(path, args.out / f"{path.stem}-traj.json")
            check = traj["check"]
            url_s, drawn_s = (statistics.median(t[i] for t in times) for i in (0, 1))
            rows.append(f"| {name} | {url_s:.1f} s | {drawn_s:.1f} s | {page.stat().st_size / 1e6:.1f} MB, drawn "
                        f"in {page_s:.1f} s{'' if offline else ' (fetched the network!)'} | "
                        f"{traj['path_length']:.2f} rad, {traj['waypoints']} waypoints | {traj['duration']:.2f} s | "
                        f"{100 * check['valid'] / check['states']:.1f} % of {check['states']} "
                        f"(worst {check['worst_violation']:.2f}) |")
    version = subprocess.run([str(CHROMIUM), "--version"], capture_output=True, text=True).stdout.strip()
    print(f"median of {args.repeats} launches; trajectories at vel/acc scale 0.5; {version} headless, software WebGL")
    print("| path | view: URL printed | view: robot drawn in Chromium | --export page | path length | trajectory "
          "duration | states within tolerance |")
    print("|---|---|---|---|---|---|---|")
    print("\n".join(rows))


def trajectory_info(path: Path, out: Path) -> dict:
    run("trajectory", str(path), "--vel-scale", "0.5", "--acc-scale", "0.5", "-o", str(out))
    return json.loads(out.read_text())["manifoldgen"]


if __name__ == "__main__":
    main()
