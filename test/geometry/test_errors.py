"""Typed input errors: each check raises its kind, every kind is a ValueError, and the bag's
rejection counting reads the kind instead of matching message text."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry import errors
from tensegrity_stiffness.geometry.quaternion import quaternion_to_rotation
from tensegrity_stiffness.geometry.screw import check_in_chart
from tensegrity_stiffness.geometry.validation import finite_array, require_frame
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes.messages import multiarray_to_array


def _model() -> JointModel:
    return JointModel.from_yaml(config.packaged_config_path())


class _Layout:
    data_offset = 0


class _Array:
    def __init__(self, data: list[float], offset: int = 0) -> None:
        self.data = data
        self.layout = _Layout()
        self.layout.data_offset = offset


@pytest.mark.parametrize(('call', 'kind'), [
    (lambda: check_in_chart([2.0 * math.pi, 0, 0, 0, 0, 0]), errors.OutsideChartError),
    (lambda: quaternion_to_rotation([0.0, 0.0, 0.0, 0.0]), errors.BadQuaternionError),
    (lambda: quaternion_to_rotation([0.0, 0.0, 0.0, 2.0]), errors.BadQuaternionError),
    (lambda: quaternion_to_rotation([math.nan, 0.0, 0.0, 1.0]), errors.BadQuaternionError),
    (lambda: finite_array('x', [1.0, math.inf]), errors.NotFiniteError),
    (lambda: require_frame('map', 'link1', 'the link-1 frame'), errors.WrongFrameError),
    (lambda: multiarray_to_array(_Array([0.0] * 5), expected_length=6),
     errors.WrongLengthError),
    (lambda: multiarray_to_array(_Array([0.0] * 10), max_length=4),
     errors.OversizedArrayError),
    (lambda: multiarray_to_array(_Array([0.0] * 2, offset=3)), errors.BadDataOffsetError),
    (lambda: _model().validate_rest_lengths(-np.ones(12)),
     errors.BadRestLengthsError),
    (lambda: _model().validate_rest_lengths([math.nan] * 12),
     errors.BadRestLengthsError),
])
def test_each_check_raises_its_kind(call, kind) -> None:
    with pytest.raises(kind) as caught:
        call()
    assert isinstance(caught.value, ValueError)
    assert errors.error_kind(caught.value) == kind.kind != errors.INVALID


def test_kinds_are_distinct_and_plain_errors_are_invalid() -> None:
    kinds = [cls.kind for cls in errors.InputError.__subclasses__()]
    assert len(kinds) == len(set(kinds)) and errors.INVALID not in kinds
    assert errors.error_kind(ValueError('anything')) == errors.INVALID
    assert errors.error_kind(RuntimeError('x')) == errors.INVALID


def test_in_context_keeps_the_kind_and_prefixes_the_text() -> None:
    inner = errors.BadQuaternionError('quaternion has zero norm')
    outer = errors.in_context(inner, 'joint 2 pose')
    assert type(outer) is errors.BadQuaternionError
    assert str(outer) == 'joint 2 pose: quaternion has zero norm'
    plain = errors.in_context(ValueError('x'), 'joint 1')
    assert type(plain) is ValueError and str(plain) == 'joint 1: x'
