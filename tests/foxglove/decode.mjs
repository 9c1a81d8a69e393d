// Decodes every message of an MCAP event log with Foxglove's own libraries, as Foxglove does:
// the indexed reader of @mcap/core (chunks decompressed by @mcap/support), the schema parsed by
// @foxglove/omgidl-parser and each message read by @foxglove/omgidl-serialization.
//
//     node decode.mjs FILE      -> one JSON line per message, in log-time order
import { McapIndexedReader } from "@mcap/core";
import { FileHandleReadable } from "@mcap/nodejs";
import { loadDecompressHandlers } from "@mcap/support";
import { parseIDL } from "@foxglove/omgidl-parser";
import { MessageReader } from "@foxglove/omgidl-serialization";
import { open } from "node:fs/promises";

const handle = await open(process.argv[2], "r");
const reader = await McapIndexedReader.Initialize({
  readable: new FileHandleReadable(handle),
  decompressHandlers: await loadDecompressHandlers(),
});
const readers = new Map();
for (const [id, channel] of reader.channelsById) {
  const schema = reader.schemasById.get(channel.schemaId);
  if (schema === undefined || schema.encoding !== "omgidl" || channel.messageEncoding !== "cdr") {
    throw new Error(`${channel.topic}: not an omgidl/cdr channel`);
  }
  const definitions = parseIDL(new TextDecoder().decode(schema.data));
  readers.set(id, { topic: channel.topic, schema: schema.name, reader: new MessageReader(schema.name, definitions) });
}
const plain = (_key, value) =>
  typeof value === "bigint" ? value.toString() : ArrayBuffer.isView(value) ? Array.from(value) : value;
for await (const message of reader.readMessages()) {
  const { topic, schema, reader: messageReader } = readers.get(message.channelId);
  const decoded = messageReader.readMessage(message.data);
  process.stdout.write(
    JSON.stringify(
      { topic, schema, sequence: message.sequence, logTime: message.logTime, message: decoded },
      plain,
    ) + "\n",
  );
}
await handle.close();
