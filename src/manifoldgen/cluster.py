"""Independent tasks on a Ray cluster (``--cluster ray`` or ``--cluster ray:ADDRESS``): the driver submits them and
writes every file; a worker computes one task and returns its result.

:func:`parse_cluster` reads the option (None: no cluster, nothing here is used and Ray is never imported).
:func:`connect` joins the cluster (the Ray running on this machine, else one started for the command; or the
running cluster at ADDRESS), checks that every node runs this machine's manifoldgen, and gives a :class:`Pool`:
:meth:`Pool.submit` a task, :meth:`Pool.wait` for finished ones (result and node, in the order they finish), or
:meth:`Pool.map_unordered` a list of jobs. A task whose worker process dies (killed, out of memory, its node
leaving the cluster) is run again by Ray, up to :data:`RETRIES` times: its result arrives once. Tasks are pure
functions of their arguments, so a rerun gives the same result.
"""

from __future__ import annotations

import importlib.metadata
import os
import socket
import tempfile
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from manifoldgen.errors import ManifoldgenError, require

RETRIES = 3  # Ray reruns a task whose worker died this many times before the command fails
CONNECT_TIMEOUT = 10.0  # seconds an ADDRESS has to accept a connection before the command fails
DISTRIBUTION = "manifoldgen"


@dataclass(frozen=True)
class Cluster:
    """Where tasks run: ``address`` None: the Ray running on this machine, else one started for the command
    (``HOST:PORT`` or ``auto``: a running cluster); ``workers`` caps the tasks running at once (None: a queue of
    twice the cluster's CPUs)."""

    address: str | None = None
    workers: int | None = None

    def describe(self) -> str:
        return "the Ray on this machine" if self.address is None else f"the Ray cluster at {self.address}"


def parse_cluster(text: str | None, workers: int | None = None) -> Cluster | None:
    """``--cluster`` (``ray`` or ``ray:ADDRESS``) with ``--workers`` as a :class:`Cluster`; None without one."""
    if text is None:
        return None
    kind, colon, address = text.strip().partition(":")
    if kind != "ray" or (colon and not address.strip()):
        raise ManifoldgenError(f"--cluster takes ray (a Ray on this machine) or ray:ADDRESS (a running cluster: "
                               f"HOST:PORT of its head, or auto), got '{text}'")
    if address.startswith("ray://"):
        raise ManifoldgenError(f"--cluster {text}: Ray Client addresses are not supported; run the command on a node "
                               "of the cluster with ray:HEAD-HOST:PORT or ray:auto")
    if workers is not None and workers <= 0:
        raise ManifoldgenError(f"--workers must be positive (with --cluster: tasks running at once), got {workers}")
    require("ray", "ray", "--cluster ray")  # before any work starts
    return Cluster(address.strip() or None, workers)


def _host_port(address: str) -> tuple[str, int] | None:
    """(host, port) of ``HOST:PORT``; None for ``auto``."""
    if address == "auto":
        return None
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise ManifoldgenError(f"--cluster ray:{address}: give the head's HOST:PORT (e.g. ray:10.0.0.5:6379) or "
                               "ray:auto")
    return host.strip("[]"), int(port)


def _reachable(address: str) -> None:
    """Refuse, within :data:`CONNECT_TIMEOUT` seconds, an ADDRESS that accepts no connection (Ray itself would
    retry for minutes)."""
    where = _host_port(address)
    if where is None:
        return
    try:
        socket.create_connection(where, timeout=CONNECT_TIMEOUT).close()
    except OSError as exc:
        raise ManifoldgenError(f"no Ray cluster answers at {address} ({exc.strerror or exc}); start one there with "
                               "`ray start --head`, or check the address and the firewall") from None


def _version() -> str:
    try:
        return importlib.metadata.version(DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:
        raise ManifoldgenError("--cluster needs manifoldgen installed as a package on this machine too (pip install "
                               "-e . in a source tree)") from None


def _node() -> dict:
    """The node a task runs on: ``host`` (its name) and Ray's ``node`` id."""
    import ray

    return {"host": socket.gethostname(), "node": ray.get_runtime_context().get_node_id()}


def _call(version: str, cwd: str, inputs: tuple[str, ...], fn: Callable, *args):
    """Run ``fn(*args)`` on a worker, in the driver's working directory ``cwd`` where the node has it (relative
    paths then name the same files), and return ``(result, node)``; refuse a worker with another manifoldgen, or
    one that cannot read an input file (``inputs``: paths every node must see)."""
    here = importlib.metadata.version(DISTRIBUTION)
    node = _node()
    if here != version:
        raise ManifoldgenError(f"node {node['host']} runs manifoldgen {here}, the driver {version}: install the same "
                               "version on every node (or give the cluster an image that has it)")
    if os.path.isdir(cwd):
        os.chdir(cwd)
    for path in inputs:
        if not os.path.exists(path):
            raise ManifoldgenError(f"node {node['host']} cannot read {path}: every node needs the inputs at the same "
                                   "path (a shared file system); outputs are written by the driver alone")
    return fn(*args), node


class Pool:
    """Tasks on a connected cluster; at most ``window`` run or wait at once (:meth:`free` slots)."""

    def __init__(self, ray, window: int, version: str):
        self.ray, self.window, self.version = ray, window, version
        self.pending: dict = {}  # ObjectRef -> the caller's key
        self._remote = ray.remote(num_cpus=1, max_retries=RETRIES, retry_exceptions=False)(_call)

    def put(self, value):
        """``value`` stored once in the cluster (pass the reference to many tasks)."""
        return self.ray.put(value)

    def free(self) -> int:
        """Tasks that may be submitted before the window is full."""
        return max(0, self.window - len(self.pending))

    def submit(self, key, fn: Callable, *args, inputs: Iterable[str] = ()) -> None:
        """Run ``fn(*args)`` on a worker (``args`` may be references from :meth:`put`); :meth:`wait` returns it
        with ``key``."""
        ref = self._remote.remote(self.version, os.getcwd(), tuple(str(p) for p in inputs), fn, *args)
        self.pending[ref] = key

    def wait(self) -> list[tuple[object, object, dict]]:
        """Block until at least one task finished; ``[(key, result, node), ...]`` of all that did."""
        self.ray.wait(list(self.pending), num_returns=1)
        ready, _ = self.ray.wait(list(self.pending), num_returns=len(self.pending), timeout=0)
        return [(self.pending.pop(ref), *self._get(ref)) for ref in ready]

    def _get(self, ref) -> tuple[object, dict]:
        ray = self.ray
        try:
            return ray.get(ref)
        except ray.exceptions.RayTaskError as exc:
            cause = exc.cause
            if isinstance(cause, ManifoldgenError):
                raise ManifoldgenError(str(cause)) from None
            if isinstance(cause, ModuleNotFoundError) and (cause.name or "").split(".")[0] == DISTRIBUTION:
                raise _missing_package() from None
            first = (str(cause).strip().splitlines() or [""])[0][:200]
            raise ManifoldgenError(f"a task failed on the cluster ({type(cause).__name__}: {first})") from None
        except (ray.exceptions.WorkerCrashedError, ray.exceptions.NodeDiedError, ray.exceptions.ObjectLostError,
                ray.exceptions.RaySystemError) as exc:
            raise ManifoldgenError(f"a task was lost on the cluster ({type(exc).__name__}, after Ray's {RETRIES} "
                                   "reruns); the finished work is saved: rerun the same command to resume") from None

    def cancel(self) -> None:
        """Cancel every pending task (done, interrupted or failed: what finished is already written)."""
        for ref in self.pending:
            self.ray.cancel(ref)
        self.pending.clear()

    def map_unordered(self, fn: Callable, jobs: Iterable[tuple], *, inputs: Iterable[str] = ()
                      ) -> Iterator[tuple[int, object, dict]]:
        """``(index, fn(*jobs[index]), node)`` for every job, in the order they finish."""
        inputs, todo = tuple(inputs), iter(enumerate(jobs))
        try:
            while True:
                for index, args in todo:
                    self.submit(index, fn, *args, inputs=inputs)
                    if not self.free():
                        break
                if not self.pending:
                    return
                yield from self.wait()
        finally:
            self.cancel()


def _missing_package() -> ManifoldgenError:
    return ManifoldgenError(f"a node of the cluster has no manifoldgen installed: install manifoldgen=={_version()} "
                            "(with the [ray] extra) on every node, or give the cluster an image that has it")


def _check_nodes(ray, version: str) -> None:
    """Ask every alive node, with a task that needs nothing but the standard library, which manifoldgen it has."""
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    probe = ray.remote(num_cpus=0, max_retries=RETRIES)(importlib.metadata.version)
    nodes = [n for n in ray.nodes() if n.get("Alive")]
    answers = [probe.options(scheduling_strategy=NodeAffinitySchedulingStrategy(n["NodeID"], soft=False))
               .remote(DISTRIBUTION) for n in nodes]
    for node, answer in zip(nodes, answers):
        try:
            found = ray.get(answer)
        except ray.exceptions.RayTaskError as exc:
            if isinstance(exc.cause, importlib.metadata.PackageNotFoundError):
                raise _missing_package() from None
            raise
        if found != version:
            raise ManifoldgenError(f"node {node.get('NodeManagerHostname', node['NodeID'])} runs manifoldgen {found}, "
                                   f"this machine {version}: install the same version on every node (or give the "
                                   "cluster an image that has it)")


@contextmanager
def _stderr_to(file) -> Iterator[None]:
    """Send this process's file descriptor 2 to ``file`` (C++ libraries write there directly)."""
    saved = os.dup(2)
    os.dup2(file.fileno(), 2)
    try:
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


@contextmanager
def connect(cluster: Cluster) -> Iterator[Pool]:
    """A :class:`Pool` on ``cluster``. Joins the Ray this process already runs, if any; otherwise ``ray.init``
    (``address`` None: the Ray running on this machine, else a new one, stopped on leaving; or the one at
    ``address``)."""
    ray = require("ray", "ray", "--cluster ray")
    version = _version()
    started = not ray.is_initialized()
    if started:
        if cluster.address is not None:
            _reachable(cluster.address)
        with tempfile.TemporaryFile() as log:
            try:
                with _stderr_to(log):  # Ray's core prints every retry of a refused connection there
                    ray.init(address=cluster.address, include_dashboard=False, log_to_driver=False,
                             logging_level="ERROR")
            except (ConnectionError, RuntimeError, ValueError, TimeoutError) as exc:
                log.seek(0)
                first = (str(exc).strip().splitlines() or [""])[0][:200]
                hint = ("the cluster wants Ray's token: set RAY_AUTH_MODE=token with the cluster's token (see "
                        "docs/cluster.md)" if b"InvalidAuthToken" in log.read() else
                        "start it with `ray start --head` or check the address")
                raise ManifoldgenError(f"cannot join {cluster.describe()} ({first}); {hint}") from None
    try:
        _check_nodes(ray, version)
        cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
        pool = Pool(ray, cluster.workers or 2 * cpus, version)  # a queue as deep as the cluster: no worker waits
        try:
            yield pool
        finally:
            pool.cancel()  # tasks drawn ahead and no longer needed
    finally:
        if started:
            ray.shutdown()
