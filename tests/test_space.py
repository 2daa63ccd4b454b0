"""The validity rule on known cases: limits, tolerance, the margin of intermediate states,
inequalities, collisions (checked last, in order), and dense path validation."""

from __future__ import annotations

import numpy as np
import pytest

from manifoldgen.errors import ManifoldgenError
from manifoldgen.space import ConstrainedSpace, ValidationSettings
from planning_problems import BoxChecker, SphereConstraint


class UpperSphere(SphereConstraint):
    """The unit sphere's upper half: |q| = 1 and G = -z <= 0."""

    def inequality(self, q, y):
        q, y = self.batch(q, y)
        return -q[:, 2:3]


class CountingChecker(BoxChecker):
    """A box checker that remembers which rows it was asked about."""

    def __init__(self, boxes):
        super().__init__(boxes)
        self.asked = []

    def in_collision(self, q):
        self.asked.extend(np.atleast_2d(q).tolist())
        return super().in_collision(q)

    def first_collision(self, q):
        hits = np.flatnonzero(BoxChecker.in_collision(self, q))
        stop = int(hits[0]) if len(hits) else len(q)
        self.asked.extend(np.atleast_2d(q)[:stop + 1].tolist())
        return stop


BOX = ([0.9, -0.1, -0.1], [1.1, 0.1, 0.1])  # around (1, 0, 0)


def _at(radius, polar):
    """Points (B, 3) in the x-z plane at ``radius`` and polar angles from +x toward +z."""
    polar = np.atleast_1d(polar)
    return radius * np.stack([np.cos(polar), np.zeros_like(polar), np.sin(polar)], axis=1)


def test_tolerance_limits_inequality_and_collision_in_order():
    checker = CountingChecker([BOX])
    space = ConstrainedSpace(UpperSphere(), [1.0], checker)
    q = np.concatenate([_at(1.009, 0.5), _at(1.011, 0.5), _at(1.0, -0.5), _at(1.0, 0.0),
                        [[2.5, 0.0, 0.0]]])
    assert space.valid(q).tolist() == [True, False, False, False, False]
    # only the rows that passed limits, tolerance and inequality were checked for collision
    assert checker.asked == q[[0, 3]].tolist() and space.collision_checks == 2
    assert space.valid(q[2:3], equality=False).tolist() == [False]  # the inequality still holds
    assert space.valid(_at(1.2, 0.5), equality=False).tolist() == [True]
    problems = [space.problem(row) for row in q]
    assert problems[0] is None
    assert problems[1].startswith("violates the constraint: residual component 0 is 0.011, 1.10 times")
    assert problems[2].startswith("violates inequality 0 of the constraint by 0.479")
    assert problems[3] == "is in collision: point with box0"
    assert problems[4] == "outside the joint limits: x = 2.5000 not in [-2.0000, 2.0000]"


def test_intermediate_states_keep_the_margin_nodes_the_tolerance():
    space = ConstrainedSpace(SphereConstraint(), [1.0], settings=ValidationSettings(margin=0.05))
    states = np.concatenate([_at(1.0, 0.1), _at(1.0097, 0.2), _at(1.009, 0.3)])
    # violations 0, 0.97, 0.9: the second needs the margin (0.97 > 0.95)
    assert space.valid_prefix(states, last_is_node=True) == 1 and space.stop == "constraint"
    node = states[[0, 2]]  # violation 0.9 at the end: fine as a node and as an intermediate state
    assert space.valid_prefix(node, last_is_node=False) == 2 and space.stop is None
    end = _at(1.0097, 0.4)  # violation 0.97 at the end: a node may have it, an intermediate state not
    assert space.valid_prefix(end, last_is_node=True) == 1
    assert space.valid_prefix(end, last_is_node=False) == 0
    assert space.stopped == {"limits": 0, "constraint": 2, "inequality": 0, "collision": 0}
    loose = ConstrainedSpace(SphereConstraint(), [1.0], settings=ValidationSettings(margin=0.0))
    assert loose.valid_prefix(end, last_is_node=False) == 1


def test_a_motion_stops_at_its_first_collision():
    checker = CountingChecker([BOX])
    space = ConstrainedSpace(SphereConstraint(), [1.0], checker)
    states = _at(1.0, np.linspace(0.6, -0.6, 13))  # through the box around polar angle 0
    count = space.valid_prefix(states, last_is_node=True)
    assert count == 5 and np.all(np.abs(states[:count, 2]) > 0.1) and abs(states[count, 2]) <= 0.1
    assert len(checker.asked) == count + 1 and space.collision_checks == count + 1
    assert space.stop == "collision" and space.stopped["collision"] == 1


def test_first_valid_piece_skips_invalid_pieces_and_counts_why():
    space = ConstrainedSpace(SphereConstraint(), [1.0], BoxChecker([BOX]))
    off = _at(1.2, [1.0, 1.1])  # off the sphere
    hit = _at(1.0, [0.1, 0.0])  # into the box
    good = _at(1.0, [1.3, 1.4])
    assert space.first_valid_piece([off, hit, good, off]) == 2
    assert space.stopped == {"limits": 0, "constraint": 1, "inequality": 0, "collision": 1}
    assert space.first_valid_piece([off, hit]) == -1 and space.stop == "collision"


def test_validate_path_finds_the_first_bad_segment():
    space = ConstrainedSpace(SphereConstraint(), [1.0], BoxChecker([BOX]))
    # segment 0 follows the sphere closely (short chord), segment 1 crosses the box, segment 2 is a long chord
    path = _at(1.0, [0.3, 0.15, -0.1, -1.5])
    report = space.validate_path(path)
    assert not report.valid and report.segment == 1 and report.reason.startswith("segment 1: is in collision")
    assert report.resolution == 0.005 and report.states_checked > 10
    assert space.validate_path(path[:2]).valid
    chord = space.validate_path(_at(1.0, [0.8, 2.4]))
    assert not chord.valid and chord.segment == 0 and "violates the constraint" in chord.reason
    assert chord.worst_violation > 1
    coarse = ConstrainedSpace(SphereConstraint(), [1.0], settings=ValidationSettings(resolution=0.05))
    report = coarse.validate_path(path[:2])
    assert report.valid and report.resolution == 0.05 and report.to_dict()["resolution"] == 0.05
    assert "shape" in space.validate_path(np.zeros((2, 4))).reason
    assert "NaN" in space.validate_path(np.full((2, 3), np.nan)).reason


def test_query_states_and_settings_are_checked():
    space = ConstrainedSpace(SphereConstraint(), [1.0], BoxChecker([BOX]))
    assert np.allclose(space.check_query_state(_at(1.0, 1.0)[0], "start"), _at(1.0, 1.0)[0])
    with pytest.raises(ManifoldgenError, match="goal configuration is in collision: point with box0; choose a "
                                               "collision-free goal"):
        space.check_query_state(_at(1.0, 0.0)[0], "goal")
    with pytest.raises(ManifoldgenError, match="start must be 3 finite joint values"):
        space.check_query_state(np.zeros(2), "start")
    for resolution in (0.0, 1e-300, 100.0, float("nan")):
        with pytest.raises(ManifoldgenError, match=r"resolution in \[1e-05, 0.05\] rad and 0 <= margin < 1"):
            ValidationSettings(resolution=resolution)
    with pytest.raises(ManifoldgenError, match="0 <= margin < 1"):
        ValidationSettings(margin=1.0)
    assert space.counts()["evaluations"] > 0
