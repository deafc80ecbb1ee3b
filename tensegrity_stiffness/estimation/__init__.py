"""Estimation: sensor models (:mod:`.sensor_models`), the estimators of pose, load and stiffness
with covariance (:mod:`.estimators`), the recursive filters on the dynamics of a joint
(:mod:`.joint_filter`) and of a spine (:mod:`.chain_filter`), the calibration of each string from
a recording (:mod:`.calibration`, :mod:`.structure_calibration`) and the poses of a structure
(:mod:`.structure_estimator`).

Import the modules (``from tensegrity_stiffness.estimation.joint_filter import JointFilter``).
This ``__init__`` imports none of them: the names it used to re-export
(``from tensegrity_stiffness.estimation import JointFilter``) still work, imported on first use,
with a DeprecationWarning naming the module (:class:`tensegrity_stiffness.deprecation.MovedNames`).

May import: :mod:`tensegrity_stiffness.mechanics`, :mod:`tensegrity_stiffness.geometry`,
:mod:`tensegrity_stiffness.config`, numpy, scipy.
"""

from tensegrity_stiffness.deprecation import MovedNames

__getattr__ = MovedNames(__name__, {'estimators': None, 'joint_filter': None, 'chain_filter': None,
                                    'structure_estimator': ('estimate_structure_poses',)})
