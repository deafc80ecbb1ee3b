"""Estimation: sensor models (:mod:`.sensor_models`), the estimators of pose, load and stiffness
with covariance (:mod:`.estimators`, re-exported here: ``tensegrity_stiffness.estimation`` is
the documented path), the recursive filters on the dynamics of a joint (:mod:`.joint_filter`)
and of a spine (:mod:`.chain_filter`), re-exported too, and the calibration of each string from
a recording (:mod:`.calibration`).

May import: :mod:`tensegrity_stiffness.mechanics`, :mod:`tensegrity_stiffness.geometry`,
:mod:`tensegrity_stiffness.config`, numpy, scipy.
"""

from tensegrity_stiffness.estimation.chain_filter import *  # noqa: F403
from tensegrity_stiffness.estimation.chain_filter import __all__ as chain_filter_names
from tensegrity_stiffness.estimation.estimators import *  # noqa: F403
from tensegrity_stiffness.estimation.estimators import __all__ as estimator_names
from tensegrity_stiffness.estimation.joint_filter import *  # noqa: F403
from tensegrity_stiffness.estimation.joint_filter import __all__ as filter_names
from tensegrity_stiffness.estimation.structure_estimator import estimate_structure_poses

__all__ = [*estimator_names, *filter_names, *chain_filter_names, 'estimate_structure_poses']
