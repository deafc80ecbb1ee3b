"""Estimation: sensor models (:mod:`.sensor_models`), the estimators of pose, load and stiffness
with covariance (:mod:`.estimators`, re-exported here: ``tensegrity_stiffness.estimation`` is
the documented path) and the calibration of each string from a recording (:mod:`.calibration`).

May import: :mod:`tensegrity_stiffness.mechanics`, :mod:`tensegrity_stiffness.geometry`,
:mod:`tensegrity_stiffness.config`, numpy, scipy.
"""

from tensegrity_stiffness.estimation.estimators import *  # noqa: F403
from tensegrity_stiffness.estimation.estimators import __all__  # noqa: F401
from tensegrity_stiffness.estimation.structure_estimator import estimate_structure_poses  # noqa: F401
