"""Maze scene (the paper's Table III), reduced: every method on the same query and seeds.

    python benchmarks/bench_maze.py [--runs 20] [--time 30] [--workers 2] [--out bench-maze]
                                    [--model DIR ...] [--methods SPEC ...]

Prints the Markdown table and each method's median speed-up and success against OMPL's
ProjectedStateSpace + RRTConnect at the same tolerance (the target: a learned sampler at
least 5x faster in median, with success at least as high). The paper's version is
``manifoldgen bench maze --runs 100 --time 200 -o OUT``.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_wall import main  # noqa: E402  (the same script, another scene)

if __name__ == "__main__":
    main("maze", 20, 30.0)
