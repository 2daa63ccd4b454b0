"""Process-wide defaults that more than one entry point shares, each defined once."""

TORCH_THREADS = 1  # these small MLPs gain nothing from a second thread, and two torch processes with two
# OpenMP threads each spin against each other on a shared 2-core machine (seen: 40x slower training)
CANDIDATES = ("cvae", "cfm")  # the models `train --model auto` trains and chooses from (manifoldgen.selection)
REFINE = 2  # projection iterations a model sample gets by default (Algorithm 1's refinement; 0 = raw)


THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def limit_threads() -> None:
    """Default the OpenMP and BLAS thread pools to :data:`TORCH_THREADS` (a variable already set wins); only
    takes effect before numpy and torch are imported: the command line calls it first."""
    import os

    for variable in THREAD_VARIABLES:
        os.environ.setdefault(variable, str(TORCH_THREADS))


MAX_THREADS = 256  # torch CPU threads a command may ask for


def set_threads(threads: int = TORCH_THREADS) -> None:
    """Set torch's CPU thread count (1 to :data:`MAX_THREADS`, else a one-line error): at once where torch is
    loaded, else through ``OMP_NUM_THREADS``, which torch reads when it loads (a command that never needs torch
    never pays its 2-3 s import); and numpy's BLAS pool as :func:`limit_threads` sizes it (its idle threads spin:
    45 % of a whole-body query's CPU on a busy machine, and a torch thread beside them runs many times slower)."""
    import operator
    import os
    import sys

    from manifoldgen.errors import ManifoldgenError

    try:
        whole = operator.index(threads)
    except TypeError:
        whole = None
    if whole is None or isinstance(threads, bool) or not 1 <= whole <= MAX_THREADS:
        raise ManifoldgenError(f"threads must be a whole number from 1 to {MAX_THREADS}, got {threads!r}")
    threads = whole
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(threads)
    else:
        os.environ["OMP_NUM_THREADS"] = str(threads)
    limit_threads()  # numpy's BLAS pool, for a numpy loaded later
    if "numpy" in sys.modules:  # already loaded: its pool takes the same size at once
        from threadpoolctl import threadpool_limits
        threadpool_limits(int(os.environ["OPENBLAS_NUM_THREADS"]), user_api="blas")


MAX_SEED = 2**32 - 1  # seeds feed numpy's and torch's generators; run r of a benchmark uses seed + r


def check_seed(seed: int, what: str = "--seed") -> int:
    """``seed`` as an int in [0, MAX_SEED], or a one-line error naming it."""
    import operator

    from manifoldgen.errors import ManifoldgenError

    try:
        value = None if isinstance(seed, bool) else operator.index(seed)
    except TypeError:
        value = None
    if value is None or not 0 <= value <= MAX_SEED:
        raise ManifoldgenError(f"{what} must be an integer from 0 to {MAX_SEED}, got {seed!r}")
    return value
