"""The Fast DDS profile of the package's nodes (``ros/runtime/middleware.py``): it parses, keeps
the per-sample reader memory, and the participant announces itself often enough that a node
running before a peer starts finds the newcomer promptly (issue 37, item 7: a bridge found its
controller at Fast DDS's next 3 s announcement, and updates stalled meanwhile)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

from tensegrity_stiffness.ros.runtime import middleware

NS = {'f': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}


def test_the_participant_announces_itself_at_most_every_half_second():
    root = ET.fromstring(middleware.FASTDDS_PROFILE.encode())
    builtin = root.find('f:participant/f:rtps/f:builtin', NS)
    announcement = builtin.find('f:discovery_config/f:leaseAnnouncement', NS)
    assert announcement is not None, 'no leaseAnnouncement: Fast DDS announces every 3 s'
    seconds = int(announcement.find('f:sec', NS).text) + 1e-9 * int(
        announcement.find('f:nanosec', NS).text)
    assert 0.0 < seconds <= 0.5, seconds
    assert seconds == middleware.ANNOUNCEMENT_PERIOD_NS * 1e-9
    # the rest as before: dynamic reader memory, synchronous writers, no data sharing
    reader = root.find('f:data_reader', NS)
    assert reader.find('f:historyMemoryPolicy', NS).text == 'DYNAMIC'
    assert root.find('f:data_writer/f:qos/f:publishMode/f:kind', NS).text == 'SYNCHRONOUS'
