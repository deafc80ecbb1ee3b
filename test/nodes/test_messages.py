"""tensegrity_stiffness.nodes.messages: the nodes' output messages built from the layouts of
tensegrity_stiffness.nodes.layouts with rclpy's classes (tensegrity_stiffness.ros.conversions, the
nodes) and with rosbags' types (the bag command) serialize to the same bytes; the readers and the
pose writer check as before."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from tensegrity_stiffness import config
from tensegrity_stiffness.mechanics.chain import DEFAULT_SPINE_CONFIG, JointChain
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes import layouts, messages, processing, spine_processing

rosbags_typesys = pytest.importorskip('rosbags.typesys')
serialization = pytest.importorskip('rclpy.serialization')
conversions = pytest.importorskip('tensegrity_stiffness.ros.conversions')

TYPESTORE = pytest.importorskip('tensegrity_stiffness.recordings.bag').jazzy_typestore()
STAMP_NS = 1_700_000_123_456_789_012


def rosbags_types() -> messages.MessageTypes:
    from tensegrity_stiffness.recordings import bag

    return bag.rosbags_types(TYPESTORE)


def same_bytes(rclpy_msg: Any, rosbags_msg: Any, msgtype: str) -> bool:
    """rclpy's serialization, read and written again by rosbags (Fast CDR leaves padding bytes
    unset, rosbags zeroes them), equals rosbags' serialization."""
    theirs = TYPESTORE.deserialize_cdr(bytes(serialization.serialize_message(rclpy_msg)),
                                       msgtype)
    return bytes(TYPESTORE.serialize_cdr(theirs, msgtype)) == bytes(
        TYPESTORE.serialize_cdr(rosbags_msg, msgtype))


def test_joint_messages_of_rclpy_and_rosbags_are_the_same() -> None:
    model = JointModel.from_yaml(config.packaged_config_path())
    outputs = processing.joint_outputs(model, model.initial_screw + 0.02)
    node = conversions.JointOutputMessages(tuple(model.string_names))
    offline = messages.JointOutputMessages(model.string_names, rosbags_types())
    node.fill(outputs, conversions.stamp_from_nanoseconds(STAMP_NS), 'link_a')
    offline.fill(outputs, offline.types.time(STAMP_NS), 'link_a')
    found = layouts.joint_output_layouts(model.string_names)
    assert list(found) == ['wrench', 'stiffness', 'cartesian_stiffness', 'string_tensions',
                           'stiffness_interpretation', 'stiffness_stamped',
                           'cartesian_stiffness_stamped']
    arrays = processing.output_arrays(outputs)
    for (name, layout), mine, theirs, k in zip(
            found.items(), offline.messages(), node.messages(), node.array_index, strict=True):
        assert arrays[k].size == layout.size, name
        assert same_bytes(theirs, mine, layout.msgtype), name
    assert node.wrench.header.frame_id == 'link_a'
    # #39: the stamped K and K_c carry the input's stamp, the frame, labels and row-major data
    for stamped, of, matrix in ((node.stiffness_stamped, node.stiffness, outputs.state.stiffness),
                                (node.cartesian_stiffness_stamped, node.cartesian_stiffness,
                                 outputs.state.cartesian_stiffness)):
        assert messages.stamp_nanoseconds(stamped.header.stamp) == STAMP_NS
        assert stamped.header.frame_id == 'link_a'
        assert (stamped.rows, stamped.cols) == (6, 6)
        assert [stamped.row_label, stamped.column_label] == [d.label for d in of.layout.dim]
        np.testing.assert_array_equal(np.asarray(stamped.data).reshape(6, 6), matrix)
    assert [d.label for d in node.tensions.layout.dim] == [
        layouts.tensions_label(model.string_names)]


def test_spine_messages_of_rclpy_and_rosbags_are_the_same() -> None:
    chain = JointChain.from_yaml(config.packaged_config_path(DEFAULT_SPINE_CONFIG))
    xi = np.array([m.initial_screw for m in chain.joints]) + 0.01
    outputs = spine_processing.spine_outputs(chain, xi)
    node = conversions.SpineOutputMessages(chain.n_joints, 'tool')
    offline = messages.SpineOutputMessages(chain.n_joints, rosbags_types(), 'tool')
    node.fill(outputs, conversions.stamp_from_nanoseconds(STAMP_NS), 'base')
    offline.fill(outputs, offline.types.time(STAMP_NS), 'base')
    found = layouts.spine_output_layouts(chain.n_joints)
    assert tuple(found) == (*spine_processing.OUTPUT_NAMES, 'tip_stiffness_stamped',
                            'tip_stiffness_base_stamped')
    arrays = spine_processing.output_arrays(outputs)
    for (name, layout), mine, theirs, k in zip(
            found.items(), offline.messages(), node.messages(), node.array_index, strict=True):
        assert arrays[k].size == layout.size, name
        assert same_bytes(theirs, mine, layout.msgtype), name
    assert [node.tip_stiffness_stamped.header.frame_id,
            node.tip_stiffness_base_stamped.header.frame_id] == ['tool', 'base']
    np.testing.assert_array_equal(np.asarray(node.tip_stiffness_base_stamped.data).reshape(6, 6),
                                  outputs.tip_stiffness_base)
    T = outputs.state.tip_transform
    np.testing.assert_allclose(messages.pose_message_to_transform(node.tip_pose.pose), T,
                               atol=1e-12)


def test_estimator_messages_of_rclpy_and_rosbags_are_the_same() -> None:
    """estimator_node's messages (the pose with its covariance among them) through the shared
    output code: the same bytes with both implementations, the pose's covariance row-major;
    an output not wanted is left as it was."""
    from support.estimation_trials import truth_from_model

    from tensegrity_stiffness.nodes import estimator_node as en
    from tensegrity_stiffness.nodes.parameter_specs import defaults
    from tensegrity_stiffness.ros.conversions import estimation

    settings = en.estimator_node_settings(defaults(en.ESTIMATOR_NODE_PARAMETERS))
    model = settings.model
    truth = truth_from_model(model, model.initial_screw)
    outputs = en.estimator_outputs(settings, en.EstimatorInput(
        {'measured_tensions': en.Reading(truth.tensions, 1.0),
         'imu': en.Reading(truth.gravity, 1.0)}, 1.0, truth.screw))
    node = estimation.EstimatorOutputMessages(tuple(model.string_names))
    offline = messages.EstimatorOutputMessages(model.string_names, rosbags_types())
    wanted = [True] * len(node.messages())
    wanted[list(node.layouts).index(layouts.ESTIMATOR_STD_OUTPUT)] = False
    node.fill(outputs, conversions.stamp_from_nanoseconds(STAMP_NS), 'link_a', wanted)
    offline.fill(outputs, offline.types.time(STAMP_NS), 'link_a', wanted)
    for (name, layout), mine, theirs in zip(node.layouts.items(), offline.messages(),
                                            node.messages(), strict=True):
        assert same_bytes(theirs, mine, layout.msgtype), name
    pose = node.messages()[0]
    assert pose.header.frame_id == 'link_a'
    np.testing.assert_array_equal(np.reshape(pose.pose.covariance, (6, 6)),
                                  outputs.estimate.covariance)
    np.testing.assert_allclose(messages.pose_message_to_transform(pose.pose.pose),
                               outputs.estimate.transform, atol=1e-12)
    assert not np.any(node.messages()[list(node.layouts).index('cartesian_stiffness_std')].data)


def test_pose_writer_refuses_a_non_rotation_and_writes_nothing() -> None:
    msg = messages.new_message(layouts.OutputLayout(layouts.POSE_STAMPED), rosbags_types())
    T = np.eye(4)
    T[:3, :3] *= 1.1
    with pytest.raises(ValueError, match='rotation'):
        messages.write_pose_stamped(msg, T, rosbags_types().time(5), 'base')
    assert (msg.pose.orientation.w, msg.header.stamp.nanosec, msg.header.frame_id) == (1.0, 0, '')


@pytest.mark.parametrize('ns, problem', [(-1, 'non-negative'), (2**31 * 10**9, 'int32')])
def test_stamps_out_of_range_are_refused(ns: int, problem: str) -> None:
    with pytest.raises(ValueError, match=problem):
        messages.stamp_parts(ns)
    with pytest.raises(ValueError, match=problem):
        conversions.stamp_from_nanoseconds(ns)
