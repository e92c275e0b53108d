"""Recordings: any bag read by streaming, analysed, and replayed (docs/analysis.md).

Layer 5 of 7 (docs/architecture.md).

* :mod:`.reader`: stream an MCAP file (no summary needed) and decode the needed fields
  of all messages of a topic at once (numpy);
* :mod:`.record`: the parameter record the nodes publish on ``grazing/parameters``;
* :mod:`.scenes`: a bag's Pi2 samples, corrections and impacts as scenes;
* :mod:`.numbers`: measured vs predicted numbers of a scene;
* :mod:`.rig_acts`: a rig scene off the rig's section read by what acted (``rig/applied``);
* :mod:`.analysis`: a scene's summary and figure (the demo's report);
* :mod:`.analyze`: the report and the ``analyze`` command;
* :mod:`.identify`: the ``identify`` command (the model's parameters from bags; the
  fit is :mod:`grazing_control.dynamics.identification`);
* :mod:`.replay`: the ``replay`` command (recorded samples through a real controller_node,
  recorded corrections through sim_node); :mod:`.stream_replay` the controller replay
  of a stream scene (its recorded sensor stream); :mod:`.replay_nodes` their rclpy side
  (the session in this process, the node replayed).

May import: :mod:`grazing_control.ros` and below. Nothing here imports rclpy except
:mod:`.replay`, :mod:`.stream_replay` and :mod:`.replay_nodes`, and only when they
run.
"""


def add_commands(sub) -> None:
    """Register ``analyze`` and ``replay`` on the ``grazing`` subparsers."""
    from . import analyze

    s = sub.add_parser("analyze", help="report from recordings: attractor, convergence, "
                                       "predicted vs measured contraction, latency")
    analyze.add_arguments(s)
    s.set_defaults(func=analyze.main)
    try:
        from . import replay
    except ImportError:          # pragma: no cover
        return
    s = sub.add_parser("replay", help="replay a bag's samples (a stream scene's sensor "
                                      "stream) through a real controller_node "
                                      "(and its corrections through sim_node); compare")
    replay.add_arguments(s)
    s.set_defaults(func=replay.main)
    from . import rig_replay

    s = sub.add_parser("replay-rig", help="replay a rig scene's bag through rig_mock (mock "
                                          "hardware) and a controller_node; compare its "
                                          "commands bit for bit")
    rig_replay.add_arguments(s)
    s.set_defaults(func=rig_replay.main)
