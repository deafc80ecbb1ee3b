"""Run by ``test/ros/test_tf.py`` in a process whose environment has ``tf2_msgs`` (the stand-in
of :mod:`support.tf2_standin`, or a stock install's): the nodes' frames on ``/tf`` and
``/tf_static`` arrive at an rclpy client with the poses the library computes.

* ``stiffness_node``: screws in; each ``/tf`` message holds ``tensegrity_link1 ->
  tensegrity_link2`` at ``JointModel.evaluate(xi).transform``; ``tf.enabled: false`` at run time
  stops it (true again starts it, with the last input's frames re-published).
* ``spine_node``: screws in; ``spine_base -> spine_base_link_<i>`` at
  ``ChainState.link_transforms`` and, latched on ``/tf_static``, ``spine_base_link_5 ->
  spine_tool`` at ``JointChain.tool``, so that base -> tool composes to the library's
  ``tip_transform``.
* ``estimator_node``: the library's tensions at a screw in; the frame at each estimate's pose
  (``~/pose_estimate`` of the same stamp).
* ``sim_node`` (joint and spine): each frame at the twin's published pose of the same stamp
  (``~/pose``; a spine: the library's link poses of its ``~/poses``).

Prints ``TF <node>: <k> frames, largest difference <e>`` per node and ``TF OK``; exits 0, or
raises. Usage: ``python tf_check.py``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

# Run as a script: the test folder, which holds the support package, on the path.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from geometry_msgs.msg import PoseArray, PoseStamped, PoseWithCovarianceStamped
from std_msgs.msg import Float64MultiArray
from tf2_msgs.msg import TFMessage

from support import JOINT_CONFIG, SPINE_CONFIG
from support.ros_harness import (
    NodeProcess,
    RosClient,
    log_has,
    repeat_until,
    unique_namespace,
)
from tensegrity_stiffness.geometry.quaternion import quaternion_to_rotation
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes.messages import (
    pose_message_to_transform,
    stamp_nanoseconds,
)
from tensegrity_stiffness.ros.runtime.tf_broadcast import TF_QOS, TF_STATIC_QOS

#: The poses must agree to this (rotation entries, and translations in m).
TOLERANCE = 1e-12
TIMEOUT = 60.0


def matrix(transform: Any) -> np.ndarray:
    """(4, 4) of a ``geometry_msgs/Transform``."""
    t, q = transform.translation, transform.rotation
    T = np.eye(4)
    T[:3, :3] = quaternion_to_rotation([q.x, q.y, q.z, q.w])
    T[:3, 3] = [t.x, t.y, t.z]
    return T


def frames_of(msg: TFMessage) -> dict[tuple[str, str], np.ndarray]:
    """``{(parent, child): (4, 4)}`` of a TFMessage."""
    return {(t.header.frame_id, t.child_frame_id): matrix(t.transform) for t in msg.transforms}


def stamp_of(msg: TFMessage) -> int:
    stamps = {stamp_nanoseconds(t.header.stamp) for t in msg.transforms}
    assert len(stamps) == 1, f'one TFMessage, several stamps: {stamps}'
    return stamps.pop()


def screws_message(xi: np.ndarray) -> Float64MultiArray:
    return Float64MultiArray(data=np.ravel(xi).tolist())


def matched(messages: list[TFMessage], expected: list[dict[tuple[str, str], np.ndarray]]
            ) -> float | None:
    """The largest difference of the best match of every expected frame set among
    ``messages`` (None while one has no message with its frames within 1e-6)."""
    worst = 0.0
    for frames in expected:
        best = np.inf
        for msg in messages:
            got = frames_of(msg)
            if set(got) != set(frames):
                continue
            best = min(best, max(float(np.abs(got[k] - frames[k]).max()) for k in frames))
        if best > 1e-6:
            return None
        worst = max(worst, best)
    return worst


class Session:
    """One client with ``/tf`` and ``/tf_static`` subscriptions (tf2's QoS)."""

    def __init__(self) -> None:
        self.ros = RosClient('tf_check')
        self.tf = self.ros.subscribe(TFMessage, '/tf', TF_QOS)
        self.static = self.ros.subscribe(TFMessage, '/tf_static', TF_STATIC_QOS)

    def run(self, name: str, start: Callable[[str], NodeProcess],
            check: Callable[[str, NodeProcess], tuple[int, float]]) -> None:
        """Start a node, ``check`` it (frames checked, largest difference), stop it cleanly."""
        self.tf.clear()
        self.static.clear()
        ns = unique_namespace('tf')
        proc = start(ns)
        try:
            count, worst = check(ns, proc)
            # The fast lane serves inputs from just before the node logs its 'ready' line
            # (which names the frames' status): wait for that line before stopping the node.
            log_has(proc, 'frames on /tf|no /tf')
        except BaseException:
            print(proc.log()[-4000:], file=sys.stderr)
            raise
        finally:
            code = proc.stop()
        assert code == 0, f'{name} exit code {code}:\n{proc.log()[-3000:]}'
        assert worst < TOLERANCE, f'{name}: frames differ from the library by {worst:.3g}'
        assert 'frames on /tf' in proc.log(), proc.log()[-3000:]
        print(f'TF {name}: {count} frames, largest difference {worst:.2e}', flush=True)

    # ------------------------------------------------------------------ the nodes
    def stiffness_node(self, ns: str, proc: NodeProcess) -> tuple[int, float]:
        model = JointModel.from_yaml(JOINT_CONFIG)
        rng = np.random.default_rng(3)
        screws = [model.initial_screw + rng.normal(0.0, 1.0, 6) * ([0.05] * 3 + [0.002] * 3)
                  for _ in range(6)]
        expected = [{('tensegrity_link1', 'tensegrity_link2'): model.evaluate(xi).transform}
                    for xi in screws]
        base = f'{ns}/stiffness_node'
        pub, worst = self._send_and_match(f'{base}/screw', screws, expected, proc)
        self._check_switch(base, pub, model)
        return len(expected), worst

    def _send_and_match(self, topic: str, screws: list[np.ndarray],
                        expected: list[dict[tuple[str, str], np.ndarray]], proc: NodeProcess
                        ) -> tuple[Any, float]:
        """Publish ``screws`` on ``topic`` (the first until a frame comes, then the rest once)
        and wait until the frames received hold each one's ``expected`` frames: the publisher
        and the largest difference."""
        pub = self.ros.publisher(Float64MultiArray, topic)
        self.ros.wait_for_subscribers(pub)
        repeat_until(lambda: pub.publish(screws_message(screws[0])),
                     lambda: len(self.tf) or None, TIMEOUT, explain=proc.log)
        for xi in screws[1:]:
            pub.publish(screws_message(xi))
        worst = repeat_until(lambda: None, lambda: matched(self.tf.messages, expected),
                             TIMEOUT, 0.05, explain=proc.log)
        return pub, worst

    def _check_switch(self, base: str, pub: Any, model: JointModel) -> None:
        """``tf.enabled: false`` at run time: an input's frames are not sent; true again: sent,
        the last input's again at once (a parameter change re-publishes it). The messages of one
        writer arrive in order, so the later ones prove the earlier absent."""
        from rcl_interfaces.srv import SetParameters

        params = self.ros.client(SetParameters, f'{base}/set_parameters')
        off, last, on = (model.initial_screw + [0.0, 0.0, 0.0, d, 0.0, 0.0]
                         for d in (0.003, 0.002, -0.003))
        stiffness = self.ros.subscribe(Float64MultiArray, f'{base}/stiffness')
        self.ros.wait_for_publishers(f'{base}/stiffness')
        assert self.ros.set_parameter(params, 'tf.enabled', False).successful
        for xi in (off, last):
            pub.publish(screws_message(xi))
            stiffness.wait_until(lambda m, xi=xi: np.allclose(
                m.data, model.stiffness(xi).ravel(), rtol=0.0, atol=1e-12), TIMEOUT)
        assert self.ros.set_parameter(params, 'tf.enabled', True).successful
        pub.publish(screws_message(on))
        frame = ('tensegrity_link1', 'tensegrity_link2')
        repeat_until(lambda: None, lambda: matched(
            self.tf.messages, [{frame: model.evaluate(xi).transform} for xi in (last, on)]),
            TIMEOUT, 0.05)
        assert matched(self.tf.messages, [{frame: model.evaluate(off).transform}]) is None, \
            'frames sent while tf.enabled was false'

    def spine_node(self, ns: str, proc: NodeProcess) -> tuple[int, float]:
        chain = JointChain.from_yaml(SPINE_CONFIG)
        rng = np.random.default_rng(4)
        unloaded = chain.unloaded_screws()
        screws = [unloaded + rng.normal(0.0, 1.0, unloaded.shape) * ([0.03] * 3 + [0.001] * 3)
                  for _ in range(4)]
        states = [chain.evaluate(xi) for xi in screws]
        expected = [{('spine_base', f'spine_base_link_{i + 1}'): L
                     for i, L in enumerate(state.link_transforms)} for state in states]
        _, worst = self._send_and_match(f'{ns}/spine_node/screws', screws, expected, proc)
        tool = frames_of(self.static.wait_for(1, TIMEOUT)[-1])
        assert set(tool) == {('spine_base_link_5', 'spine_tool')}, tool
        O_tool = tool[('spine_base_link_5', 'spine_tool')]
        worst = max(worst, float(np.abs(O_tool - chain.tool).max()))
        for state, frames in zip(states, expected, strict=True):  # base -> tool composes
            tip = frames[('spine_base', 'spine_base_link_5')] @ O_tool
            worst = max(worst, float(np.abs(tip - state.tip_transform).max()))
        return sum(len(f) for f in expected) + 1, worst

    def estimator_node(self, ns: str, proc: NodeProcess) -> tuple[int, float]:
        model = JointModel.from_yaml(JOINT_CONFIG)
        base = f'{ns}/estimator_node'
        estimates = self.ros.subscribe(PoseWithCovarianceStamped, f'{base}/pose_estimate')
        pub = self.ros.publisher(Float64MultiArray, f'{base}/measured_tensions')
        self.ros.wait_for_subscribers(pub)
        self.ros.wait_for_publishers(f'{base}/pose_estimate')
        xi = model.initial_screw + [0.02, -0.01, 0.01, 0.001, 0.0, -0.001]
        tensions = screws_message(model.evaluate(xi).tensions)
        repeat_until(lambda: pub.publish(tensions), lambda: len(estimates) >= 3 or None,
                     TIMEOUT, explain=proc.log)
        return self._by_stamp(estimates.messages, lambda m: pose_message_to_transform(
            m.pose.pose), ('tensegrity_link1', 'tensegrity_link2'))

    def _by_stamp(self, poses: list[Any], transform: Callable[[Any], np.ndarray],
                  frame: tuple[str, str]) -> tuple[int, float]:
        """Every pose message against the ``/tf`` message of its stamp (waited for)."""
        wanted = {stamp_nanoseconds(m.header.stamp): transform(m) for m in poses}

        def compare() -> tuple[int, float] | None:
            got = {stamp_of(m): frames_of(m) for m in self.tf.messages}
            if not set(wanted) <= set(got):
                return None
            return len(wanted), max(float(np.abs(got[s][frame] - T).max())
                                    for s, T in wanted.items())

        return repeat_until(lambda: None, compare, TIMEOUT, 0.05)

    def sim_joint(self, ns: str, proc: NodeProcess) -> tuple[int, float]:
        poses = self.ros.subscribe(PoseStamped, f'{ns}/sim_node/pose')
        self.ros.wait_for_publishers(f'{ns}/sim_node/pose')
        first = poses.wait_for(5, TIMEOUT)[:5]
        return self._by_stamp(first, lambda m: pose_message_to_transform(m.pose),
                              ('tensegrity_link1', 'tensegrity_link2'))

    def sim_spine(self, ns: str, proc: NodeProcess) -> tuple[int, float]:
        chain = JointChain.from_yaml(SPINE_CONFIG)
        poses = self.ros.subscribe(PoseArray, f'{ns}/sim_node/poses')
        self.ros.wait_for_publishers(f'{ns}/sim_node/poses')
        first = poses.wait_for(3, TIMEOUT)[:3]
        count, worst = 0, 0.0
        for link in range(chain.n_joints):
            n, error = self._by_stamp(first, lambda m, i=link: self._link_pose(chain, m, i),
                                      ('spine_base', f'spine_base_link_{link + 1}'))
            count, worst = count + n, max(worst, error)
        tool = frames_of(self.static.wait_for(1, TIMEOUT)[-1])
        worst = max(worst, float(np.abs(tool[('spine_base_link_5', 'spine_tool')]
                                        - chain.tool).max()))
        return count + 1, worst

    @staticmethod
    def _link_pose(chain: JointChain, msg: PoseArray, link: int) -> np.ndarray:
        """The library's pose of link ``link`` in the base from the twin's joint poses."""
        pose = np.eye(4)
        for i in range(link + 1):
            if i > 0:
                pose = pose @ chain.link_offsets[i - 1]
            pose = pose @ pose_message_to_transform(msg.poses[i])
        return pose

    def structure_node(self, ns: str, proc: NodeProcess) -> tuple[int, float]:
        """The packaged 6-bar: world -> every body at the poses sent on ``~/pose_values``
        (the bodies' transforms as the node reads them, ``Structure.transforms``)."""
        from tensegrity_stiffness.config import example_config_path
        from tensegrity_stiffness.mechanics.templates import pose_vector
        from tensegrity_stiffness.structures.structure import Structure, twist_exp

        structure = Structure.from_yaml(example_config_path('six_bar.yaml'))
        rng = np.random.default_rng(5)
        values = [np.array([pose_vector(twist_exp(0.05 * rng.standard_normal(6)) @ P)
                            for P in structure.start_poses()]) for _ in range(4)]
        expected = [{('world', name): T for name, T in zip(
            structure.body_names, structure.transforms(v), strict=True)} for v in values]
        _, worst = self._send_and_match(f'{ns}/structure_node/pose_values', values, expected,
                                        proc)
        return sum(len(f) for f in expected), worst

    def close(self) -> None:
        self.ros.close()


def main() -> None:
    session = Session()
    try:
        session.run('stiffness_node', lambda ns: NodeProcess(ns, JOINT_CONFIG),
                    session.stiffness_node)
        session.run('spine_node', lambda ns: NodeProcess(ns, SPINE_CONFIG,
                                                         executable='spine_node'),
                    session.spine_node)
        session.run('estimator_node', lambda ns: NodeProcess(ns, JOINT_CONFIG,
                                                             executable='estimator_node'),
                    session.estimator_node)
        session.run('sim_node', lambda ns: NodeProcess(
            ns, JOINT_CONFIG, ['-p', 'sim.publish_every:=10'], executable='sim_node'),
            session.sim_joint)
        session.run('sim_node (spine)', lambda ns: NodeProcess(
            ns, SPINE_CONFIG, ['-p', 'sim.spine:=true', '-p', 'sim.publish_every:=20'],
            executable='sim_node'), session.sim_spine)
        session.run('structure_node', lambda ns: NodeProcess(
            ns, JOINT_CONFIG, ['-p', 'structure.config:=six_bar.yaml'],
            executable='structure_node'), session.structure_node)
    finally:
        session.close()
    print('TF OK', flush=True)


if __name__ == '__main__':
    main()
