// Hostile clients against densemap's Foxglove endpoint; each case says what the server must
// answer. Exits 1 naming the first case that went otherwise. The caller checks afterwards that
// the server runs and its map is intact.
// node hostile.mjs --url ws://127.0.0.1:PORT
import net from "node:net";
import process from "node:process";

import WebSocket from "ws";

const SUBPROTOCOL = "foxglove.websocket.v1";
const url = new URL(process.argv[process.argv.indexOf("--url") + 1]);
const host = url.hostname;
const port = Number(url.port);

function fail(message) {
  console.error(`hostile: ${message}`);
  process.exit(1);
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/// Opens a Foxglove connection; resolves once serverInfo and advertise arrived.
function open() {
  return new Promise((resolve, reject) => {
    const ws = new WebSocket(url.href, [SUBPROTOCOL]);
    const texts = [];
    ws.on("message", (data, binary) => {
      if (!binary) texts.push(JSON.parse(data.toString()));
      if (texts.length === 2 && !ws.ready) {
        ws.ready = true;
        resolve({ ws, texts });
      }
    });
    ws.once("error", reject);
  });
}

/// Sends `frame` and resolves with the next status the server sends (or rejects on close).
async function expectStatus(name, frame, binary = false) {
  const { ws, texts } = await open();
  const status = new Promise((resolve, reject) => {
    ws.on("message", (data, isBinary) => {
      if (isBinary) return;
      const op = JSON.parse(data.toString());
      if (op.op === "status") resolve(op);
    });
    ws.once("close", () => reject(new Error("closed")));
  });
  ws.send(frame, { binary });
  const s = await Promise.race([status, sleep(5000).then(() => null)]).catch(() => null);
  ws.close();
  if (!s || s.level !== 2) fail(`${name}: no error status (got ${JSON.stringify(s)})`);
  if (typeof s.message !== "string" || s.message.length > 400) fail(`${name}: status ${s.message}`);
  if (texts[0].op !== "serverInfo" || texts[1].op !== "advertise") fail(`${name}: handshake`);
  return s.message;
}

/// Sends `frame` and expects the server to close the connection.
async function expectClose(name, frame) {
  const { ws } = await open();
  const closed = new Promise((resolve) => ws.once("close", (code) => resolve(code)));
  ws.send(frame);
  const code = await Promise.race([closed, sleep(5000).then(() => null)]);
  if (code === null) fail(`${name}: the connection stayed open`);
}

/// A raw TCP exchange: sends `bytes`, resolves with what came back before the server closed.
function raw(bytes, waitMs = 3000) {
  return new Promise((resolve) => {
    const socket = net.connect({ host, port });
    let got = "";
    socket.on("data", (d) => {
      got += d.toString("latin1");
    });
    socket.on("connect", () => socket.write(bytes));
    const done = () => resolve(got);
    socket.on("close", done);
    socket.on("error", done);
    setTimeout(() => {
      socket.destroy();
      done();
    }, waitMs);
  });
}

const cases = [];
const run = async (name, f) => {
  await f();
  cases.push(name);
};

await run("not JSON", () => expectStatus("not JSON", "{op: subscribe"));
await run("no op", () => expectStatus("no op", JSON.stringify({ subscriptions: [] })));
await run("unknown op", () => expectStatus("unknown op", JSON.stringify({ op: "x".repeat(5000) })));
await run("client publish", async () => {
  const m = await expectStatus("client publish", JSON.stringify({ op: "advertise", channels: [] }));
  if (!m.includes("capability")) fail(`client publish: ${m}`);
});
await run("service call op", () =>
  expectStatus("service call", JSON.stringify({ op: "getParameters", parameterNames: [] })));
await run("unknown channel", () =>
  expectStatus("unknown channel", JSON.stringify({ op: "subscribe", subscriptions: [{ id: 1, channelId: 99 }] })));
await run("negative id", () =>
  expectStatus("negative id", JSON.stringify({ op: "subscribe", subscriptions: [{ id: -1, channelId: 1 }] })));
await run("id past 32 bits", () =>
  expectStatus("big id", JSON.stringify({ op: "subscribe", subscriptions: [{ id: 2 ** 40, channelId: 1 }] })));
await run("float id", () =>
  expectStatus("float id", JSON.stringify({ op: "subscribe", subscriptions: [{ id: 1.5, channelId: 1 }] })));
await run("too many subscriptions", () =>
  expectStatus("too many", JSON.stringify({
    op: "subscribe",
    subscriptions: Array.from({ length: 2000 }, (_, i) => ({ id: i, channelId: 1 })),
  })));
await run("a reused subscription id", async () => {
  const { ws } = await open();
  const statuses = [];
  ws.on("message", (d, b) => {
    if (!b && JSON.parse(d.toString()).op === "status") statuses.push(1);
  });
  ws.send(JSON.stringify({ op: "subscribe", subscriptions: [{ id: 7, channelId: 6 }, { id: 7, channelId: 2 }] }));
  ws.send(JSON.stringify({ op: "unsubscribe", subscriptionIds: [12345] }));
  await sleep(1000);
  ws.close();
  if (statuses.length !== 2) fail(`reused id / unknown unsubscribe: ${statuses.length} statuses`);
});
await run("deep JSON", () => expectStatus("deep JSON", "[".repeat(60000)));
await run("binary garbage", () =>
  expectStatus("binary garbage", Buffer.from([0x01, 0xff, 0xff, 0xff, 0xff, 1, 2, 3]), true));
await run("empty binary", () => expectStatus("empty binary", Buffer.alloc(0), true));
await run("a huge frame", () => expectClose("huge frame", "x".repeat(1 << 20)));
await run("plain HTTP", async () => {
  const reply = await raw(`GET / HTTP/1.1\r\nHost: ${host}\r\n\r\n`);
  if (!reply.startsWith("HTTP/1.1 400") || !reply.includes("Foxglove")) fail(`plain HTTP: ${reply.slice(0, 80)}`);
});
await run("no subprotocol", async () => {
  const reply = await raw(
    `GET / HTTP/1.1\r\nHost: ${host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n` +
      "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n");
  if (!reply.startsWith("HTTP/1.1 400")) fail(`no subprotocol: ${reply.slice(0, 80)}`);
});
await run("an endless header", async () => {
  const reply = await raw(`GET / HTTP/1.1\r\nX: ${"a".repeat(100000)}`, 4000);
  if (reply.startsWith("HTTP/1.1 101")) fail("an endless header was upgraded");
});
await run("bytes that are not HTTP", () => raw(Buffer.from(Array.from({ length: 4096 }, (_, i) => (i * 7919) % 256))));
await run("half-open connections", async () => {
  // Connections that never send a byte: closed after the handshake timeout; meanwhile a real
  // client still gets in (they hold fewer than max_clients slots).
  const sockets = Array.from({ length: 4 }, () => net.connect({ host, port }));
  await sleep(300);
  const { ws } = await open();
  ws.close();
  const closed = await Promise.all(
    sockets.map((s) => new Promise((resolve) => {
      s.on("close", () => resolve(true));
      s.on("error", () => resolve(true));
      setTimeout(() => resolve(false), 9000);
    })));
  if (!closed.every(Boolean)) fail("half-open connections were not closed within 9 s");
});
await run("1,000 connections a second", async () => {
  const began = Date.now();
  const all = [];
  for (let i = 0; i < 1000; ++i) {
    all.push(new Promise((resolve) => {
      const s = net.connect({ host, port });
      s.on("connect", () => s.destroy());
      s.on("close", resolve);
      s.on("error", resolve);
    }));
    if (i % 100 === 99) await sleep(Math.max(0, (i + 1) - (Date.now() - began)));
  }
  await Promise.all(all);
  // And a burst past max_clients of real WebSocket clients: the extra ones are closed.
  const burst = await Promise.all(Array.from({ length: 20 }, () =>
    new Promise((resolve) => {
      const ws = new WebSocket(url.href, [SUBPROTOCOL]);
      ws.on("open", () => resolve(ws));
      ws.on("error", () => resolve(null));
      ws.on("close", () => resolve(null));
    })));
  const opened = burst.filter((w) => w && w.readyState === WebSocket.OPEN);
  for (const w of opened) w.close();
  if (opened.length === 0) fail("no client of the burst got in");
  await sleep(500);
  const { ws } = await open();  // a client after the flood gets in
  ws.close();
});
console.log(`hostile: ${cases.length} cases handled: ${cases.join("; ")}`);
process.exit(0);
