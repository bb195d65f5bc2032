// A Foxglove WebSocket protocol client for the viewer's tests, built on @foxglove/ws-protocol (the
// protocol library of the Foxglove app). It connects, subscribes to every advertised channel, decodes each
// message with the schema its channel advertises (protobuf FileDescriptorSet or JSON) and prints one JSON
// object per line on stdout:
//   {"kind": "server", "name", "capabilities"}
//   {"kind": "advertise", "topic", "encoding", "schemaName", "schemaEncoding", "schema"}
//   {"kind": "message", "topic", "logTimeNs", "data"}
//
// usage: node client.mjs ws://HOST:PORT --seconds S [--need TOPIC=N ...] [--until-close]
// Exits 0 once every --need topic has N messages (with --until-close: once the server, having served
// the client, closes the connection; with neither: after S seconds), 1 when S seconds pass first (stderr
// says what is missing), 2 on a protocol or decoding error.
import wsProtocol from "@foxglove/ws-protocol";
import protobuf from "protobufjs";
import descriptor from "protobufjs/ext/descriptor/index.js";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol; // a CommonJS package
// foxglove-sdk servers accept only the subprotocol name "foxglove.sdk.v1", the same protocol as
// "foxglove.websocket.v1" under a new name; the client leaves the choice to the WebSocket (ws-protocol
// 0.7.5 and later).
const SUBPROTOCOL = "foxglove.sdk.v1";

const args = process.argv.slice(2);
const url = args[0];
let seconds = 10;
let untilClose = false;
const need = new Map();
for (let i = 1; i < args.length; i += 2) {
  if (args[i] === "--until-close") {
    untilClose = true;
    i -= 1;
  } else if (args[i] === "--seconds") seconds = Number(args[i + 1]);
  else if (args[i] === "--need") {
    const [topic, n] = args[i + 1].split("=");
    need.set(topic, Number(n));
  } else {
    console.error(`unknown argument ${args[i]}`);
    process.exit(2);
  }
}

const print = (obj) => process.stdout.write(JSON.stringify(obj) + "\n");
const counts = new Map();
const decoders = new Map(); // subscription id -> {topic, decode}

function decoder(channel) {
  if (channel.encoding === "json") {
    const text = new TextDecoder();
    return (view) => JSON.parse(text.decode(view));
  }
  if (channel.encoding === "protobuf" && channel.schemaEncoding === "protobuf") {
    const set = descriptor.FileDescriptorSet.decode(Buffer.from(channel.schema, "base64"));
    const type = protobuf.Root.fromDescriptor(set).lookupType(channel.schemaName);
    return (view) =>
      type.toObject(type.decode(new Uint8Array(view.buffer, view.byteOffset, view.byteLength)), {
        longs: Number,
        enums: String,
        defaults: true,
      });
  }
  throw new Error(`channel ${channel.topic}: cannot decode encoding ${channel.encoding}`);
}

function done() {
  if (need.size === 0) return false;
  for (const [topic, n] of need) if ((counts.get(topic) ?? 0) < n) return false;
  return true;
}

let socket = null;
let finishing = false;

function finish(code, why) {
  if (finishing) return;
  finishing = true;
  if (why) console.error(why);
  // Close the connection with a handshake, so the server sees a clean disconnect.
  if (socket) socket.close();
  setTimeout(() => process.stdout.write("", () => process.exit(code)), 200);
}

function connect() {
  const ws = new WebSocket(url, [SUBPROTOCOL]);
  socket = ws;
  const client = new FoxgloveClient({ ws });
  client.on("error", () => {}); // connection refused before the server is up: retried below
  let served = false;
  client.on("close", () => {
    if (untilClose && served) finish(0);
    else if (!finishing) setTimeout(connect, 200);
  });
  client.on("serverInfo", (info) => {
    served = true;
    print({ kind: "server", name: info.name, capabilities: info.capabilities });
  });
  client.on("advertise", (channels) => {
    for (const channel of channels) {
      print({
        kind: "advertise",
        topic: channel.topic,
        encoding: channel.encoding,
        schemaName: channel.schemaName,
        schemaEncoding: channel.schemaEncoding ?? "",
        schema: channel.encoding === "json" ? channel.schema : "",
      });
      try {
        decoders.set(client.subscribe(channel.id), { topic: channel.topic, decode: decoder(channel) });
      } catch (err) {
        finish(2, String(err));
      }
    }
  });
  client.on("message", ({ subscriptionId, timestamp, data }) => {
    if (finishing) return;
    const sub = decoders.get(subscriptionId);
    if (!sub) return;
    let decoded;
    try {
      decoded = sub.decode(data);
    } catch (err) {
      finish(2, `${sub.topic}: cannot decode a message: ${err}`);
      return;
    }
    counts.set(sub.topic, (counts.get(sub.topic) ?? 0) + 1);
    print({ kind: "message", topic: sub.topic, logTimeNs: timestamp.toString(), data: decoded });
    if (done()) finish(0);
  });
}

setTimeout(() => {
  if (need.size === 0 && !untilClose) finish(0);
  const missing = [...need].map(([t, n]) => `${t}: ${counts.get(t) ?? 0} of ${n}`).join(", ");
  finish(1, `timed out after ${seconds} s; received ${missing}`);
}, seconds * 1000);
connect();
