// The stock Foxglove client (@foxglove/ws-protocol, over the `ws` package) against the bridge:
// connect offering only foxglove.websocket.v1, subscribe to TOPIC and count its messages, and,
// if PUB_TOPIC is given and the server offers clientPublish, publish the CDR bytes CDR_HEX there
// every 50 ms (schema PUB_SCHEMA from the environment, default geometry_msgs/msg/Twist). Prints one
// JSON line: what it saw, with every status message. Used by test/test_foxglove_security.py and
// test/test_foxglove_publish_refused.py.
const { FoxgloveClient } = require('@foxglove/ws-protocol');
const WebSocket = require('ws');

const [url, topic, pubTopic, cdrHex] = process.argv.slice(2);
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const pubSchema = process.env.PUB_SCHEMA || 'geometry_msgs/msg/Twist';
const out = { subprotocol: null, capabilities: null, schemaName: null, messages: 0, published: 0, status: [] };
let wanted = null;

function done(code) {
  console.log(JSON.stringify(out));
  process.exit(code);
}

ws.on('open', () => { out.subprotocol = ws.protocol; });
client.on('serverInfo', (info) => {
  out.capabilities = info.capabilities;
  if (pubTopic && info.capabilities.includes('clientPublish')) {
    const id = client.advertise({ topic: pubTopic, encoding: 'cdr', schemaName: pubSchema });
    setInterval(() => { client.sendMessage(id, Buffer.from(cdrHex, 'hex')); out.published += 1; }, 50);
  }
});
client.on('advertise', (channels) => {
  for (const channel of channels) {
    if (channel.topic === topic) {
      wanted = channel;
      out.schemaName = channel.schemaName;
      client.subscribe(channel.id);
    }
  }
});
client.on('status', (status) => {
  out.status.push(String(status.message));
  // foxglove-sdk may refuse a subscription that follows the advertisement too closely: again
  if (wanted && String(status.message).includes('Unknown channel')) {
    setTimeout(() => client.subscribe(wanted.id), 200);
  }
});
client.on('message', () => {
  out.messages += 1;
  if (out.messages >= 3 && (!pubTopic || out.published >= 10)) done(0);
});
client.on('error', (err) => { console.error(String(err)); done(1); });
setTimeout(() => done(3), 30000);
