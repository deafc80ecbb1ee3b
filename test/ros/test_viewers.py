"""The viewers' configurations against running nodes: every topic they name (in the twin demo's
namespace, mapped to this test's) is one the running ``stiffness_node`` / ``spine_node`` /
``structure_node`` publishes, and the plotted ``~/stiffness_eigenvalues``
(``~/tip_stiffness_eigenvalues``) are the principal stiffnesses of the library's K_c (tip
stiffness) to 1e-12."""

from __future__ import annotations

import time

import numpy as np
import pytest
from support import REPO

pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')

from std_msgs.msg import Float64MultiArray
from support.ros_harness import NodeProcess, RosClient, repeat_until, unique_namespace
from support.viewer_configs import NAMESPACE, viewer_configs

from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.interpretation import principal_stiffnesses
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes.layouts import STIFFNESS_EIGENVALUES_LABEL
from tensegrity_stiffness.nodes.spine_node import spine_outputs

pytestmark = [pytest.mark.ros, pytest.mark.slow]

JOINT = REPO / 'config' / 'default_joint.yaml'
SPINE = REPO / 'config' / 'default_spine.yaml'


def published_by(ros: RosClient, node: str, ns: str, wanted: set[str]) -> set[str]:
    """The topics ``node`` in ``ns`` publishes, once the graph lists all of ``wanted`` (or 20
    s passed)."""
    deadline = time.monotonic() + 20.0
    while True:
        try:
            topics = {t for t, _ in ros.node.get_publisher_names_and_types_by_node(node, ns)}
        except Exception:  # not in the graph yet
            topics = set()
        if wanted <= topics or time.monotonic() > deadline:
            return topics
        time.sleep(0.05)


def test_viewer_topics_are_published_and_the_eigenvalues_are_the_librarys(tmp_path) -> None:
    ns = unique_namespace('view')
    joint = NodeProcess(ns, JOINT)
    spine = NodeProcess(ns, SPINE, executable='spine_node')
    structure_params = tmp_path / 'structure_node.yaml'  # the packaged 6-bar (its default)
    structure_params.write_text('structure_node:\n  ros__parameters:\n    structure.config: '
                                'six_bar.yaml\n')
    structure = NodeProcess(ns, structure_params, executable='structure_node')
    ros = RosClient('viewers')
    try:
        for config in viewer_configs():
            wanted = {ns + t[len(NAMESPACE):] for t in config.topics}
            missing = wanted - published_by(ros, config.node, ns, wanted)
            assert not missing, f'{config.path.name}: {sorted(missing)} not published'

        model, chain = JointModel.from_yaml(JOINT), JointChain.from_yaml(SPINE)
        xi = model.initial_screw + [0.03, -0.02, 0.01, 0.001, -0.002, 0.0]
        screws = chain.unloaded_screws() + 0.01
        cases = (('stiffness_node/screw', 'stiffness_node/stiffness_eigenvalues', xi,
                  model.evaluate(xi).cartesian_stiffness),
                 ('spine_node/screws', 'spine_node/tip_stiffness_eigenvalues', screws,
                  spine_outputs(chain, screws).tip_stiffness_tool))
        for input_topic, output, value, K in cases:
            inbox = ros.subscribe(Float64MultiArray, f'{ns}/{output}')
            pub = ros.publisher(Float64MultiArray, f'{ns}/{input_topic}')
            ros.wait_for_subscribers(pub)
            ros.wait_for_publishers(f'{ns}/{output}')
            msg = Float64MultiArray(data=np.ravel(value).tolist())
            got = repeat_until(lambda m=msg, p=pub: p.publish(m),
                               lambda i=inbox: i.messages[0] if i.messages else None, 30.0)
            want = principal_stiffnesses(K)
            assert got.layout.dim[0].label == STIFFNESS_EIGENVALUES_LABEL
            np.testing.assert_allclose(got.data, want, rtol=0.0,
                                       atol=1e-12 * np.abs(want).max(), err_msg=output)
            assert np.all(np.diff(got.data[:3]) >= 0) and np.all(np.diff(got.data[3:]) >= 0)
    finally:
        ros.close()
        codes = joint.stop(), spine.stop(), structure.stop()
    assert codes == (0, 0, 0), (joint.log()[-2000:] + spine.log()[-2000:]
                                + structure.log()[-2000:])
