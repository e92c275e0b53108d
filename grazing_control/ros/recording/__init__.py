"""Recording ROS 2 topics to rosbag2-style MCAP bags, and reading them back.

This package is the recording part of the ROS layer (see ``docs/recording.md``).
It writes what ``ros2 bag record -s mcap`` writes, on top of the ``mcap``
library, without ROS: the recorder node (``grazing_control.ros.recorder_node``)
is a thin adapter that feeds it serialized CDR bytes, and the analysis reads
the bags back with :func:`read_messages`.

A bag is a directory::

    <bag_dir>/
        <bag_dir name>_0.mcap   MCAP, profile ``ros2``, zstd/lz4-compressed chunks
        metadata.yaml           rosbag2 metadata, version 9 (ROS 2 Jazzy)

The MCAP file follows the ``ros2`` profile of the MCAP specification as
rosbag2's ``mcap`` storage plugin writes it:

* one Schema per message type, named like ``sensor_msgs/msg/JointState``,
  encoding ``ros2msg``, whose data is the ``.msg`` text followed by every
  nested definition (see :func:`message_definition`);
* one Channel per topic, message encoding ``cdr``, with the channel metadata
  keys ``offered_qos_profiles`` (a YAML list of QoS profiles, see
  :func:`qos_profiles_yaml`) and ``topic_type_hash`` (the ``RIHS01_`` type
  description hash);
* Message records with ``log_time`` = receive time and ``publish_time`` =
  source (send) time, in nanoseconds;
* chunks with message indexes; at :meth:`BagWriter.close`, a ``rosbag2``
  Metadata record (``serialized_metadata``, ``ROS_DISTRO``) and the summary
  (schemas, channels, Statistics, chunk and metadata indexes).

Chunks are written to the operating system as soon as they are complete, so
a recorder that dies before :meth:`BagWriter.close` leaves a file that
:func:`read_messages` still reads up to its last complete chunk.

Examples
--------
>>> with BagWriter("/tmp/run1") as bag:                  # doctest: +SKIP
...     bag.add_topic("/oscillator/state", "sensor_msgs/msg/JointState")
...     bag.write("/oscillator/state", cdr_bytes, receive_time_ns)
>>> for m in read_messages("/tmp/run1"):                 # doctest: +SKIP
...     print(m.topic, m.log_time_ns, m.message.position)
Modules, one idea each: :mod:`.schemas` (constants, ros2msg schemas, type hashes, QoS
profiles), :mod:`.writer` (:class:`BagWriter`), :mod:`.reading` (two readers),
:mod:`.recovery` (``reindex``), :mod:`.record` (the parameter record a node publishes
so that a recording describes itself).
"""

import importlib

#: Each public name -> the module that defines it. They are loaded on first use
#: (PEP 562): the nodes import only :mod:`.record` of this package (the parameter
#: record they publish), and importing the package no longer loads the ``mcap``
#: library and the readers and writer into every simulator and controller (0.05-0.1
#: CPU-s of each node's start, docs/benchmarks.md "The nodes' imports").
_DEFINED_IN = {
    "BagMessage": "reading", "bag_file": "reading", "message_to_dict": "reading",
    "read_messages": "reading", "read_messages_rosbags": "reading",
    "read_metadata": "reading",
    "ReindexResult": "recovery", "reindex": "recovery",
    "COMPRESSIONS": "schemas", "DEFAULT_CHUNK_SIZE": "schemas",
    "METADATA_VERSION": "schemas", "ROS_DISTRO": "schemas",
    "message_definition": "schemas", "qos_profile_dict": "schemas",
    "qos_profiles_yaml": "schemas", "type_description_hash": "schemas",
    "BagWriter": "writer",
}

__all__ = sorted(_DEFINED_IN)


def __getattr__(name: str):
    module = _DEFINED_IN.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_DEFINED_IN))
