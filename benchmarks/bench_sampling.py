"""Table I of the paper and beyond: sampling time, accuracy and coverage of trained models.

    python benchmarks/bench_sampling.py                       # the shipped pretrained panda pose CVAE
    python benchmarks/bench_sampling.py MODEL_DIR... [-o OUT] # any trained models (same task)

Prints the Markdown tables (time for 100 ... 100k samples, median of warm repeats on 2 CPU
threads; raw and refine-3 within-tolerance rates; k-NN precision/recall/density/coverage and
MMD against fresh projection samples at seen and unseen conditions) and the targets.
Same as ``manifoldgen bench sampling MODEL_DIR... -o OUT``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import torch

from manifoldgen.bench.sampling import run_sampling_bench
from manifoldgen.models import pretrained_model_dir
from manifoldgen.runtime import set_threads


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="*", type=Path, help="model directories (default: the pretrained CVAE)")
    parser.add_argument("-o", "--output", type=Path, default=None, help="report folder (default: a temp dir)")
    parser.add_argument("--samples", type=int, default=3000)
    parser.add_argument("--reference", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    args = parser.parse_args()
    set_threads()  # as every command: torch's and numpy's BLAS threads sized for this machine
    torch.set_num_threads(max(1, args.threads))
    models = args.models or [pretrained_model_dir()]
    out = args.output or Path(tempfile.mkdtemp(prefix="bench-sampling-"))
    results = run_sampling_bench(models, out, samples=args.samples, reference_rows=args.reference,
                                 repeats=args.repeats, threads=max(1, args.threads))
    print((out / "table.md").read_text())
    print("targets (panda pose, tolerance 0.01 m / 0.01 rad):")
    for name, entry in results["models"].items():
        seen = entry["seen"]
        print(f"  {name}: 100k samples {entry['time_ms']['100000']:.1f} ms (paper CVAE 783.7 ms on a GPU; "
              f"target <= 60 ms for the CVAE), raw valid {seen['raw']:.1%}, after refine 3 {seen['refined']:.2%} "
              f"(target >= 99.5%), recall {seen['recall']:.3f}")
    print(f"report: {out}")


if __name__ == "__main__":
    main()
