"""Middleware memory settings of a node's process: oversized input messages must not grow the
process for good. Call :func:`bound_input_memory` before ``rclpy.init``."""

from __future__ import annotations

import ctypes
import os
import tempfile
from pathlib import Path

#: glibc ``mallopt`` parameter M_MMAP_THRESHOLD, and the threshold set (bytes).
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_BYTES = 128 * 1024
#: Seconds between the participant's discovery announcements (Fast DDS ``leaseAnnouncement``;
#: its default is 3 s). A node running before a peer starts (a bridge before its controller)
#: found the newcomer only at its next announcement on this machine: 1.8-2.4 s after the peer
#: started in 5 of 7 runs (a bridge streaming K_c at 100 Hz reached its controller 1-5 times in
#: 3 s, issue 37), against 0.35-0.56 s in 7 of 7 runs with this period, side by side.
ANNOUNCEMENT_PERIOD_NS = 250_000_000
#: Fast DDS profile of the node's process (see :func:`bound_input_memory`): readers allocate a
#: sample's memory when it arrives and free it once it is taken (``DYNAMIC``), instead of the
#: rmw_fastrtps default, a pool of buffers that each grow to the largest sample seen and are kept:
#: with it, a burst of 8 MB messages on a topic of depth 100 pins up to 800 MB for good. The
#: participant announces itself every :data:`ANNOUNCEMENT_PERIOD_NS`. Writers, the rest of
#: discovery and the publication mode are those rmw_fastrtps sets by default.
FASTDDS_PROFILE = f"""<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <participant profile_name="tensegrity_stiffness_participant" is_default_profile="true">
    <rtps>
      <builtin>
        <discovery_config>
          <leaseAnnouncement>
            <sec>0</sec><nanosec>{ANNOUNCEMENT_PERIOD_NS}</nanosec>
          </leaseAnnouncement>
        </discovery_config>
        <readerHistoryMemoryPolicy>PREALLOCATED_WITH_REALLOC</readerHistoryMemoryPolicy>
        <writerHistoryMemoryPolicy>PREALLOCATED_WITH_REALLOC</writerHistoryMemoryPolicy>
      </builtin>
    </rtps>
  </participant>
  <data_writer profile_name="tensegrity_stiffness_writer" is_default_profile="true">
    <qos>
      <publishMode><kind>SYNCHRONOUS</kind></publishMode>
      <data_sharing><kind>OFF</kind></data_sharing>
    </qos>
    <historyMemoryPolicy>PREALLOCATED_WITH_REALLOC</historyMemoryPolicy>
  </data_writer>
  <data_reader profile_name="tensegrity_stiffness_reader" is_default_profile="true">
    <qos>
      <data_sharing><kind>OFF</kind></data_sharing>
    </qos>
    <historyMemoryPolicy>DYNAMIC</historyMemoryPolicy>
  </data_reader>
</profiles>
"""
#: Environment variables with which a deployment configures Fast DDS itself (then the node
#: leaves Fast DDS alone).
FASTDDS_ENVIRONMENT = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE',
                       'RMW_FASTRTPS_USE_QOS_FROM_XML')


def bound_input_memory() -> Path | None:
    """Keep oversized input messages from growing the process for good; call before the first
    node is created. Returns the Fast DDS profile file written (delete it once the node exists),
    or None.

    * glibc: allocations above ``MMAP_THRESHOLD_BYTES`` always by ``mmap``, so that freeing one
      returns it to the system (by default the threshold rises to the largest block freed, up to
      32 MB, and later 8 MB message buffers stay in the heap).
    * Fast DDS: unless the environment configures Fast DDS itself (``FASTDDS_ENVIRONMENT``),
      readers with per-sample memory (``FASTDDS_PROFILE``), through a profile file and
      ``RMW_FASTRTPS_USE_QOS_FROM_XML=1``; the QoS set in code still apply.
    """
    try:
        ctypes.CDLL(None).mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
    except (OSError, AttributeError):  # not glibc
        pass
    rmw = os.environ.get('RMW_IMPLEMENTATION') or 'rmw_fastrtps_cpp'
    if not rmw.startswith('rmw_fastrtps') or any(os.environ.get(v) for v in FASTDDS_ENVIRONMENT):
        return None
    fd, name = tempfile.mkstemp(prefix='tensegrity_stiffness_fastdds_', suffix='.xml')
    with os.fdopen(fd, 'w') as f:
        f.write(FASTDDS_PROFILE)
    os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'] = name
    os.environ['RMW_FASTRTPS_USE_QOS_FROM_XML'] = '1'
    return Path(name)
