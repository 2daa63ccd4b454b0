"""The compiled extension ``manifoldgen_core`` (C++ in ``native/``): whether it loads, and an empty core space.

:func:`core_problem` says in one line why the core cannot be used (not built, or built against another pinocchio)
with the command that fixes it; :func:`core_module` is the extension or None. :func:`empty_core` makes a
``manifoldgen_core.Space`` of a :class:`~manifoldgen.space.ConstrainedSpace`'s robot, limits and check settings,
without constraint terms: the robot model and the collision model (robot geometries, obstacles, a held tool, the
exact collision pairs) go over by pinocchio's own binary serialization (:func:`write_models`, shared with the C++
OMPL baseline), a floating base's six Euler coordinates as pinocchio's free flyer (:func:`active_coordinates`, as
:meth:`~manifoldgen.robot.Robot.to_pinocchio` maps them). What the core cannot take (a robot that is not a
pinocchio :class:`~manifoldgen.robot.Robot`): :func:`unsupported` says why, and the planners fall back to Python.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pinocchio as pin

from manifoldgen.robot import Robot
from manifoldgen.space import ConstrainedSpace

CORES = ("auto", "python", "native")


BUILD_HINT = "install manifoldgen with pip, which compiles it (pip install -e . in a checkout: scripts/setup.sh does)"


REBUILD = ("pip install scikit-build-core nanobind cmeel-eigen && pip install --no-build-isolation --no-deps "
           "--force-reinstall -e . (in the manifoldgen checkout)")


def core_module():
    """The ``manifoldgen_core`` extension, or None when it is not built or does not fit the installed
    pinocchio (:func:`core_problem` says why)."""
    return None if core_problem() else _import_core()


def core_problem() -> str:
    """Why the compiled core cannot be used, with the command that fixes it, in one line; "" when it can. A core
    compiled against another pinocchio than the installed one is refused: its inline pinocchio code would not
    match the libraries it runs with."""
    try:
        core = _import_core()
    except ImportError as exc:  # the module is there but does not load (e.g. an undefined pinocchio symbol)
        return (f"the compiled core manifoldgen_core does not load with pinocchio {pin.__version__} "
                f"({(str(exc).splitlines() or [type(exc).__name__])[0]}); rebuild it: {REBUILD}")
    if core is None:
        return f"the compiled core manifoldgen_core is not installed; {BUILD_HINT}"
    if core.PINOCCHIO_VERSION != pin.__version__:
        return (f"the compiled core was built against pinocchio {core.PINOCCHIO_VERSION} but pinocchio "
                f"{pin.__version__} is installed; pip install pin=={core.PINOCCHIO_VERSION}, or rebuild the core "
                f"against {pin.__version__}: {REBUILD}")
    return ""


def _import_core():
    """The ``manifoldgen_core`` module; None when it is not installed."""
    try:
        import manifoldgen_core
    except ModuleNotFoundError as exc:
        if exc.name != "manifoldgen_core":
            raise
        return None
    return manifoldgen_core


def write_models(space: ConstrainedSpace, folder: Path) -> tuple[Path, Path]:
    """Write the robot model and the space's collision model (obstacles and exact pairs included) with
    pinocchio's binary serialization into ``folder``: (model file, geometry file)."""
    folder = Path(folder)
    model_file, geometry_file = folder / "model.bin", folder / "geometry.bin"
    space.robot.model.saveToBinary(str(model_file))
    (space.checker.geom if space.checker is not None else pin.GeometryModel()).saveToBinary(str(geometry_file))
    return model_file, geometry_file


def active_coordinates(robot) -> list[tuple[int, int, int]]:
    """(idx_q, idx_v, nq) of each planning-group joint in pinocchio's q and v (nq 2: continuous); a floating
    base first, as its free flyer (nq 7), which stands for the group's six base coordinates."""
    joints = ([1] if robot.floating_base else []) + list(robot._joint_ids)
    return [(robot.model.joints[j].idx_q, robot.model.joints[j].idx_v, robot.model.joints[j].nq) for j in joints]


def unsupported(space: ConstrainedSpace) -> str | None:
    """Why the core cannot take ``space`` (a one-line reason), or None when it can."""
    if not isinstance(space.robot, Robot):
        return "the compiled core needs a pinocchio Robot"
    return None


def empty_core(space: ConstrainedSpace, geometry: bool = True):
    """A ``manifoldgen_core.Space`` of ``space``'s robot, limits and settings without constraint terms; with its
    collision model (``geometry``), else with none."""
    robot = space.robot
    with tempfile.TemporaryDirectory(prefix="manifoldgen-core-") as folder:
        if geometry:
            model_file, geometry_file = write_models(space, Path(folder))
        else:
            model_file, geometry_file = Path(folder) / "model.bin", Path(folder) / "geometry.bin"
            robot.model.saveToBinary(str(model_file))
            pin.GeometryModel().saveToBinary(str(geometry_file))
        return core_module().Space(str(model_file), str(geometry_file), robot.reference, active_coordinates(robot),
                                   robot.lower, robot.upper, space.settings.margin, space.settings.resolution)
