// Watch a Foxglove WebSocket server as the Foxglove app does, and print a JSON report.
//
//   node test/interop/live_client.mjs URL [--topics T1,T2,...] [--seconds S]
//
// Client: @foxglove/ws-protocol's FoxgloveClient over the `ws` package, offering the
// subprotocols "foxglove.sdk.v1" (the SDK server's) and "foxglove.websocket.v1" (the client
// library's own), as the Foxglove app does. Every advertised channel's schema goes through
// @foxglove/rosmsg parse(text, {ros2: true}); the channels named by --topics (default: every one)
// are subscribed and each message decoded by @foxglove/rosmsg2-serialization MessageReader.
// Prints "subscribed N" once N channels are subscribed, then, after S seconds (default: until
// SIGINT or SIGTERM), the report: the negotiated protocol, the server's name and capabilities,
// and per topic its schema name and encodings, the schema's parse error, messages received,
// decoded and failed with the first error, the first and last decoded message, the first and
// last receive time (wall ms) and log time (ns); for each JointState its stamps and positions.
// Exit 0 once reported, 2 on a usage or connection error.
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;    // a CommonJS package: its exports by the default

const SUBPROTOCOLS = ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL];

function plain(value) {
  if (typeof value === "bigint") {
    return Number.isSafeInteger(Number(value)) ? Number(value) : value.toString();
  }
  if (ArrayBuffer.isView(value)) {
    return Array.from(value, plain);
  }
  if (Array.isArray(value)) {
    return value.map(plain);
  }
  if (value !== null && typeof value === "object") {
    return Object.fromEntries(Object.entries(value).map(([k, v]) => [k, plain(v)]));
  }
  return value;
}

function oneLine(error) {
  return String(error?.message ?? error).split(/\s+/).join(" ");
}

function usage() {
  console.error("usage: node live_client.mjs URL [--topics T1,T2] [--seconds S]");
  process.exit(2);
}

const args = process.argv.slice(2);
if (args.length < 1 || args[0].startsWith("--")) {
  usage();
}
const url = args[0];
let wanted = null;
let seconds = null;
for (let i = 1; i < args.length; i += 2) {
  if (args[i] === "--topics" && i + 1 < args.length) {
    wanted = new Set(args[i + 1].split(",").filter((t) => t));
  } else if (args[i] === "--seconds" && i + 1 < args.length) {
    seconds = Number(args[i + 1]);
  } else {
    usage();
  }
}

const ws = new WebSocket(url, SUBPROTOCOLS);
const client = new FoxgloveClient({ ws });
const report = { url, protocol: "", server: null, topics: {}, errors: [] };
const bySubscription = new Map();
let subscribed = 0;
let finished = false;

function finish(code) {
  if (finished) {
    return;
  }
  finished = true;
  for (const entry of Object.values(report.topics)) {
    entry.last = entry.last == null ? null : plain(entry.last);
  }
  console.log(JSON.stringify(report));
  client.close();
  process.exit(code);
}

client.on("open", () => {
  report.protocol = ws.protocol;
});
client.on("serverInfo", (info) => {
  report.server = { name: info.name, capabilities: info.capabilities };
});
client.on("advertise", (channels) => {
  for (const channel of channels) {
    const entry = {
      schema: channel.schemaName,
      schema_encoding: channel.schemaEncoding ?? "",
      message_encoding: channel.encoding,
      schema_error: "",
      received: 0,
      decoded: 0,
      failed: 0,
      error: "",
      first: null,
      last: null,
      first_wall_ms: null,
      last_wall_ms: null,
      first_log_ns: null,
      last_log_ns: null,
      joint_states: [],
    };
    report.topics[channel.topic] = entry;
    let reader = null;
    try {
      if (channel.schemaEncoding !== "ros2msg") {
        throw new Error(`schema encoding ${channel.schemaEncoding} is not ros2msg`);
      }
      reader = new MessageReader(parse(channel.schema, { ros2: true }));
    } catch (error) {
      entry.schema_error = oneLine(error);
    }
    if (wanted === null || wanted.has(channel.topic)) {
      const id = client.subscribe(channel.id);
      bySubscription.set(id, { entry, reader, joint: channel.schemaName === "sensor_msgs/msg/JointState" });
      subscribed += 1;
    }
  }
  const expected = wanted === null ? Object.keys(report.topics).length : wanted.size;
  if (subscribed >= expected) {
    console.log(`subscribed ${subscribed}`);
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const target = bySubscription.get(subscriptionId);
  if (target === undefined) {
    return;
  }
  const { entry, reader, joint } = target;
  const now = performance.timeOrigin + performance.now();
  entry.received += 1;
  entry.first_wall_ms ??= now;
  entry.last_wall_ms = now;
  entry.first_log_ns ??= plain(timestamp);
  entry.last_log_ns = plain(timestamp);
  if (reader === null) {
    entry.failed += 1;
    return;
  }
  try {
    const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
    const decoded = reader.readMessage(bytes);
    if (entry.decoded === 0) {
      entry.first = plain(decoded);
    }
    entry.last = decoded;
    entry.decoded += 1;
    if (joint) {
      const stamp = decoded.header.stamp;
      entry.joint_states.push([stamp.sec * 1e9 + stamp.nanosec, decoded.position[0]]);
    }
  } catch (error) {
    entry.failed += 1;
    entry.error ||= oneLine(error);
  }
});
client.on("error", (error) => {
  report.errors.push(oneLine(error));
});
client.on("close", (event) => {
  if (!finished) {
    report.errors.push(`closed: ${event?.code ?? ""} ${oneLine(event?.reason ?? "")}`.trim());
    finish(report.server === null ? 2 : 0);
  }
});
process.on("SIGINT", () => finish(0));
process.on("SIGTERM", () => finish(0));
if (seconds !== null) {
  setTimeout(() => finish(0), seconds * 1000);
}
