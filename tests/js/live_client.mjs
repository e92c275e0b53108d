// The live view read by the Foxglove WebSocket protocol authors' own client library
// (@foxglove/ws-protocol over ws), its messages decoded as ROS 2 CDR with the schema the
// server advertises (@foxglove/rosmsg parses the ros2msg text, @foxglove/rosmsg2-
// serialization reads the CDR): tests/test_live_node.py runs it beside a scene and checks
// what it prints against the scene's bag.
//
// usage: node live_client.mjs URL TOPIC[,TOPIC...] TIMEOUT_S
// Connects (retrying until the server listens), subscribes to every topic named once all
// are advertised, decodes each message, and when the server closes the connection (or
// at the timeout) prints one JSON object: {subprotocol, channels: {topic: {encoding,
// schemaName, schemaEncoding}}, messages: [{topic, timestamp, payload (base64), value}],
// errors: [...]}. Non-finite doubles are written as the strings "NaN", "Infinity",
// "-Infinity", typed arrays as arrays, bigints as strings.

import wsProtocol from "@foxglove/ws-protocol";    // CommonJS: its default export
import rosmsg from "@foxglove/rosmsg";
import rosmsg2 from "@foxglove/rosmsg2-serialization";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;
const { parse } = rosmsg;
const { MessageReader } = rosmsg2;

const [url, topicList, timeoutText] = process.argv.slice(2);
const wanted = new Set(topicList.split(","));
const deadline = Date.now() + Number(timeoutText) * 1000;
const out = { subprotocol: null, channels: {}, messages: [], errors: [] };
const byId = new Map();      // channel id -> {topic, reader}
const bySubscription = new Map();

function finish(code) {
  const json = JSON.stringify(out, (_key, value) => {
    if (typeof value === "number" && !Number.isFinite(value)) return String(value);
    if (typeof value === "bigint") return value.toString();
    if (ArrayBuffer.isView(value)) return Array.from(value, (v) => (
      typeof v === "number" && !Number.isFinite(v) ? String(v) : v));
    return value;
  });
  process.stdout.write(json + "\n", () => process.exit(code));
}

function connect() {
  // The Foxglove SDK's server (live_node) speaks the protocol under its new name
  // foxglove.sdk.v1 only, refusing foxglove.websocket.v1 with a 400; the protocol is the
  // same, and FoxgloveClient (since 0.7.5) leaves the name to the socket: a client offers
  // both, as Lichtblick does since its foxglove.sdk.v1 support.
  const ws = new WebSocket(url, ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
  let opened = false;
  ws.on("error", (err) => {
    if (!opened && String(err).includes("ECONNREFUSED") && Date.now() < deadline) {
      setTimeout(connect, 200);          // the server does not listen yet
    } else {
      out.errors.push(String(err));
      finish(1);
    }
  });
  ws.on("open", () => {
    opened = true;
    out.subprotocol = ws.protocol;
  });
  ws.on("close", () => {
    if (opened) finish(0);
  });
  const client = new FoxgloveClient({ ws });
  let subscribed = false;
  client.on("advertise", (channels) => {
    for (const ch of channels) {
      out.channels[ch.topic] = { encoding: ch.encoding, schemaName: ch.schemaName,
                                 schemaEncoding: ch.schemaEncoding };
      if (!wanted.has(ch.topic)) continue;
      try {
        const reader = new MessageReader(parse(ch.schema, { ros2: true }));
        byId.set(ch.id, { topic: ch.topic, reader });
      } catch (err) {
        out.errors.push(`${ch.topic}: schema not parsed: ${err}`);
      }
    }
    const topics = new Set([...byId.values()].map((c) => c.topic));
    if (!subscribed && [...wanted].every((t) => topics.has(t))) {
      subscribed = true;
      for (const [id, ch] of byId) bySubscription.set(client.subscribe(id), ch);
    }
  });
  client.on("message", ({ subscriptionId, timestamp, data }) => {
    const ch = bySubscription.get(subscriptionId);
    const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
    let value = null;
    try {
      value = ch.reader.readMessage(bytes);
    } catch (err) {
      out.errors.push(`${ch.topic}: not decoded: ${err}`);
    }
    out.messages.push({ topic: ch.topic, timestamp, value,
                        payload: Buffer.from(bytes).toString("base64") });
  });
}

setTimeout(() => {
  out.errors.push("timeout");
  finish(1);
}, Math.max(0, deadline - Date.now()));
connect();
