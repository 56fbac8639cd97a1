// A Foxglove client for densemap's tests, built on the real client library
// (@foxglove/ws-protocol) and the decoders Foxglove itself uses (protobufjs from the advertised
// FileDescriptorSet; @foxglove/rosmsg + rosmsg2-serialization for cdr/ros2msg channels).
//
// node client.mjs --url ws://127.0.0.1:PORT --out CELLS.txt [--channels CHANNELS.json]
//                 [--version-file FILE] [--timeout-s 120] [--stall]
//
// Subscribes to every advertised channel, decodes each message, and rebuilds the occupied
// cells from /densemap/occupied (entities per block; deletions). It waits until FILE holds a
// map version V and the server's catch-up marker says V, then writes the cells (one "x y z" key
// a line, sorted), a summary of every channel's decoded messages and exits 0.
// --stall: subscribes to everything, then never reads again (a client that stopped reading).
// --follow: subscribes to everything and counts messages and bytes per topic without decoding
// them (a load-test viewer that costs its machine little); on SIGTERM writes the counts to OUT.
import fs from "node:fs";
import net from "node:net";
import process from "node:process";

import wsProtocol from "@foxglove/ws-protocol";
import { parse as parseMessageDefinition } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import protobuf from "protobufjs";
import descriptor from "protobufjs/ext/descriptor/index.js";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;

function args() {
  const a = { timeoutS: 120, stall: false, follow: false };
  const argv = process.argv.slice(2);
  for (let i = 0; i < argv.length; ++i) {
    const k = argv[i];
    if (k === "--url") a.url = argv[++i];
    else if (k === "--out") a.out = argv[++i];
    else if (k === "--channels") a.channels = argv[++i];
    else if (k === "--version-file") a.versionFile = argv[++i];
    else if (k === "--timeout-s") a.timeoutS = Number(argv[++i]);
    else if (k === "--stall") a.stall = true;
    else if (k === "--follow") a.follow = true;
    else throw new Error(`unknown argument ${k}`);
  }
  if (!a.url) throw new Error("--url is required");
  return a;
}

function fail(message) {
  console.error(`client: ${message}`);
  process.exit(1);
}

const opts = args();
const deadline =
  opts.follow || opts.stall
    ? null
    : setTimeout(() => fail(`timed out after ${opts.timeoutS} s`), opts.timeoutS * 1000);

// Waits until the server listens (it may still be starting): TCP connection attempts.
async function waitForPort(url) {
  const { hostname, port } = new URL(url);
  for (let attempt = 0; attempt < 150; ++attempt) {
    const ok = await new Promise((resolve) => {
      const socket = net.connect({ host: hostname, port: Number(port) });
      socket.once("connect", () => {
        socket.destroy();
        resolve(true);
      });
      socket.once("error", () => resolve(false));
    });
    if (ok) return;
    await new Promise((r) => setTimeout(r, 200));
  }
  fail(`nothing listens on ${url}`);
}

await waitForPort(opts.url);
const ws = new WebSocket(opts.url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });

const decoders = new Map(); // channel id -> (bytes) => object
const channelsById = new Map();
const subscriptions = new Map(); // subscription id -> channel
const counts = new Map(); // topic -> messages decoded
const cellsOf = new Map(); // entity id -> array of "x y z"
let markerVersion = -1;
let targetVersion = null;
let statusSeen = null;
let gridSeen = null;
let scanPoints = -1;
let transformsSeen = 0;
let serverInfo = null;

function decoderFor(channel) {
  if (channel.encoding === "protobuf") {
    const set = descriptor.FileDescriptorSet.decode(Buffer.from(channel.schema, "base64"));
    const root = protobuf.Root.fromDescriptor(set);
    const type = root.lookupType(channel.schemaName);
    return (bytes) => type.toObject(type.decode(bytes), { longs: Number, defaults: true });
  }
  if (channel.encoding === "cdr") {
    const reader = new MessageReader(parseMessageDefinition(channel.schema, { ros2: true }));
    return (bytes) => reader.readMessage(bytes);
  }
  if (channel.encoding === "json") {
    const decoder = new TextDecoder();
    return (bytes) => JSON.parse(decoder.decode(bytes));
  }
  fail(`channel ${channel.topic}: unknown encoding ${channel.encoding}`);
}

client.on("serverInfo", (info) => {
  serverInfo = info;
});
client.on("error", (e) => fail(`client error: ${e?.message ?? e}`));
client.on("close", () => {
  closedByServer = true;
  if (!opts.stall && !opts.follow) fail("the server closed the connection");
});
client.on("status", (s) => {
  if (s.level >= 2) console.error(`client: server status: ${s.message}`);
});

client.on("advertise", (channels) => {
  for (const c of channels) {
    channelsById.set(c.id, c);
    decoders.set(c.id, decoderFor(c));
    counts.set(c.topic, 0);
    const sub = client.subscribe(c.id);
    subscriptions.set(sub, c);
  }
  if (opts.channels) {
    const list = channels.map((c) => ({
      id: c.id,
      topic: c.topic,
      encoding: c.encoding,
      schemaName: c.schemaName,
      schemaEncoding: c.schemaEncoding,
      schemaBytes: c.schema.length,
    }));
    fs.writeFileSync(opts.channels, JSON.stringify({ serverInfo, channels: list }, null, 1));
  }
  if (opts.stall) {
    // Subscribed: now never read again (the kernel's receive buffer fills, then the server's
    // send queue).
    setTimeout(() => ws._socket.pause(), 50);
  }
});

function applySceneUpdate(update) {
  for (const d of update.deletions) cellsOf.delete(d.id);
  for (const e of update.entities) {
    if (e.id === "densemap/version") {
      const kv = e.metadata.find((m) => m.key === "map_version");
      if (kv) markerVersion = Number(kv.value);
      continue;
    }
    const cells = [];
    for (const cube of e.cubes) {
      const size = cube.size.x;
      const p = cube.pose.position;
      cells.push(`${Math.floor(p.x / size)} ${Math.floor(p.y / size)} ${Math.floor(p.z / size)}`);
    }
    cellsOf.set(e.id, cells);
  }
}

const bytesOf = new Map(); // topic -> payload bytes (--follow)
let closedByServer = false;
process.on("SIGTERM", () => {
  if (opts.out) {
    fs.writeFileSync(opts.out, JSON.stringify({
      messages: Object.fromEntries(counts),
      bytes: Object.fromEntries(bytesOf),
      markerVersion,
      closedByServer,
    }));
  }
  process.exit(0);
});

client.on("message", ({ subscriptionId, data }) => {
  const channel = subscriptions.get(subscriptionId);
  if (!channel) fail(`a message for unknown subscription ${subscriptionId}`);
  if (opts.follow) {
    counts.set(channel.topic, counts.get(channel.topic) + 1);
    bytesOf.set(channel.topic, (bytesOf.get(channel.topic) ?? 0) + data.byteLength);
    return;
  }
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  const message = decoders.get(channel.id)(bytes);
  counts.set(channel.topic, counts.get(channel.topic) + 1);
  switch (channel.topic) {
    case "/densemap/occupied":
      applySceneUpdate(message);
      break;
    case "/densemap/status":
      statusSeen = message;
      break;
    case "/densemap/grid":
      if (message.data.length !== message.info.width * message.info.height) {
        fail(`grid: ${message.data.length} cells for ${message.info.width} x ${message.info.height}`);
      }
      gridSeen = { width: message.info.width, height: message.info.height };
      break;
    case "/densemap/scan":
      scanPoints = message.width * message.height;
      if (message.data.length !== scanPoints * message.point_step) fail("scan: data size");
      break;
    case "/tf":
      transformsSeen += message.transforms.length;
      break;
    default:
      break;
  }
  maybeDone();
});

function maybeDone() {
  if (opts.stall) return;
  if (targetVersion === null && opts.versionFile && fs.existsSync(opts.versionFile)) {
    const text = fs.readFileSync(opts.versionFile, "utf8").trim();
    if (text !== "") targetVersion = Number(text);
  }
  if (targetVersion === null || markerVersion < targetVersion) return;
  if (markerVersion > targetVersion) fail(`map version ${markerVersion} passed ${targetVersion}`);
  const cells = [];
  for (const list of cellsOf.values()) cells.push(...list);
  cells.sort();
  fs.writeFileSync(opts.out, cells.join("\n") + (cells.length ? "\n" : ""));
  const summary = {
    version: markerVersion,
    cells: cells.length,
    entities: cellsOf.size,
    messages: Object.fromEntries(counts),
    status: statusSeen,
    grid: gridSeen,
    scanPoints,
    transformsSeen,
  };
  fs.writeFileSync(`${opts.out}.json`, JSON.stringify(summary, null, 1));
  if (deadline) clearTimeout(deadline);
  client.close();
  process.exit(0);
}

// The version file may appear while no message arrives (an idle server): look every 100 ms.
if (!opts.stall && !opts.follow) setInterval(maybeDone, 100);
// --stall, --follow: until SIGTERM.
if (opts.stall || opts.follow) setInterval(() => {}, 1 << 30);
