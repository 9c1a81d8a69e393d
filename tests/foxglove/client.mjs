// A Foxglove client made of Foxglove's own libraries, for tests/test_foxglove_bridge.py: the
// WebSocket client of @foxglove/ws-protocol over `ws`, speaking the subprotocol the Foxglove SDK
// serves (foxglove.sdk.v1), schemas parsed by @foxglove/omgidl-parser and messages read and
// written by @foxglove/omgidl-serialization.
//
//     node client.mjs URL STEPS_JSON   -> one JSON line per result, then {"done": true}
//
// STEPS_JSON is a list of steps, run in order:
//   {"op": "receive", "topic": T, "count": N}        N messages of T, decoded
//   {"op": "call", "service": S, "request": {...}}   a service call: its response or failure
//   {"op": "get", "names": [...]}                    parameter values
//   {"op": "set", "params": [{"name", "value"}]}     set, then the values the server sends back
//   {"op": "subscribeParams", "names": [...], "count": N}  the next N parameterValues events
//   {"op": "publish", "topic": T, "like": T2, "messages": [...], "period": MS}
//                                                    advertise T with T2's schema (cdr) and
//                                                    publish the messages, written by MessageWriter
//   {"op": "playback", "command": "play"|"pause", "speed": X, "seek": NS|null}
//                                                    a PlaybackControlRequest; the state it gets
//   {"op": "channels", "has": [...], "lacks": [...]}  once the advertised topics have and
//                                                    lack those: the topics advertised
//   {"op": "status"}                                 the next status message
//   {"op": "count", "topics": [...], "keys": {T: OFFSET|"u64last"}, "last": T, "until": N}
//                                                    each message's number (see the step)
//   {"op": "stall", "topic": T}                      subscribe, then never read again
//   {"op": "seekPlay", "topic": T, "seek": "NS", "speed": X, "count": N}
//                                                    pause, seek, play: the first N messages
//   {"op": "wait", "ms": MS}
import wsProtocol from "@foxglove/ws-protocol";
import { parseIDL } from "@foxglove/omgidl-parser";
import { MessageReader, MessageWriter } from "@foxglove/omgidl-serialization";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;
const [url, stepsText] = process.argv.slice(2);
const steps = JSON.parse(stepsText);
const SUBPROTOCOL = "foxglove.sdk.v1";
const PLAYBACK_CONTROL_REQUEST = 3; // client binary opcode
const PLAYBACK_STATE = 5; // server binary opcode

const out = (value) =>
  process.stdout.write(
    JSON.stringify(value, (_k, v) =>
      typeof v === "bigint" ? v.toString() : ArrayBuffer.isView(v) ? Array.from(v) : v,
    ) + "\n",
  );

const ws = new WebSocket(url, [SUBPROTOCOL]);
ws.binaryType = "arraybuffer";
const client = new FoxgloveClient({ ws });
const channels = new Map(); // topic -> channel
const waiters = [];
const events = [];
const notify = () => {
  for (const w of [...waiters]) w();
};
const until = (check) =>
  new Promise((resolve) => {
    const test = () => {
      const got = check();
      if (got !== undefined) {
        waiters.splice(waiters.indexOf(test), 1);
        resolve(got);
      }
    };
    waiters.push(test);
    test();
  });
const record = (kind) => (event) => {
  events.push({ kind, event });
  notify();
};

let serverInfo;
client.on("serverInfo", (info) => {
  serverInfo = info;
  notify();
});
client.on("advertise", (list) => {
  for (const c of list) channels.set(c.topic, c);
  notify();
});
client.on("unadvertise", (ids) => {
  for (const [topic, c] of channels) if (ids.includes(c.id)) channels.delete(topic);
  notify();
});
const services = new Map();
client.on("advertiseServices", (list) => {
  for (const s of list) services.set(s.name, s);
  notify();
});
client.on("message", record("message"));
client.on("serviceCallResponse", record("response"));
client.on("serviceCallFailure", record("failure"));
client.on("parameterValues", record("parameters"));
client.on("status", record("status"));
client.on("time", record("time"));
client.on("error", (e) => {
  // ws-protocol 0.8 knows no PlaybackState (read below, from the socket itself)
  if (String(e).includes(`opcode in binary message: ${PLAYBACK_STATE}`)) return;
  out({ error: String(e) });
  process.exit(1);
});
// PlaybackState is not known to ws-protocol 0.8: read from the socket itself.
ws.on("message", (data, isBinary) => {
  if (!isBinary) return;
  const view = new DataView(data instanceof ArrayBuffer ? data : new Uint8Array(data).buffer);
  if (view.getUint8(0) !== PLAYBACK_STATE) return;
  const status = view.getUint8(1);
  const time = view.getBigUint64(2, true);
  const speed = view.getFloat32(10, true);
  const didSeek = view.getUint8(14) !== 0;
  events.push({ kind: "playback", event: { status, time, speed, didSeek } });
  notify();
});

const take = (kind, filter = () => true) =>
  until(() => {
    const i = events.findIndex((e) => e.kind === kind && filter(e.event));
    if (i < 0) return undefined;
    return events.splice(i, 1)[0].event;
  });

const readers = new Map();
const readerOf = (channel) => {
  if (!readers.has(channel.id)) {
    const defs = parseIDL(channel.schema);
    readers.set(channel.id, new MessageReader(channel.schemaName, defs));
  }
  return readers.get(channel.id);
};

await until(() => serverInfo);
out({ serverInfo: { name: serverInfo.name, capabilities: serverInfo.capabilities } });
let callId = 1;
for (const step of steps) {
  if (step.op === "receive") {
    const channel = await until(() => channels.get(step.topic));
    if (channel.encoding !== "cdr" || channel.schemaEncoding !== "omgidl") {
      throw new Error(`${step.topic}: ${channel.encoding}/${channel.schemaEncoding}`);
    }
    const reader = readerOf(channel);
    const sub = client.subscribe(channel.id);
    for (let n = 0; n < step.count; n++) {
      const m = await take("message", (e) => e.subscriptionId === sub);
      const bytes = new Uint8Array(m.data.buffer, m.data.byteOffset, m.data.byteLength);
      out({
        topic: step.topic,
        schema: channel.schemaName,
        timestamp: m.timestamp,
        message: reader.readMessage(bytes),
      });
    }
    client.unsubscribe(sub);
  } else if (step.op === "call") {
    const service = await until(() => services.get(step.service));
    const id = callId++;
    client.sendServiceCallRequest({
      serviceId: service.id,
      callId: id,
      encoding: "json",
      data: new DataView(new TextEncoder().encode(JSON.stringify(step.request)).buffer),
    });
    const got = await until(() => {
      const i = events.findIndex(
        (e) => (e.kind === "response" || e.kind === "failure") && e.event.callId === id,
      );
      return i < 0 ? undefined : events.splice(i, 1)[0];
    });
    if (got.kind === "response") {
      const d = got.event.data;
      const text = new TextDecoder().decode(new Uint8Array(d.buffer, d.byteOffset, d.byteLength));
      out({ service: step.service, response: JSON.parse(text) });
    } else {
      out({ service: step.service, failure: got.event.message });
    }
  } else if (step.op === "get") {
    const id = `get-${callId++}`;
    client.getParameters(step.names, id);
    const values = await take("parameters", (e) => e.id === id);
    out({ get: values.parameters });
  } else if (step.op === "set") {
    const id = `set-${callId++}`;
    client.setParameters(step.params, id);
    const values = await take("parameters", (e) => e.id === id);
    out({ set: values.parameters });
  } else if (step.op === "subscribeParams") {
    client.subscribeParameterUpdates(step.names);
    for (let n = 0; n < step.count; n++) {
      const values = await take("parameters", (e) => e.id === undefined);
      out({ update: values.parameters });
    }
  } else if (step.op === "status") {
    const s = await take("status");
    out({ status: s.message, level: s.level });
  } else if (step.op === "publish") {
    const like = await until(() => channels.get(step.like));
    const writer = new MessageWriter(like.schemaName, parseIDL(like.schema));
    const id = client.advertise({
      topic: step.topic,
      encoding: "cdr",
      schemaName: like.schemaName,
      schemaEncoding: "omgidl",
      schema: like.schema,
    });
    for (const message of step.messages) {
      await new Promise((r) => setTimeout(r, step.period ?? 50));
      client.sendMessage(id, writer.writeMessage(message));
    }
    out({ published: step.messages.length });
  } else if (step.op === "playback") {
    const rid = new TextEncoder().encode(`pb-${callId++}`);
    const buf = new ArrayBuffer(1 + 1 + 4 + 1 + 8 + 4 + rid.length);
    const v = new DataView(buf);
    v.setUint8(0, PLAYBACK_CONTROL_REQUEST);
    v.setUint8(1, step.command === "pause" ? 1 : 0);
    v.setFloat32(2, step.speed ?? 1, true);
    v.setUint8(6, step.seek == null ? 0 : 1);
    v.setBigUint64(7, BigInt(step.seek ?? 0), true);
    v.setUint32(15, rid.length, true);
    new Uint8Array(buf, 19).set(rid);
    events.splice(0, events.length); // what came before the request is of no interest
    ws.send(buf);
    const state = await take("playback");
    out({ playback: state });
  } else if (step.op === "count") {
    // The numbers of the messages received of each topic, read straight from the CDR (a
    // camera's megabytes are not decoded): an unsigned long at the byte offset `keys[topic]`,
    // or "u64last", the last 8 bytes; until `until` of `last` have arrived.
    const subs = new Map();
    const seen = {};
    for (const topic of step.topics) {
      const channel = await until(() => channels.get(topic));
      subs.set(client.subscribe(channel.id), topic);
      seen[topic] = [];
    }
    await until(() => {
      for (let i = events.length - 1; i >= 0; i--) {
        const e = events[i];
        if (e.kind !== "message" || !subs.has(e.event.subscriptionId)) continue;
        events.splice(i, 1);
        const d = e.event.data;
        const key = step.keys[subs.get(e.event.subscriptionId)];
        seen[subs.get(e.event.subscriptionId)].push(
          key === "u64last"
            ? Number(d.getBigUint64(d.byteLength - 8, true))
            : d.getUint32(key, true),
        );
      }
      return seen[step.last].length >= step.until ? true : undefined;
    });
    for (const sub of subs.keys()) client.unsubscribe(sub);
    out({ counts: seen });
  } else if (step.op === "stall") {
    // Subscribe to `topic`, then stop reading the socket: a client that does not keep up.
    const channel = await until(() => channels.get(step.topic));
    client.subscribe(channel.id);
    await new Promise((r) => setTimeout(r, 100));
    ws._socket.pause();
    out({ stalled: step.topic });
    await new Promise(() => {}); // until killed
  } else if (step.op === "seekPlay") {
    // Pause, seek to `seek` (still paused), then play at `speed`: the first `count` messages
    // of `topic` played after, decoded with their log times.
    const channel = await until(() => channels.get(step.topic));
    const reader = readerOf(channel);
    const sub = client.subscribe(channel.id);
    const request = (command, seek) => {
      const rid = new TextEncoder().encode(`pb-${callId++}`);
      const buf = new ArrayBuffer(1 + 1 + 4 + 1 + 8 + 4 + rid.length);
      const v = new DataView(buf);
      v.setUint8(0, PLAYBACK_CONTROL_REQUEST);
      v.setUint8(1, command === "pause" ? 1 : 0);
      v.setFloat32(2, step.speed ?? 1, true);
      v.setUint8(6, seek == null ? 0 : 1);
      v.setBigUint64(7, BigInt(seek ?? 0), true);
      v.setUint32(15, rid.length, true);
      new Uint8Array(buf, 19).set(rid);
      ws.send(buf);
    };
    request("pause", null);
    out({ paused: await take("playback", (s) => s.status === 1) });
    await new Promise((r) => setTimeout(r, 300)); // what was on its way before the pause
    events.splice(0, events.length);
    request("pause", step.seek);
    out({ seeked: await take("playback", (s) => s.didSeek) });
    events.splice(0, events.length);
    request("play", null);
    for (let n = 0; n < step.count; n++) {
      const m = await take("message", (e) => e.subscriptionId === sub);
      const bytes = new Uint8Array(m.data.buffer, m.data.byteOffset, m.data.byteLength);
      out({ timestamp: m.timestamp, message: reader.readMessage(bytes) });
    }
    client.unsubscribe(sub);
  } else if (step.op === "channels") {
    await until(() =>
      (step.has ?? []).every((t) => channels.has(t)) &&
      (step.lacks ?? []).every((t) => !channels.has(t))
        ? true
        : undefined,
    );
    out({ channels: [...channels.keys()].sort() });
  } else if (step.op === "wait") {
    await new Promise((r) => setTimeout(r, step.ms));
  } else {
    throw new Error(`unknown step ${step.op}`);
  }
}
out({ done: true });
const closed = new Promise((resolve) => ws.once("close", resolve));
client.close();
await closed;
process.exit(0);
