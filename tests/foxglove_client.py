"""A Foxglove WebSocket protocol client for the live view's tests and benchmark.

Written from the protocol's specification (foxglove/ws-protocol, ``docs/spec.md``), not
from the server's code: the handshake offers the subprotocols ``foxglove.sdk.v1`` (what
the Foxglove SDK serves) and ``foxglove.websocket.v1`` (the same protocol under its
older name); text frames are JSON (``serverInfo``, ``advertise``); the client sends
``subscribe``; a binary frame ``messageData`` is opcode 0x01, uint32 subscription id,
uint64 timestamp (ns), then the payload, little endian.
"""

from __future__ import annotations

import json
import struct
import threading
import time

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01
_HEADER = struct.Struct("<BIQ")


def parse_message_data(frame: bytes):
    """``(subscription id, timestamp ns, payload)`` of a binary messageData frame."""
    opcode, sub_id, stamp = _HEADER.unpack_from(frame, 0)
    if opcode != MESSAGE_DATA:
        raise ValueError(f"opcode {opcode:#x} is not messageData")
    return sub_id, stamp, bytes(frame[_HEADER.size:])


class FoxgloveClient:
    """Connects (retrying until ``timeout``), reads serverInfo and the advertised
    channels, subscribes to the topics wanted, and collects messages in a thread.

    ``messages``: list of ``(topic, timestamp ns, payload bytes)`` in arrival order;
    ``channels``: topic -> the advertised channel (a dict of the protocol's fields).
    """

    def __init__(self, port: int, topics=None, timeout: float = 30.0,
                 host: str = "127.0.0.1"):
        end = time.monotonic() + timeout
        while True:
            try:
                self.ws = connect(f"ws://{host}:{port}", subprotocols=SUBPROTOCOLS,
                                  compression=None, open_timeout=5, max_size=None,
                                  legacy=True)
                break
            except (OSError, TimeoutError):
                if time.monotonic() > end:
                    raise
                time.sleep(0.2)
        self.subprotocol = self.ws.subprotocol
        self.server_info = json.loads(self.ws.recv(timeout=10))
        self.channels = {}
        self.messages = []
        self.frames = 0
        want = None if topics is None else set(topics)
        while want is None and not self.channels or want and not want <= set(self.channels):
            op = json.loads(self.ws.recv(timeout=10))
            if op.get("op") == "advertise":
                for ch in op["channels"]:
                    self.channels[ch["topic"]] = ch
        subscribe = [ch for t, ch in self.channels.items() if want is None or t in want]
        self._topic_of = {i + 1: ch["topic"] for i, ch in enumerate(subscribe)}
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": i + 1, "channelId": ch["id"]} for i, ch in enumerate(subscribe)]}))
        self._thread = threading.Thread(target=self._receive, daemon=True)
        self._thread.start()

    def _receive(self):
        try:
            for frame in self.ws:
                if isinstance(frame, (bytes, bytearray)):
                    sub_id, stamp, payload = parse_message_data(frame)
                    self.messages.append((self._topic_of[sub_id], stamp, payload))
                    self.frames += 1
        except ConnectionClosed:
            pass

    def wait_for(self, predicate, timeout: float) -> bool:
        """Wait until ``predicate(self)`` is true; return whether it became true."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate(self):
                return True
            time.sleep(0.05)
        return predicate(self)

    def close(self):
        self.ws.close()
        self._thread.join(5)
