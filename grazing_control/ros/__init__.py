"""The ROS 2 adapters: nodes, the launcher, packed CDR messages, MCAP recording.

Layer 4 of 7 (docs/architecture.md), the only layer that imports rclpy (its node
modules do; :mod:`.launcher` and :mod:`.recording` only spawn processes and write
files). :mod:`.controller_node`, :mod:`.recorder_node` (and sim_node at the top level
of the repository) are thin adapters over the layers below; :mod:`.common` holds what
the nodes share (QoS, descriptors, the spin loop), :mod:`.cdr` the packed messages,
:mod:`.launcher` starts a scene as processes, :mod:`.recording` writes and reads
rosbag2-style MCAP bags, :mod:`.live_node` serves a scene to Foxglove/Lichtblick,
:mod:`.scene` tells a scene's nodes from another's (the scene token),
:mod:`.scheduling` applies the real-time scheduling options, :mod:`.entry` holds the
executables' entry points (quiet on a Ctrl-C while a node imports).

May import: :mod:`grazing_control.plant` and below.
"""
