"""The robots that load by name: example-robot-data's URDFs (and SRDFs) found by file name, and a robot
recognised by its URDF's content hash."""

from __future__ import annotations

import difflib
import functools
import hashlib
import os
import re
import site
from pathlib import Path

from manifoldgen.errors import ManifoldgenError, not_a_file

# Names that no file stem gives, or gives ambiguously: name -> (folder, URDF stem).
_ALIASES = {
    "anymal": ("anymal_b_simple_description", "anymal"),  # anymal.urdf is in both ANYmal folders
    "anymal_b": ("anymal_b_simple_description", "anymal"),
    "anymal_c": ("anymal_c_simple_description", "anymal"),
    "g1": ("g1_description", "g1_29dof_rev_1_0"),
    "so_arm": ("so_arm_description", "so101"),
    "talos": ("talos_data", "talos_reduced"),
}


# URDFs that are not robots Robot.load can plan for: (folder, URDF stem).
_EXCLUDED = {
    ("ur_description", "ur3"),  # a xacro stub without a robot name: pinocchio cannot parse it (ur3 is ur3_robot)
    ("hector_description", "quadrotor_base"),  # a single body without joints: nothing to plan for
    ("iris_description", "iris_simple"),  # a single body without joints (iris has its rotor joints)
}


def robots_dir() -> Path:
    """Folder of example-robot-data's robots (the package ships no Python module)."""
    for root in [*site.getsitepackages(), site.getusersitepackages()]:
        path = Path(root) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
        if path.is_dir():
            return path
    raise ManifoldgenError("example-robot-data is not installed: run `pip install example-robot-data`")


def known_robots() -> list[str]:
    """Sorted names that :meth:`Robot.load` accepts for example-robot-data robots."""
    return list(robot_files(robots_dir()))


@functools.cache
def robot_files(root: Path) -> dict[str, tuple[Path, Path | None]]:
    """Name -> (URDF, SRDF or None) for every robot under ``root``, read from the files.

    Each ``*_description`` / ``*_data`` folder's ``urdf/`` and ``robots/`` URDFs are named by
    their stem (lower case, ``-``/``.`` as ``_``), by the stem without ``_robot`` (``ur5_robot``
    -> ``ur5``) and, for a folder's only URDF or the one named after it, by the folder; an
    explicit alias wins, then a stem, then the shorter names; ties go to the first folder.
    """
    ranked: dict[str, tuple[int, Path, Path | None]] = {}
    by_file: dict[tuple[str, str], tuple[Path, Path | None]] = {}
    for folder in sorted([*root.glob("*_description"), *root.glob("*_data")]):
        package = folder.name.removesuffix("_description").removesuffix("_data")
        urdfs = [u for sub in ("urdf", "robots") for u in sorted((folder / sub).glob("*.urdf"))
                 if (folder.name, u.stem) not in _EXCLUDED]
        srdfs = sorted((folder / "srdf").glob("*.srdf"))
        for urdf in urdfs:
            files = by_file[folder.name, urdf.stem] = (urdf, _matching_srdf(urdf.stem, package, srdfs))
            stem = re.sub(r"[^a-z0-9]+", "_", urdf.stem.lower())
            names = [(stem, 1), (stem.removesuffix("_robot"), 2)]
            if len(urdfs) == 1 or stem == package:
                names.append((package, 3))
            for name, rank in names:
                if name not in ranked or rank < ranked[name][0]:
                    ranked[name] = (rank, *files)
    for name, key in _ALIASES.items():
        if key in by_file:
            ranked[name] = (0, *by_file[key])
    return {name: (urdf, srdf) for name, (_, urdf, srdf) in sorted(ranked.items())}


def _matching_srdf(stem: str, package: str, srdfs: list[Path]) -> Path | None:
    """The SRDF of a URDF: same stem (or without ``_robot``), else the folder's only one or its namesake."""
    by_stem = {s.stem: s for s in srdfs}
    for candidate in (stem, stem.removesuffix("_robot")):
        if candidate in by_stem:
            return by_stem[candidate]
    return srdfs[0] if len(srdfs) == 1 else by_stem.get(package)


def is_path(robot: str) -> bool:
    return robot.endswith(".urdf") or os.sep in robot


def resolve_robot(robot: str, srdf: str | os.PathLike | None = None) -> tuple[Path, Path | None]:
    """Map an example-robot-data name or a URDF path to ``(urdf, srdf or None)``.

    srdf: an explicit SRDF path; by default the robot's own (for a path: the ``.srdf`` beside it).
    """
    if not robot.strip():
        raise ManifoldgenError("the robot name is empty; give a robot name (`manifoldgen robots` lists them) or the "
                               "path of a .urdf")
    if is_path(robot):
        urdf = Path(robot)
        if not urdf.is_file():
            raise ManifoldgenError(f"{not_a_file(urdf, 'URDF file')}; give an existing path or a robot name")
        beside = urdf.with_suffix(".srdf")
        default = beside if beside.is_file() else None
    else:
        catalogue = robot_files(robots_dir())
        if robot not in catalogue:
            lower = {name.lower(): name for name in catalogue}  # a name in other letter case is the closest
            close = [lower[robot.lower()]] if robot.lower() in lower else \
                difflib.get_close_matches(robot, list(catalogue), n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise ManifoldgenError(f"unknown robot '{robot}'{hint}; give one of the {len(catalogue)} names "
                                   "`manifoldgen robots` lists, or the path of a .urdf")
        urdf, default = catalogue[robot]
    if srdf is None:
        return urdf, default
    if not Path(srdf).is_file():
        raise ManifoldgenError(f"{not_a_file(srdf, 'SRDF file')}; give an existing .srdf path, "
                               f"or none to use {default or 'no SRDF'}")
    return urdf, Path(srdf)


def find_robot(identity: dict, hint: str | None = None) -> str:
    """What to pass to :meth:`Robot.load` for the robot of ``identity`` (see :attr:`Robot.identity`).

    The example-robot-data name if its URDF has the identity's hash, else ``hint`` (a URDF path
    or robot name) if its URDF has it: files are compared by content, not by path.
    """
    name, digest = identity.get("name"), identity.get("urdf_sha256")
    if not digest:
        raise ManifoldgenError(f"robot identity {identity} has no urdf_sha256; "
                               "give an identity from Robot.identity")
    catalogue = robot_files(robots_dir())
    tried = []
    sources = ([name] if name in catalogue else []) + ([str(hint)] if hint is not None else [])
    for source in dict.fromkeys(sources):
        urdf = Path(source) if is_path(source) else catalogue.get(source, (None,))[0]
        if urdf is not None and urdf.is_file():
            found = file_sha256(urdf)
            if found == digest:
                return source
            tried.append(f"{source} has {found[:12]}")
        else:
            tried.append(f"{source} is not a URDF file or robot name")
    if name not in catalogue:
        tried.insert(0, f"'{name}' is not an example-robot-data robot")
    raise ManifoldgenError(f"no URDF with sha256 {digest[:12]} (robot '{name}'): {'; '.join(tried)}; pass the path "
                           "of the URDF the file was made with (on the command line: --task FILE, a task file whose "
                           "robot is that path), or remake the file with this URDF")


def file_sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()
