"""The bridge's call timeout without ROS (:meth:`~tensegrity_stiffness.nodes.stiffness_bridge.
BridgeSettings.call_timeout`): until the controller answers, a call is sent again after
``target.first_contact_timeout``, doubled with each resend up to ``target.timeout``; once it
answered, ``target.timeout``; 0 turns the first-contact resends off (issue 37, item 7)."""

from __future__ import annotations

import pytest

from tensegrity_stiffness.nodes.parameter_specs import defaults
from tensegrity_stiffness.nodes.stiffness_bridge import (
    BRIDGE_PARAMETERS,
    FIRST_CONTACT_TIMEOUT,
    bridge_settings,
)


def settings(**values: object):
    given = defaults(BRIDGE_PARAMETERS)
    given.update({'preset': 'cartesian_controllers', 'target.node': '/arm/controller'})
    given.update({k.replace('__', '.'): v for k, v in values.items()})
    return bridge_settings(given)


def test_before_the_first_answer_calls_are_resent_sooner_doubling_up_to_the_timeout():
    s = settings()
    assert s.first_contact_timeout == FIRST_CONTACT_TIMEOUT < s.timeout == 1.0
    assert [s.call_timeout(False, n) for n in range(5)] == [0.25, 0.5, 1.0, 1.0, 1.0]
    s = settings(target__timeout=3.0, target__first_contact_timeout=0.2)
    assert [s.call_timeout(False, n) for n in range(6)] == pytest.approx(
        [0.2, 0.4, 0.8, 1.6, 3.0, 3.0])
    assert s.call_timeout(False, 10_000) == 3.0  # no overflow after a long outage


def test_once_answered_a_call_waits_the_timeout():
    s = settings(target__timeout=2.0)
    assert s.call_timeout(True, 0) == s.call_timeout(True, 3) == 2.0


def test_zero_turns_the_first_contact_resends_off_and_a_short_timeout_wins():
    assert settings(target__first_contact_timeout=0.0).call_timeout(False, 0) == 1.0
    s = settings(target__timeout=0.1)  # shorter than the first-contact timeout
    assert s.call_timeout(False, 0) == 0.1


def test_a_negative_first_contact_timeout_is_refused_naming_it():
    with pytest.raises(ValueError, match=r'target\.first_contact_timeout'):
        settings(target__first_contact_timeout=-1.0)
