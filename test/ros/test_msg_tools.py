"""tensegrity_stiffness.ros.conversions:
conversions tested by building messages directly (no rclpy.init, no node)."""

from __future__ import annotations

import array
from types import SimpleNamespace

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Point, Pose, Quaternion, Vector3, Wrench
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout
from visualization_msgs.msg import Marker

from tensegrity_stiffness.ros.conversions import (
    CARTESIAN_TWIST_COL_LABEL,
    DEFAULT_MAX_LENGTH,
    QUATERNION_UNIT_TOLERANCE,
    SCREW_COL_LABEL,
    WRENCH_ROW_LABEL,
    diagnostic_array,
    diagnostic_status,
    format_value,
    marker_array,
    matrix_to_multiarray,
    msg_to_wrench,
    multiarray_to_array,
    multiarray_to_matrix,
    pose_message_to_transform,
    quaternion_to_rotation,
    rotation_to_quaternion,
    stamp_from_nanoseconds,
    stamp_from_seconds,
    stamp_to_nanoseconds,
    stamp_to_seconds,
    tension_color,
    transform_to_pose,
    vector_to_multiarray,
    wrench_to_msg,
)

#: Tolerance of float round trips through messages (float64 all the way: exact up to rounding).
ROUND_TRIP_ATOL = 1e-12
#: Tolerance of rotation / quaternion identities.
ROTATION_ATOL = 1e-12


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """Uniform random rotation (QR of a Gaussian matrix with sign fix)."""
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q @ np.diag(np.sign(np.diag(r)))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' formula, independent of msg_tools."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def raw_multiarray(data: list[float], dims: list[tuple[str, int, int]] = (),
                   offset: int = 0) -> Float64MultiArray:
    layout = MultiArrayLayout(
        dim=[MultiArrayDimension(label=lab, size=size, stride=stride)
             for lab, size, stride in dims],
        data_offset=offset)
    return Float64MultiArray(layout=layout, data=data)


# ------------------------------------------------------------------------------------------
# Float64MultiArray
# ------------------------------------------------------------------------------------------
class TestMultiArray:
    def test_matrix_layout_and_labels(self, rng: np.random.Generator) -> None:
        K = rng.standard_normal((6, 6))
        msg = matrix_to_multiarray(K)
        assert isinstance(msg, Float64MultiArray)
        d0, d1 = msg.layout.dim
        assert d0.label == 'rows: wrench [fx fy fz mx my mz]' == WRENCH_ROW_LABEL
        assert d1.label == 'cols: screw [wx wy wz vx vy vz]' == SCREW_COL_LABEL
        assert (d0.size, d0.stride) == (6, 36)
        assert (d1.size, d1.stride) == (6, 6)
        assert msg.layout.data_offset == 0
        # row-major: M[i, j] = data[i * stride1 + j]
        assert msg.data[1 * d1.stride + 4] == K[1, 4]
        assert isinstance(msg.data, array.array)

    def test_matrix_round_trip_non_square(self, rng: np.random.Generator) -> None:
        M = rng.standard_normal((3, 5))
        msg = matrix_to_multiarray(M, 'rows: a', 'cols: b')
        assert [d.size for d in msg.layout.dim] == [3, 5]
        assert [d.stride for d in msg.layout.dim] == [15, 5]
        back = multiarray_to_matrix(msg)
        np.testing.assert_allclose(back, M, rtol=0, atol=ROUND_TRIP_ATOL)
        np.testing.assert_allclose(multiarray_to_matrix(msg, expected_shape=(3, 5)), M,
                                   rtol=0, atol=ROUND_TRIP_ATOL)

    def test_cartesian_label(self) -> None:
        msg = matrix_to_multiarray(np.eye(6), WRENCH_ROW_LABEL, CARTESIAN_TWIST_COL_LABEL)
        assert msg.layout.dim[1].label == ('cols: spatial twist in {1} [dx dy dz rx ry rz] '
                                           '(linear first, as ROS)')

    def test_vector_round_trip(self, rng: np.random.Generator) -> None:
        v = rng.standard_normal(12)
        msg = vector_to_multiarray(v, 'tensions [N]')
        (dim,) = msg.layout.dim
        assert (dim.label, dim.size, dim.stride) == ('tensions [N]', 12, 12)
        out = multiarray_to_array(msg, expected_length=12)
        np.testing.assert_allclose(out, v, rtol=0, atol=ROUND_TRIP_ATOL)
        out[0] = 99.0  # a copy, not a view of the message
        assert msg.data[0] == v[0]

    def test_empty_vector(self) -> None:
        msg = vector_to_multiarray([], 'empty')
        assert msg.layout.dim[0].size == 0
        assert multiarray_to_array(msg).shape == (0,)

    def test_data_offset_honoured(self) -> None:
        msg = raw_multiarray([9.0, 1.0, 2.0, 3.0], offset=1)
        np.testing.assert_array_equal(multiarray_to_array(msg, expected_length=3), [1, 2, 3])

    def test_matrix_from_expected_shape_without_layout(self) -> None:
        msg = raw_multiarray([1.0, 2.0, 3.0, 4.0])
        np.testing.assert_array_equal(multiarray_to_matrix(msg, expected_shape=(2, 2)),
                                      [[1, 2], [3, 4]])

    def test_wrong_length(self) -> None:
        msg = vector_to_multiarray(np.zeros(5))
        with pytest.raises(ValueError, match=r'expected 6 values, got 5'):
            multiarray_to_array(msg, expected_length=6)

    @pytest.mark.parametrize('bad', [np.nan, np.inf, -np.inf])
    def test_non_finite_rejected(self, bad: float) -> None:
        msg = raw_multiarray([0.0, bad, 1.0])
        with pytest.raises(ValueError, match='NaN or inf'):
            multiarray_to_array(msg)

    def test_oversized_rejected_before_conversion(self) -> None:
        class HugePayload:
            """Claims 10**9 elements; any access to them fails the test."""

            def __len__(self) -> int:
                return 10**9

            def __getitem__(self, index: object) -> float:
                raise AssertionError('payload converted before the length check')

            def __iter__(self) -> None:
                raise AssertionError('payload converted before the length check')

            def __array__(self, *args: object, **kwargs: object) -> None:
                raise AssertionError('payload converted before the length check')

        msg = SimpleNamespace(layout=MultiArrayLayout(), data=HugePayload())
        with pytest.raises(ValueError, match=r'too many elements: 1000000000 > max_length 10'):
            multiarray_to_array(msg, max_length=10)

    def test_default_max_length(self) -> None:
        msg = raw_multiarray([0.0] * (DEFAULT_MAX_LENGTH + 1))
        with pytest.raises(ValueError, match='too many elements'):
            multiarray_to_array(msg)

    def test_offset_beyond_data(self) -> None:
        with pytest.raises(ValueError, match='data_offset 4 exceeds'):
            multiarray_to_array(raw_multiarray([1.0, 2.0], offset=4))

    def test_matrix_layout_errors(self) -> None:
        with pytest.raises(ValueError, match='layout must have 2 dimensions, got 1'):
            multiarray_to_matrix(vector_to_multiarray(np.zeros(4)))
        bad_strides = raw_multiarray([0.0] * 4, [('r', 2, 4), ('c', 2, 3)])
        with pytest.raises(ValueError, match='not those of a dense row-major 2x2'):
            multiarray_to_matrix(bad_strides)
        with pytest.raises(ValueError, match=r'expected shape \(6, 6\), got \(2, 3\)'):
            multiarray_to_matrix(matrix_to_multiarray(np.zeros((2, 3))), expected_shape=(6, 6))
        with pytest.raises(ValueError, match='no dimensions and no expected_shape'):
            multiarray_to_matrix(raw_multiarray([1.0]))
        short = raw_multiarray([0.0] * 3, [('r', 2, 4), ('c', 2, 2)])
        with pytest.raises(ValueError, match='expected 4 values, got 3'):
            multiarray_to_matrix(short)

    def test_builder_input_errors(self) -> None:
        with pytest.raises(ValueError, match=r'matrix must be 2-D, got shape \(6,\)'):
            matrix_to_multiarray(np.zeros(6))
        with pytest.raises(ValueError, match=r'vector must be 1-D, got shape \(2, 2\)'):
            vector_to_multiarray(np.zeros((2, 2)))
        with pytest.raises(ValueError, match='matrix contains NaN or inf'):
            matrix_to_multiarray(np.full((2, 2), np.nan))
        with pytest.raises(ValueError, match='vector contains NaN or inf'):
            vector_to_multiarray([1.0, np.inf])
        with pytest.raises(ValueError, match='vector must be numeric'):
            vector_to_multiarray(['a', 'b'])


# ------------------------------------------------------------------------------------------
# Wrench
# ------------------------------------------------------------------------------------------
class TestWrench:
    def test_round_trip_and_order(self) -> None:
        F = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
        msg = wrench_to_msg(F)
        assert (msg.force.x, msg.force.y, msg.force.z) == (1.0, 2.0, 3.0)
        assert (msg.torque.x, msg.torque.y, msg.torque.z) == (4.0, 5.0, 6.0)
        np.testing.assert_array_equal(msg_to_wrench(msg), F)

    def test_errors(self) -> None:
        with pytest.raises(ValueError, match=r'wrench must have shape \(6,\), got \(3,\)'):
            wrench_to_msg([1.0, 2.0, 3.0])
        with pytest.raises(ValueError, match='wrench contains NaN or inf'):
            wrench_to_msg([0, 0, np.nan, 0, 0, 0])
        bad = Wrench(force=Vector3(x=np.inf), torque=Vector3())
        with pytest.raises(ValueError, match='wrench contains NaN or inf'):
            msg_to_wrench(bad)


# ------------------------------------------------------------------------------------------
# Rotations, quaternions, poses
# ------------------------------------------------------------------------------------------
class TestRotation:
    def test_known_quaternions(self) -> None:
        np.testing.assert_allclose(rotation_to_quaternion(np.eye(3)), [0, 0, 0, 1],
                                   atol=ROTATION_ATOL)
        s = np.sqrt(0.5)
        np.testing.assert_allclose(rotation_to_quaternion(axis_angle([0, 0, 1], np.pi / 2)),
                                   [0, 0, s, s], atol=ROTATION_ATOL)
        np.testing.assert_allclose(quaternion_to_rotation([s, 0, 0, s]),
                                   axis_angle([1, 0, 0], np.pi / 2), atol=ROTATION_ATOL)

    def test_round_trip_random(self, rng: np.random.Generator) -> None:
        for _ in range(200):
            R = random_rotation(rng)
            q = rotation_to_quaternion(R)
            assert q[3] >= 0.0
            assert abs(np.linalg.norm(q) - 1.0) < ROTATION_ATOL
            np.testing.assert_allclose(quaternion_to_rotation(q), R, atol=ROTATION_ATOL)

    @pytest.mark.parametrize('axis', [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, -1], [1, 1, 1],
                                      [0.3, -0.2, 0.9]])
    @pytest.mark.parametrize('angle', [np.pi, np.pi - 1e-9, 1e-9, 0.0, 2.5])
    def test_near_pi_and_identity(self, axis: list[float], angle: float) -> None:
        """Shepperd's pivoting keeps full accuracy near rotations by pi (w -> 0)."""
        R = axis_angle(np.asarray(axis, dtype=float), angle)
        q = rotation_to_quaternion(R)
        k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
        expected = np.append(np.sin(angle / 2) * k, np.cos(angle / 2))
        if expected[3] < 0 or (expected[3] == 0 and q @ expected < 0):
            expected = -expected
        if abs(expected[3]) < 1e-12:  # at exactly pi both signs are the same rotation
            expected = expected * np.sign(q @ expected)
        np.testing.assert_allclose(q, expected, atol=ROTATION_ATOL)

    def test_rotation_errors(self) -> None:
        with pytest.raises(ValueError, match=r'rotation must have shape \(3, 3\)'):
            rotation_to_quaternion(np.eye(4))
        with pytest.raises(ValueError, match='rotation contains NaN or inf'):
            rotation_to_quaternion(np.full((3, 3), np.nan))
        with pytest.raises(ValueError, match='not orthonormal'):
            rotation_to_quaternion(2.0 * np.eye(3))
        with pytest.raises(ValueError, match='det < 0'):
            rotation_to_quaternion(np.diag([1.0, 1.0, -1.0]))

    def test_quaternion_errors(self) -> None:
        with pytest.raises(ValueError, match='quaternion contains NaN or inf'):
            quaternion_to_rotation([np.nan, 0, 0, 1])
        with pytest.raises(ValueError, match='quaternion has zero norm'):
            quaternion_to_rotation([0, 0, 0, 0])
        with pytest.raises(ValueError, match='not a unit quaternion'):
            quaternion_to_rotation([0, 0, 0, 2.0])
        with pytest.raises(ValueError, match=r'quaternion must have shape \(4,\)'):
            quaternion_to_rotation([0, 0, 1])


def make_pose(p: tuple[float, float, float], q: tuple[float, float, float, float]) -> Pose:
    return Pose(position=Point(x=p[0], y=p[1], z=p[2]),
                orientation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]))


class TestPose:
    def test_round_trip(self, rng: np.random.Generator) -> None:
        for _ in range(50):
            T = np.eye(4)
            T[:3, :3] = random_rotation(rng)
            T[:3, 3] = rng.standard_normal(3)
            pose = transform_to_pose(T)
            np.testing.assert_allclose(pose_message_to_transform(pose), T, atol=ROTATION_ATOL)

    def test_default_pose_is_identity(self) -> None:
        np.testing.assert_array_equal(pose_message_to_transform(Pose()), np.eye(4))

    def test_mild_renormalisation(self) -> None:
        s = 0.7071  # hand-typed sqrt(1/2): norm 0.99999... within the tolerance
        T = pose_message_to_transform(make_pose((1.0, 2.0, 3.0), (0.0, 0.0, s, s)))
        np.testing.assert_allclose(T[:3, :3], axis_angle([0, 0, 1], np.pi / 2), atol=1e-12)
        np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12)
        np.testing.assert_array_equal(T[:3, 3], [1.0, 2.0, 3.0])

    def test_tolerance_keyword(self) -> None:
        q = (0.0, 0.0, 0.0, 1.0 + 10 * QUATERNION_UNIT_TOLERANCE)
        with pytest.raises(ValueError, match='not a unit quaternion'):
            pose_message_to_transform(make_pose((0, 0, 0), q))
        T = pose_message_to_transform(make_pose((0, 0, 0), q), unit_tolerance=0.1)
        np.testing.assert_allclose(T, np.eye(4), atol=ROTATION_ATOL)
        with pytest.raises(ValueError, match='not a unit quaternion'):
            pose_message_to_transform(make_pose((0, 0, 0), (0.0, 0.0, 0.0, 1.0 + 1e-6)),
                              unit_tolerance=1e-8)

    @pytest.mark.parametrize(('q', 'match'), [
        ((np.nan, 0.0, 0.0, 1.0), 'quaternion contains NaN or inf'),
        ((0.0, 0.0, 0.0, np.inf), 'quaternion contains NaN or inf'),
        ((0.0, 0.0, 0.0, 0.0), 'quaternion has zero norm'),
        ((0.0, 0.0, 0.5, 0.5), 'not a unit quaternion'),
    ])
    def test_orientation_errors(self, q: tuple[float, ...], match: str) -> None:
        with pytest.raises(ValueError, match=match):
            pose_message_to_transform(make_pose((0.0, 0.0, 0.0), q))

    def test_position_error(self) -> None:
        with pytest.raises(ValueError, match='pose position contains NaN or inf'):
            pose_message_to_transform(make_pose((np.nan, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)))

    def test_transform_errors(self) -> None:
        with pytest.raises(ValueError, match=r'transform must have shape \(4, 4\)'):
            transform_to_pose(np.eye(3))
        T = np.eye(4)
        T[3, 0] = 1.0
        with pytest.raises(ValueError, match=r'last row must be \[0 0 0 1\]'):
            transform_to_pose(T)
        T = np.eye(4)
        T[0, 0] = 1.1
        with pytest.raises(ValueError, match='not orthonormal'):
            transform_to_pose(T)
        with pytest.raises(ValueError, match='transform contains NaN or inf'):
            transform_to_pose(np.full((4, 4), np.inf))


# ------------------------------------------------------------------------------------------
# Stamps
# ------------------------------------------------------------------------------------------
class TestStamps:
    def test_nanoseconds_round_trip(self) -> None:
        ns = 1_700_000_000_123_456_789
        stamp = stamp_from_nanoseconds(ns)
        assert isinstance(stamp, Time)
        assert (stamp.sec, stamp.nanosec) == (1_700_000_000, 123_456_789)
        assert stamp_to_nanoseconds(stamp) == ns

    def test_seconds(self) -> None:
        stamp = stamp_from_seconds(12.5)
        assert (stamp.sec, stamp.nanosec) == (12, 500_000_000)
        assert stamp_to_seconds(stamp) == 12.5
        assert stamp_from_seconds(0.9999999999).sec == 1  # rounds to the nanosecond, carries

    def test_errors(self) -> None:
        with pytest.raises(ValueError, match='stamp must be non-negative'):
            stamp_from_nanoseconds(-1)
        with pytest.raises(ValueError, match='exceeds the int32 range'):
            stamp_from_nanoseconds(2**31 * 1_000_000_000)
        with pytest.raises(ValueError, match='stamp must be finite'):
            stamp_from_seconds(float('nan'))


# ------------------------------------------------------------------------------------------
# Diagnostics
# ------------------------------------------------------------------------------------------
class TestDiagnostics:
    def test_status(self) -> None:
        status = diagnostic_status(
            'tensegrity_stiffness: equilibrium', 'warn', 'residual high',
            {'residual': 1.23456789e-3, 'stable': True, 'iterations': 7,
             'screw': np.array([0.0, 1.5])},
            hardware_id='joint1')
        assert status.level == DiagnosticStatus.WARN
        assert status.name == 'tensegrity_stiffness: equilibrium'
        assert status.hardware_id == 'joint1'
        assert [(kv.key, kv.value) for kv in status.values] == [
            ('residual', '0.00123457'), ('stable', 'true'), ('iterations', '7'),
            ('screw', '[0 1.5]')]

    @pytest.mark.parametrize(('level', 'expected'), [
        ('OK', DiagnosticStatus.OK), ('error', DiagnosticStatus.ERROR),
        (3, DiagnosticStatus.STALE), (np.int64(1), DiagnosticStatus.WARN),
        (DiagnosticStatus.ERROR, DiagnosticStatus.ERROR)])
    def test_levels(self, level: object, expected: bytes) -> None:
        assert diagnostic_status('n', level, 'm').level == expected

    @pytest.mark.parametrize(('level', 'match'), [
        ('FATAL', "invalid diagnostic level 'FATAL'"), (4, 'invalid diagnostic level 4'),
        (b'\x07', 'invalid diagnostic level'), (True, 'invalid diagnostic level'),
        (1.0, 'invalid diagnostic level')])
    def test_level_errors(self, level: object, match: str) -> None:
        with pytest.raises(ValueError, match=match):
            diagnostic_status('n', level, 'm')

    def test_pairs_keep_order_and_array(self) -> None:
        status = diagnostic_status('n', 0, 'm', [('b', 'x'), ('a', float('nan'))])
        assert [(kv.key, kv.value) for kv in status.values] == [('b', 'x'), ('a', 'nan')]
        arr = diagnostic_array([status], Time(sec=3, nanosec=4), 'link1')
        assert arr.header.stamp == Time(sec=3, nanosec=4)
        assert arr.header.frame_id == 'link1'
        assert list(arr.status) == [status]
        assert format_value([1, 2.0]) == '[1 2]'


# ------------------------------------------------------------------------------------------
# Markers
# ------------------------------------------------------------------------------------------
P1 = np.array([[0.0, 0.0, 0.0], [0.03, 0.0, 0.0], [0.0, 0.03, 0.0]])
P2 = np.array([[0.0, 0.0, 0.05], [0.03, 0.0, 0.05]])
CONN = np.array([[0, 0], [1, 1], [2, 0], [2, 1]])


class TestMarkers:
    def make(self, tensions: list[float] | None = None, slack: list[bool] | None = None,
             **kwargs: object) -> list[Marker]:
        tensions = [1.0, 2.0, 4.0, 0.0] if tensions is None else tensions
        slack = [False, False, False, True] if slack is None else slack
        out = marker_array(P1, P2, CONN, tensions, slack, 'link1', Time(sec=5, nanosec=6),
                           **kwargs)
        return list(out.markers)

    def test_structure(self) -> None:
        nodes1, nodes2, strings, slack = self.make()
        assert [m.ns for m in (nodes1, nodes2, strings, slack)] == [
            'link1_nodes', 'link2_nodes', 'strings', 'slack_strings']
        for m in (nodes1, nodes2, strings, slack):
            assert m.header.frame_id == 'link1'
            assert m.header.stamp == Time(sec=5, nanosec=6)
            assert m.action == Marker.ADD
            assert m.pose.orientation.w == 1.0
        assert nodes1.type == nodes2.type == Marker.SPHERE_LIST
        assert strings.type == slack.type == Marker.LINE_LIST
        assert len(nodes1.points) == 3 and len(nodes2.points) == 2
        assert (nodes2.points[1].x, nodes2.points[1].z) == (0.03, 0.05)
        assert len(strings.points) == 6 and len(strings.colors) == 6
        assert len(slack.points) == 2 and not slack.colors
        # string 3 is slack: from p1[2] to p2[1]
        assert (slack.points[0].y, slack.points[1].x) == (0.03, 0.03)
        assert slack.scale.x < strings.scale.x
        assert slack.color.r == slack.color.g == slack.color.b  # grey

    def test_tension_colours(self) -> None:
        _, _, strings, _ = self.make()
        reds = [c.r for c in strings.colors[::2]]
        blues = [c.b for c in strings.colors[::2]]
        assert reds == pytest.approx([0.25, 0.5, 1.0])  # t / max(t) with max = 4 N
        assert blues[0] > blues[1] > blues[2] == 0.0
        assert strings.colors[0] == strings.colors[1]  # both vertices of one string
        _, _, fixed, _ = self.make(max_tension=8.0)
        assert [c.r for c in fixed.colors[::2]] == pytest.approx([0.125, 0.25, 0.5])
        assert tension_color(2.0) == tension_color(1.0)  # clipped

    def test_all_slack_and_all_taut(self) -> None:
        _, _, strings, slack = self.make(tensions=[0.0] * 4, slack=[True] * 4)
        assert not strings.points and len(slack.points) == 8
        _, _, strings, slack = self.make(tensions=[0.0] * 4, slack=[False] * 4)
        assert len(strings.points) == 8 and not slack.points
        assert all(c.b > 0.9 for c in strings.colors)  # zero tension: blue, no division by 0

    @pytest.mark.parametrize(('kwargs', 'match'), [
        ({'p1': np.zeros((3, 2))}, r'p1 must have shape \(n, 3\)'),
        ({'p2': np.full((2, 3), np.nan)}, 'p2 contains NaN or inf'),
        ({'connections': np.zeros(4, dtype=int)}, r'connections must have shape \(n, 2\)'),
        ({'connections': CONN.astype(float)}, 'connections must be integer'),
        ({'connections': CONN + [[3, 0]] * 4}, r'connections\[:, 0\] must index p1'),
        ({'connections': CONN + [[0, 2]] * 4}, r'connections\[:, 1\] must index p2'),
        ({'tensions': [1.0, 2.0]}, r'tensions must have shape \(4,\)'),
        ({'tensions': [1.0, np.nan, 0.0, 0.0]}, 'tensions contains NaN or inf'),
        ({'tensions': [1.0, -2.0, 0.0, 0.0]}, 'tensions must be >= 0'),
        ({'slack': [True]}, r'slack must have shape \(4,\)'),
        ({'max_tension': 0.0}, 'max_tension must be finite and > 0'),
    ])
    def test_errors(self, kwargs: dict[str, object], match: str) -> None:
        args: dict[str, object] = {
            'p1': P1, 'p2': P2, 'connections': CONN, 'tensions': [1.0, 2.0, 4.0, 0.0],
            'slack': [False, False, False, True], 'frame_id': 'link1', 'stamp': Time()}
        args.update(kwargs)
        with pytest.raises(ValueError, match=match):
            marker_array(**args)
