// A Foxglove WebSocket client, as Foxglove's app is one: Foxglove's own protocol client
// (@foxglove/ws-protocol) over `ws`, subscribed to every channel the server advertises. Writes
// each message it receives as a JSON line: its topic, schema, log time (ns, as a string), when
// it arrived (wall clock, microseconds since the epoch) and its bytes (base64). Ends when the
// server closes the connection, or after SECONDS.
//
//     node tests/node/foxglove_client.mjs ws://127.0.0.1:PORT OUT.jsonl SECONDS
//
// The SDK's server names the protocol `foxglove.sdk.v1` (ws-protocol's `foxglove.websocket.v1`,
// renamed): the client offers that.
import { createWriteStream } from 'node:fs';
import { performance } from 'node:perf_hooks';
import wsProtocol from '@foxglove/ws-protocol';
import WebSocket from 'ws';

const [url, out, seconds] = process.argv.slice(2);
const file = createWriteStream(out);
const channels = new Map();
const subscriptions = new Map();
let lastTime = null;
let serverInfo = null;
const now = () => Math.round((performance.timeOrigin + performance.now()) * 1000);

const { FoxgloveClient } = wsProtocol;
const client = new FoxgloveClient({ ws: new WebSocket(url, ['foxglove.sdk.v1']) });
client.on('serverInfo', (info) => { serverInfo = info; });
client.on('advertise', (list) => {
  for (const channel of list) {
    channels.set(channel.id, channel);
    subscriptions.set(client.subscribe(channel.id), channel);
  }
});
client.on('time', (event) => { lastTime = event.timestamp.toString(); });
client.on('message', (event) => {
  const arrived = now();
  const channel = subscriptions.get(event.subscriptionId);
  const data = Buffer.from(event.data.buffer, event.data.byteOffset, event.data.byteLength);
  file.write(JSON.stringify({
    topic: channel.topic,
    schema: channel.schemaName,
    encoding: channel.encoding,
    log_time: event.timestamp.toString(),
    arrived,
    data: data.toString('base64'),
  }) + '\n');
});
client.on('error', (error) => { process.stderr.write(`client: ${error}\n`); });

function finish(why) {
  file.end(JSON.stringify({
    end: why,
    server: serverInfo && { name: serverInfo.name, capabilities: serverInfo.capabilities },
    time: lastTime,
    channels: [...channels.values()].map((c) => ({ topic: c.topic, schema: c.schemaName, encoding: c.encoding })),
  }) + '\n', () => process.exit(0));
}
client.on('close', () => finish('closed'));
setTimeout(() => finish('timeout'), Number(seconds) * 1000);
