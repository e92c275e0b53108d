"""``grazing bag``: tools for recorded bags (``reindex``: recover a killed recording).

``grazing bag reindex BAG`` is ``ros2 bag reindex`` for this project's bags
(:func:`grazing_control.ros.recording.reindex`): after a recorder died without closing its
bag (SIGKILL, power loss), it rewrites the MCAP file with a summary, keeping every
message of every complete chunk, and writes ``metadata.yaml``, so that every reader
(mcap's seeking reader, mcap_ros2, rosbags, ``ros2 bag``) opens it.
"""

from __future__ import annotations

__all__ = ["add_bag_parser", "cmd_reindex"]


def cmd_reindex(args):
    """Reindex one bag; a dict with --json, else a line of text."""
    from grazing_control.ros.recording import reindex

    res = reindex(args.bag)
    if args.json:
        return {"bag": str(args.bag), "file": str(res.path), "messages": res.message_count,
                "topics": res.topics, "had_summary": res.had_summary,
                "dropped_bytes": res.dropped_bytes}
    state = ("it was complete" if res.had_summary
             else f"{res.dropped_bytes} bytes of an unfinished chunk dropped")
    print(f"reindexed {res.path}: {res.message_count} messages on {len(res.topics)} topics "
          f"({state}); metadata.yaml written")
    return 0


def add_bag_parser(sub) -> None:
    """Register ``grazing bag reindex`` on the subcommands of the ``grazing`` parser."""
    s = sub.add_parser("bag", help="recorded bags: reindex (recover a killed recording)")
    tools = s.add_subparsers(dest="bag_command", required=True)
    r = tools.add_parser("reindex", help="rewrite a bag's summary and metadata.yaml "
                                         "(after its recorder was killed), like ros2 bag "
                                         "reindex")
    r.add_argument("bag", help="the bag directory")
    r.add_argument("--json", action="store_true", help="one JSON object on stdout")
    r.set_defaults(func=cmd_reindex)
