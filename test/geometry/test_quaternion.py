"""tensegrity_stiffness.geometry.quaternion:
the pure-numpy pose rule shared by the node and the CLI."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tensegrity_stiffness.geometry.quaternion import (
    QUATERNION_UNIT_TOLERANCE,
    quaternion_to_rotation,
    rotation_to_quaternion,
    rotation_to_quaternion_unchecked,
)
from tensegrity_stiffness.geometry.screw import exp_so3


def test_round_trip_against_scipy_including_half_turns():
    rng = np.random.default_rng(3)
    rotations = list(Rotation.random(500, random_state=4))
    axes = rng.normal(size=(50, 3))
    rotations += [Rotation.from_rotvec(np.pi * a / np.linalg.norm(a)) for a in axes]
    for rot in rotations:
        q_ref = rot.as_quat()  # scipy uses [x y z w] too
        R = quaternion_to_rotation(q_ref)
        np.testing.assert_allclose(R, rot.as_matrix(), atol=1e-15)
        q = rotation_to_quaternion(R)
        assert q[3] >= 0.0 and abs(np.linalg.norm(q) - 1.0) < 1e-15
        # Same rotation (q and -q are one rotation).
        assert min(np.abs(q - q_ref).max(), np.abs(q + q_ref).max()) < 1e-14


def test_renormalised_within_the_tolerance_rejected_beyond():
    q = np.array([0.0, 0.0, np.sin(0.3), np.cos(0.3)])
    R = quaternion_to_rotation(q * (1.0 + 0.5 * QUATERNION_UNIT_TOLERANCE))
    np.testing.assert_allclose(R, Rotation.from_quat(q).as_matrix(), atol=1e-15)
    with pytest.raises(ValueError, match='not a unit quaternion'):
        quaternion_to_rotation(q * (1.0 + 2.0 * QUATERNION_UNIT_TOLERANCE))


@pytest.mark.parametrize(('value', 'match'), [
    ([0.0, 0.0, 0.0, 0.0], 'zero norm'),
    ([np.nan, 0.0, 0.0, 1.0], 'quaternion contains NaN or inf'),
    ([0.0, 0.0, 1.0], r'quaternion must have shape \(4,\)'),
    ('abcd', 'quaternion must be numeric'),
])
def test_bad_quaternions_raise_naming_the_problem(value, match):
    with pytest.raises(ValueError, match=match):
        quaternion_to_rotation(value)


@pytest.mark.parametrize(('R', 'match'), [
    (np.diag([1.0, 1.0, -1.0]), 'det < 0'),
    (2.0 * np.eye(3), 'not orthonormal'),
    (np.eye(4), r'rotation must have shape \(3, 3\)'),
])
def test_bad_rotations_raise_naming_the_problem(R, match):
    with pytest.raises(ValueError, match=match):
        rotation_to_quaternion(R)


def test_unchecked_conversion_equals_the_checked_one():
    """The publishers' float path gives the checked conversion's quaternion (every pivot of
    Shepperd's method, rotations by pi included)."""
    rng = np.random.default_rng(5)
    pivots = set()
    for i in range(400):
        w = rng.normal(size=3)
        w *= (math.pi if i % 4 == 0 else rng.uniform(0.0, math.pi)) / np.linalg.norm(w)
        R = exp_so3(w)
        pivots.add(int(np.argmax([np.trace(R), *np.diag(R)])))
        q = rotation_to_quaternion_unchecked(R)
        np.testing.assert_allclose(q, rotation_to_quaternion(R), rtol=0.0, atol=1e-15)
        assert q[3] >= 0.0
    assert pivots == {0, 1, 2, 3}
