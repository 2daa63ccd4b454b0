"""Process-wide defaults that more than one entry point shares, each defined once."""

TORCH_THREADS = 1  # these small MLPs gain nothing from a second thread, and two torch processes with two
# OpenMP threads each spin against each other on a shared 2-core machine (seen: 40x slower training)
REFINE = 2  # projection iterations a model sample gets by default (Algorithm 1's refinement; 0 = raw)


def set_torch_threads(threads: int = TORCH_THREADS) -> None:
    """Set torch's CPU thread count (at least 1)."""
    import torch

    torch.set_num_threads(max(1, int(threads)))
