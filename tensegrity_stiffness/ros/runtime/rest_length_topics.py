"""The ``~/rest_lengths`` topic of the nodes that take one: a joint's (``stiffness_node``,
``estimator_node``) and a spine's (``spine_node``, ``spine_estimator_node``). Each mixin gives a
:class:`~.node_base.StreamingNode` the two hooks it asks for, once for every node of its kind."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from std_msgs.msg import Float64MultiArray

from tensegrity_stiffness.nodes.shared_parameters import rest_length_offsets
from tensegrity_stiffness.nodes.spine_node import rest_lengths_input
from tensegrity_stiffness.nodes.stiffness_node import with_rest_lengths
from tensegrity_stiffness.ros import conversions


class JointRestLengthTopic:
    """Commanded rest lengths of one joint (n values, config order) on a topic, the model's
    rest lengths after ``joint.rest_length_offsets``
    (:func:`~tensegrity_stiffness.nodes.shared_parameters.rest_length_offsets`), within the
    joint's range (:func:`~tensegrity_stiffness.nodes.stiffness_node.with_rest_lengths`);
    settings with a ``model`` (:class:`~tensegrity_stiffness.mechanics.joint.JointModel`),
    ``max_array_length`` and ``values``."""

    def _keep_topic_rest_lengths(self, old: Any, settings: Any, names: set[str]) -> Any:
        rest = old.model.rest_lengths
        if 'joint.rest_lengths' not in names and rest.shape == (settings.model.n_strings,):
            return replace(settings, model=settings.model.with_rest_lengths(rest))
        return settings

    def _with_rest_lengths(self, settings: Any, msg: Float64MultiArray) -> Any:
        n = settings.model.n_strings
        commanded = conversions.multiarray_to_array(msg, expected_length=n,
                                                    max_length=settings.max_array_length)
        rest = commanded + rest_length_offsets(settings.values, n)
        return replace(settings, model=with_rest_lengths(settings.model, rest))


class SpineRestLengthTopic:
    """Rest lengths of every joint of a spine on a topic; settings with ``rest_lengths`` (per
    joint, None for the config's), ``n_strings``, ``chain`` and ``max_array_length``."""

    def _keep_topic_rest_lengths(self, old: Any, settings: Any, names: set[str]) -> Any:
        if old.rest_lengths is not None and not any(
                n.endswith('.rest_lengths') for n in names) and [
                r.shape[0] for r in old.rest_lengths] == settings.n_strings:
            return replace(settings, rest_lengths=old.rest_lengths)
        return settings

    def _with_rest_lengths(self, settings: Any, msg: Float64MultiArray) -> Any:
        rest = rest_lengths_input(conversions.multiarray_to_array(
            msg, max_length=settings.max_array_length), settings.chain)
        return replace(settings, rest_lengths=rest)
