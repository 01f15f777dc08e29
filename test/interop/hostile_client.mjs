// Send a Foxglove WebSocket server what a broken or hostile client might, then stop reading.
//
//   node test/interop/hostile_client.mjs URL
//
// Over the `ws` package with the SDK's subprotocol "foxglove.sdk.v1": text that is not JSON,
// JSON without or with an unknown "op", subscriptions to unknown channels and a subscription id
// used twice, an unsubscription nobody made, a client channel advertised and data sent on it,
// binary frames of unknown and of data opcodes, parameter, service, asset and connection-graph
// requests (the server offers none of those capabilities), then a subscription to every
// advertised channel, after which it stops reading its socket. Prints "stalled N" (N channels
// subscribed) once it has stopped reading, and on SIGTERM the JSON list of the server's status
// messages it read before, then exits without a closing handshake.
import WebSocket from "ws";

if (process.argv.length !== 3) {
  console.error("usage: node hostile_client.mjs URL");
  process.exit(2);
}
const ws = new WebSocket(process.argv[2], ["foxglove.sdk.v1"]);
const statuses = [];
let advertised = [];
let stalled = false;

function hostile() {
  ws.send("not json at all {");
  ws.send("{}");
  ws.send(JSON.stringify({ op: "nope" }));
  ws.send(JSON.stringify({ op: "subscribe", subscriptions: [{ id: 1, channelId: 999999 }] }));
  ws.send(JSON.stringify({ op: "subscribe", subscriptions: "everything" }));
  ws.send(JSON.stringify({ op: "unsubscribe", subscriptionIds: [12345] }));
  ws.send(JSON.stringify({
    op: "advertise",
    channels: [{ id: 7, topic: "/gripper/joint_commands", encoding: "cdr",
                 schemaName: "sensor_msgs/msg/JointState" }],
  }));
  const data = Buffer.alloc(5 + 64, 0xff);
  data.writeUInt8(1, 0);            // client message data on the advertised channel 7
  data.writeUInt32LE(7, 1);
  ws.send(data);
  ws.send(Buffer.from([0xee, 1, 2, 3]));                   // an unknown binary opcode
  ws.send(Buffer.from([2]));                               // a service call, cut short
  ws.send(JSON.stringify({ op: "getParameters", parameterNames: ["/gripper/plant_simulator"] }));
  ws.send(JSON.stringify({ op: "setParameters", parameters: [{ name: "x", value: 1 }] }));
  ws.send(JSON.stringify({ op: "subscribeConnectionGraph" }));
  ws.send(JSON.stringify({ op: "fetchAsset", uri: "file:///etc/passwd", requestId: 1 }));
  const twice = advertised.slice(0, 1).flatMap((c) => [{ id: 5, channelId: c.id }]);
  ws.send(JSON.stringify({ op: "subscribe", subscriptions: [...twice, ...twice] }));
  const all = advertised.map((c, i) => ({ id: 100 + i, channelId: c.id }));
  ws.send(JSON.stringify({ op: "subscribe", subscriptions: all }), () => {
    setTimeout(() => {
      ws._socket.pause();            // read nothing more: the server's queue for us fills up
      stalled = true;
      console.log(`stalled ${all.length}`);
    }, 500);
  });
}

ws.on("message", (data, isBinary) => {
  if (stalled || isBinary) {
    return;
  }
  const message = JSON.parse(data.toString());
  if (message.op === "advertise") {
    advertised = advertised.concat(message.channels);
    if (advertised.length > 0 && !hostile.sent) {
      hostile.sent = true;
      setTimeout(hostile, 200);      // after the whole advertisement
    }
  } else if (message.op === "status") {
    statuses.push(message.message);
  }
});
ws.on("error", (error) => {
  statuses.push(`client error: ${error.message}`);
});
ws.on("close", (code, reason) => {
  statuses.push(`closed by the server: ${code} ${reason}`.trim());
});
const alive = setInterval(() => {}, 1000);       // until SIGTERM, whatever the server does
process.on("SIGTERM", () => {
  clearInterval(alive);
  process.stdout.write(`${JSON.stringify(statuses)}\n`, () => {
    ws._socket?.destroy();
    process.exit(0);
  });
});
