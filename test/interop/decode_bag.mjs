// Decode every message of one rosbag2 .mcap the way Foxglove does, and print a JSON report.
//
//   node test/interop/decode_bag.mjs BAG_0.mcap
//
// Reader: @mcap/core McapIndexedReader (zstd chunks through fzstd); per channel the schema text
// goes through @foxglove/rosmsg parse(text, {ros2: true}) and @foxglove/rosmsg2-serialization
// MessageReader. The report holds, per topic: schema name and encoding, the count in the file's
// statistics, decoded and failed counts, the first error, how many decodes left trailing bytes,
// and the first and last decoded messages (BigInt as number when safe, typed arrays as arrays).
// Exit 0 when the file was read (decoding failures are in the report), 2 on a usage or read error.
import { readFile } from "node:fs/promises";

import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import { McapIndexedReader } from "@mcap/core";
import { decompress } from "fzstd";

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

async function main(path) {
  const bytes = await readFile(path);
  const readable = {
    size: async () => BigInt(bytes.byteLength),
    read: async (offset, size) => bytes.subarray(Number(offset), Number(offset + size)),
  };
  const reader = await McapIndexedReader.Initialize({
    readable,
    decompressHandlers: { zstd: (buffer, size) => decompress(buffer, new Uint8Array(Number(size))) },
  });
  const topics = {};
  const decoders = new Map();
  for (const [id, channel] of reader.channelsById) {
    const schema = reader.schemasById.get(channel.schemaId);
    const entry = {
      schema: schema?.name ?? "",
      schema_encoding: schema?.encoding ?? "",
      message_encoding: channel.messageEncoding,
      statistics_count: Number(reader.statistics?.channelMessageCounts.get(id) ?? 0n),
      decoded: 0,
      failed: 0,
      error: "",
      trailing_bytes: 0,
      first: null,
      last: null,
    };
    topics[channel.topic] = entry;
    try {
      if (schema == undefined || schema.encoding !== "ros2msg") {
        throw new Error(`schema encoding ${schema?.encoding ?? "(none)"} is not ros2msg`);
      }
      const definitions = parse(new TextDecoder().decode(schema.data), { ros2: true });
      decoders.set(id, new MessageReader(definitions));
    } catch (error) {
      entry.error = `schema ${entry.schema}: ${oneLine(error)}`;
    }
  }
  for await (const message of reader.readMessages({ validateCrcs: true })) {
    const channel = reader.channelsById.get(message.channelId);
    const entry = topics[channel.topic];
    const decoder = decoders.get(message.channelId);
    if (decoder == undefined) {
      entry.failed += 1;
      continue;
    }
    try {
      const decoded = decoder.readMessage(message.data);
      if (decoder.lastReadHadTrailingBytes()) {
        entry.trailing_bytes += 1;
      }
      if (entry.decoded === 0) {
        entry.first = plain(decoded);
      }
      entry.last = decoded;
      entry.decoded += 1;
    } catch (error) {
      entry.failed += 1;
      if (!entry.error) {
        entry.error = `message ${message.sequence}: ${oneLine(error)}`;
      }
    }
  }
  for (const entry of Object.values(topics)) {
    entry.last = entry.last == null ? null : plain(entry.last);
  }
  return { profile: reader.header.profile, library: reader.header.library, topics };
}

if (process.argv.length !== 3) {
  console.error("usage: node decode_bag.mjs FILE.mcap");
  process.exit(2);
}
main(process.argv[2]).then(
  (report) => console.log(JSON.stringify(report)),
  (error) => {
    console.error(`decode_bag: ${process.argv[2]}: ${oneLine(error)}`);
    process.exit(2);
  },
);
