"""Self-collision (and, through ``obstacles``, scene collision) with pinocchio and coal.

Objects ``attached`` to a robot joint (a held tool) are checked against the obstacles and
the robot links that are not adjacent to their joint. Configurations run through a coal
broad phase (dynamic AABB tree) rather than pair by pair.
Pairs are pruned as MoveIt's setup assistant does: pairs the SRDF disables, pairs whose
relative pose the planning group cannot change, and, when the SRDF disables fewer than
``MIN_SRDF_PAIRS`` (centauro's disables none), pairs found never or always colliding
over random configurations. That matrix is cached on disk, keyed by robot and group; the cache
file holds hashes of the robot (URDF and SRDF content, group, reference), of the candidate pairs and
of its own pair list, and one that does not match is recomputed with a one-line notice.
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin

from manifoldgen.errors import ManifoldgenError
from manifoldgen.io import atomic_write_text
from manifoldgen.robot import Robot, as_batch

MIN_SRDF_PAIRS = 1
MATRIX_SAMPLES = 2000
# Scene objects (obstacles and held tools) one checker takes: pinocchio's geometry model keeps a square table of
# its objects' pairs and copies it whole on each object added, so set-up grows as the cube of the count
# (1,000 objects: about 0.4 s; 2,000: 3 s; 20,000: hours).
MAX_SCENE_OBJECTS = 1000


def cache_dir() -> Path:
    """Where computed collision matrices live (``$MANIFOLDGEN_CACHE`` or ~/.cache/manifoldgen)."""
    return Path(os.environ.get("MANIFOLDGEN_CACHE", Path.home() / ".cache" / "manifoldgen"))


class CollisionChecker:
    """Checks configurations ``q (B, n)`` of a robot's planning group for collisions.

    obstacles: extra ``pin.GeometryObject`` attached to the universe (parent joint 0),
    checked against every robot geometry that the planning group moves.
    attached: ``pin.GeometryObject`` fixed to a robot joint (parentJoint, parentFrame and
    placement set), checked against the obstacles and every robot geometry that moves
    relative to it, except those on its ``touch`` links (default :func:`touch_links`).
    """

    def __init__(self, robot: Robot, obstacles: list[pin.GeometryObject] | None = None,
                 attached: list[pin.GeometryObject] | None = None, touch: list[list[str]] | None = None):
        self.robot = robot
        count = len(obstacles or []) + len(attached or [])
        if count > MAX_SCENE_OBJECTS:
            raise ManifoldgenError(f"the scene has {count:,} objects; at most {MAX_SCENE_OBJECTS:,} are supported (the "
                                   "collision model's set-up grows as the cube of their count): merge small obstacles "
                                   "into mesh obstacles")
        self.geom = robot.collision_model.copy()
        self.geom.removeAllCollisionPairs()
        self.self_pairs = _self_pairs(robot)
        for a, b in self.self_pairs:
            self.geom.addCollisionPair(pin.CollisionPair(a, b))
        # plain values: references into geometryObjects dangle once objects are added
        robot_geoms = [(i, g.parentJoint, robot.model.frames[g.parentFrame].name)
                       for i, g in enumerate(self.geom.geometryObjects)]
        moving = [i for i, joint, _ in robot_geoms if _moving(robot, joint)]
        self.obstacle_ids = []
        for obstacle in obstacles or []:
            oid = self.geom.addGeometryObject(obstacle)
            self.obstacle_ids.append(oid)
            for i in moving:
                self.geom.addCollisionPair(pin.CollisionPair(i, oid))
        self.attached_ids = []
        for k, obj in enumerate(attached or []):
            aid = self.geom.addGeometryObject(obj)
            self.attached_ids.append(aid)
            touching = set(touch[k] if touch is not None else touch_links(robot, obj.parentJoint))
            joint = self.geom.geometryObjects[aid].parentJoint
            for i, parent, link in robot_geoms:
                if link not in touching and _moving(robot, parent) != _moving(robot, joint):
                    self.geom.addCollisionPair(pin.CollisionPair(i, aid))
            for oid in self.obstacle_ids:
                self.geom.addCollisionPair(pin.CollisionPair(aid, oid))
        self.data = robot.model.createData()
        self.geom_data = pin.GeometryData(self.geom)
        # a broad phase (dynamic AABB tree) over the same pairs; pinocchio's parallel pool variant
        # would reset OpenMP's thread count (torch's too) as a side effect
        self._broad = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(robot.model, self.geom, self.geom_data)

    def in_collision(self, q: np.ndarray) -> np.ndarray:
        """(B,) bool: True where some checked pair collides."""
        full = self.robot.to_pinocchio(as_batch(q, self.robot.n))
        return np.array([pin.computeCollisions(self.robot.model, self.data, self._broad, row, True)
                         for row in full], dtype=bool)

    def first_collision(self, q: np.ndarray) -> int:
        """Index of the first colliding row of ``q (B, n)`` (rows checked in order, stopping
        there), or B when every row is free."""
        full = self.robot.to_pinocchio(as_batch(q, self.robot.n))
        for i, row in enumerate(full):
            if pin.computeCollisions(self.robot.model, self.data, self._broad, row, True):
                return i
        return len(full)

    def collisions(self, q: np.ndarray) -> list[tuple[str, str]]:
        """Names of the colliding geometry pairs at one configuration ``q (n,)``."""
        full = self.robot.to_pinocchio(as_batch(q, self.robot.n))[0]
        pin.computeCollisions(self.robot.model, self.data, self.geom, self.geom_data, full, False)
        names = [g.name for g in self.geom.geometryObjects]
        return [(names[p.first], names[p.second]) for p, r in
                zip(self.geom.collisionPairs, self.geom_data.collisionResults) if r.isCollision()]


def touch_links(robot: Robot, joint: int) -> list[str]:
    """Robot links an object fixed to ``joint`` may touch (as MoveIt's touch links): those on
    the joint itself, its parent joint and its child joints (a held tool touches the hand,
    the fingers and the wrist)."""
    model = robot.model
    adjacent = {joint, model.parents[joint]} | {j for j in range(1, model.njoints) if model.parents[j] == joint}
    return sorted({model.frames[g.parentFrame].name for g in robot.collision_model.geometryObjects
                   if g.parentJoint in adjacent})


def _moving(robot: Robot, joint: int) -> frozenset[int]:
    """The active coordinates that move a body attached to ``joint``."""
    return frozenset(m.index for a in robot._ancestors(joint) for m in robot._links[a].motions)


def _self_pairs(robot: Robot) -> list[tuple[int, int]]:
    """Geometry index pairs worth checking for self-collision."""
    geom = robot.collision_model.copy()
    geom.addAllCollisionPairs()
    if robot.srdf is not None:
        pin.removeCollisionPairs(robot.model, geom, str(robot.srdf))
    objects = geom.geometryObjects
    srdf_disabled = len(objects) * (len(objects) - 1) // 2 - len(geom.collisionPairs)
    pairs = []
    for k in range(len(geom.collisionPairs)):
        p = geom.collisionPairs[k]
        a, b = int(p.first), int(p.second)
        ja, jb = objects[a].parentJoint, objects[b].parentJoint
        adjacent = ja == jb or robot.model.parents[ja] == jb or robot.model.parents[jb] == ja
        if not adjacent and _moving(robot, ja) != _moving(robot, jb):
            pairs.append((a, b))
    if pairs and srdf_disabled < MIN_SRDF_PAIRS * len(objects):  # nothing to sample without candidate pairs
        pairs = _sampled_matrix(robot, pairs)
    return pairs


def _digest(value) -> str:
    return hashlib.sha256(json.dumps(value).encode()).hexdigest()


def _sampled_matrix(robot: Robot, pairs: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """Drop pairs never or always in collision over random configurations (cached)."""
    robot_sha = _digest([robot.identity, robot.joints, robot.reference.tolist()])
    stamp = {"robot_sha256": robot_sha, "candidates_sha256": _digest([list(p) for p in pairs]),
             "samples": MATRIX_SAMPLES}
    path = cache_dir() / "collision" / f"{robot.name}-{_digest([robot_sha, stamp])[:16]}.json"
    kept = read_matrix_cache(path, stamp, pairs)
    if kept is not None:
        return kept
    geom = robot.collision_model.copy()
    geom.removeAllCollisionPairs()
    for a, b in pairs:
        geom.addCollisionPair(pin.CollisionPair(a, b))
    data, gdata = robot.model.createData(), pin.GeometryData(geom)
    hits = np.zeros(len(pairs), int)
    rng = np.random.default_rng(0)
    for row in robot.to_pinocchio(robot.sample_uniform(MATRIX_SAMPLES, rng)):
        pin.computeCollisions(robot.model, data, geom, gdata, row, False)
        hits += [r.isCollision() for r in gdata.collisionResults]
    kept = [p for p, h in zip(pairs, hits) if 0 < h < MATRIX_SAMPLES]
    doc = {"robot": robot.name, "joints": robot.joints, **stamp, "pairs": [list(p) for p in kept],
           "pairs_sha256": _digest([list(p) for p in kept])}
    try:
        atomic_write_text(path, json.dumps(doc))
    except ManifoldgenError as exc:  # an unwritable cache costs time, not correctness
        warnings.warn(f"collision matrix not cached: {exc}")
    return kept


def read_matrix_cache(path: Path, stamp: dict, candidates: list[tuple[int, int]]) -> list[tuple[int, int]] | None:
    """The cached pair list at ``path`` if it was computed for ``stamp`` (robot, candidates, samples) and is
    intact; None (with a one-line notice when a file was there) otherwise."""
    if not path.exists():
        return None
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        return _stale(path, f"unreadable: {type(exc).__name__}")
    if not isinstance(doc, dict) or any(doc.get(k) != v for k, v in stamp.items()):
        return _stale(path, "made for another robot, group or pair list")
    pairs, allowed = doc.get("pairs"), {tuple(p) for p in candidates}
    if not isinstance(pairs, list) or doc.get("pairs_sha256") != _digest(pairs):
        return _stale(path, "its pair list does not match its checksum")
    if not all(isinstance(p, list) and len(p) == 2 and all(type(i) is int for i in p) and tuple(p) in allowed
               for p in pairs):
        return _stale(path, "it names pairs that are not candidate pairs of this robot")
    return [tuple(p) for p in pairs]


def _stale(path: Path, why: str) -> None:
    warnings.warn(f"collision matrix cache {path} is not valid ({why}); recomputing it")
    return None
