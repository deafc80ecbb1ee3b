"""``principal_stiffnesses``: the eigenvalues of the symmetric parts of a Cartesian stiffness's
translational and rotational blocks, each ascending (what the viewers plot)."""

from __future__ import annotations

import numpy as np
import pytest
from support import REPO

from tensegrity_stiffness.geometry.screw import exp_so3
from tensegrity_stiffness.mechanics.interpretation import principal_stiffnesses
from tensegrity_stiffness.mechanics.joint import JointModel


def test_the_blocks_principal_values_in_any_axes() -> None:
    R, Q = exp_so3([0.3, -0.2, 0.9]), exp_so3([-1.1, 0.4, 0.2])
    K = np.zeros((6, 6))
    K[:3, :3] = R @ np.diag([300.0, 100.0, 200.0]) @ R.T
    K[3:, 3:] = Q @ np.diag([0.02, 0.05, 0.01]) @ Q.T
    K[:3, 3:] = [[1.0, 2.0, 3.0]] * 3  # coupling and an antisymmetric part change nothing
    K[:3, :3] += [[0.0, 5.0, 0.0], [-5.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
    np.testing.assert_allclose(principal_stiffnesses(K),
                               [100.0, 200.0, 300.0, 0.01, 0.02, 0.05], rtol=1e-12)


def test_the_default_joint_is_stiff_in_every_direction_at_rest() -> None:
    model = JointModel.from_yaml(REPO / 'config' / 'default_joint.yaml')
    values = principal_stiffnesses(model.evaluate(model.initial_screw).cartesian_stiffness)
    assert np.all(values > 0.0) and np.all(np.diff(values[:3]) >= 0)
    with pytest.raises(ValueError, match=r'shape \(6, 6\)'):
        principal_stiffnesses(np.eye(3))
