// The station's Foxglove WebSocket (subprotocol foxglove.websocket.v1): connects with the station
// token, subscribes to the channels this page uses as they are advertised (each checked against
// the schema it must have), decodes the binary message frames with the advertised schema and
// hands each message to its Rig. Reconnects after 0.5 s, doubling to 10 s, when the socket is lost.

import { Proto } from './util.js';
import { stevi } from './state.js';
import { addProblem, clearProblem } from './problems.js';
import { getStationToken } from './api.js';
import { ensureRig, refreshRigs, rigs } from './rigs.js';

const RECONNECT_MIN_MS = 500;
const RECONNECT_MAX_MS = 10000;

// The channels this page uses (the others, /image/left, /annotations and /scene, are for
// Foxglove), with the schema each one must have.
const KINDS = {
  'tracks': 'stevi.v1.TrackFrame',
  'status': 'stevi.v1.StationRigStatus',
  'image/annotated': 'foxglove.CompressedImage',
  'image/disparity': 'foxglove.CompressedImage',
  'vehicle': 'foxglove.LocationFix',
};
const TOPIC_RE = /^\/(rig[0-9]+)\/(tracks|status|vehicle|image\/annotated|image\/disparity)$/;

const socketState = document.getElementById('socket-state');
let ws = null;
let backoffMs = RECONNECT_MIN_MS;
let reconnectTimer = null;
let countdownTimer = null;
const channels = new Map();  // channel id -> advertised channel
const subs = new Map();      // subscription id -> {id, channelId, topic, rig, kind, type, schema}
let nextSubId = 1;

function setSocketState(state, text) {
  socketState.dataset.state = state;
  socketState.textContent = text;
}

export function connect() {
  clearTimeout(reconnectTimer);
  clearInterval(countdownTimer);
  setSocketState('connecting', 'connecting…');
  let sock;
  try {
    const url = new URL('./', location.href);
    url.protocol = location.protocol === 'https:' ? 'wss:' : 'ws:';
    url.hash = '';
    const stationToken = getStationToken();
    url.search = stationToken ? `?token=${encodeURIComponent(stationToken)}` : '';
    sock = new WebSocket(url.href, ['foxglove.websocket.v1']);
  } catch (e) {
    addProblem('socket', `cannot open the station socket: ${e.message}`);
    lost();
    return;
  }
  ws = sock;
  sock.binaryType = 'arraybuffer';
  sock.onopen = () => {
    if (sock !== ws) return;
    if (sock.protocol !== 'foxglove.websocket.v1') {
      addProblem('protocol', `the station speaks "${sock.protocol}", not foxglove.websocket.v1`);
    }
    backoffMs = RECONNECT_MIN_MS;
    stevi.socketOpen = true;
    clearProblem('socket');
    setSocketState('open', 'connected');
    for (const rig of rigs.values()) rig.setStale(false);
    refreshRigs();
  };
  sock.onmessage = (ev) => {
    if (sock !== ws) return;
    if (typeof ev.data === 'string') onText(ev.data);
    else onBinary(ev.data);
  };
  sock.onclose = () => {
    if (sock !== ws) return;
    ws = null;
    lost();
  };
  sock.onerror = () => { /* onclose follows */ };
}

function lost() {
  stevi.socketOpen = false;
  channels.clear();
  subs.clear();
  stevi.subscribed = [];
  for (const rig of rigs.values()) rig.setStale(true);
  const due = Date.now() + backoffMs;
  const show = () => {
    const s = Math.max(0, Math.ceil((due - Date.now()) / 1000));
    setSocketState('closed', `station connection lost — reconnecting in ${s} s`);
  };
  show();
  countdownTimer = setInterval(show, 1000);
  reconnectTimer = setTimeout(connect, backoffMs);
  backoffMs = Math.min(backoffMs * 2, RECONNECT_MAX_MS);
}

// Drops the socket (if any) and connects again at once, as after a new station token.
export function reconnectNow() {
  backoffMs = RECONNECT_MIN_MS;
  if (ws) {
    const old = ws;
    ws = null;
    old.close();
    lost();
  }
  clearTimeout(reconnectTimer);
  clearInterval(countdownTimer);
  connect();
}

function send(obj) {
  if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(obj));
}

function onText(text) {
  let msg;
  try {
    msg = JSON.parse(text);
  } catch (e) {
    addProblem('socket-json', `the station sent bad JSON: ${e.message}`);
    return;
  }
  if (!msg || typeof msg !== 'object') return;
  switch (msg.op) {
    case 'serverInfo':
      stevi.serverInfo = { name: String(msg.name || ''), sessionId: msg.sessionId, capabilities: msg.capabilities };
      break;
    case 'advertise':
      if (Array.isArray(msg.channels)) advertise(msg.channels);
      break;
    case 'unadvertise':
      if (Array.isArray(msg.channelIds)) unadvertise(msg.channelIds);
      break;
    case 'status': {
      const level = Number(msg.level);
      const key = `status:${msg.id || msg.message}`;
      if (level >= 1) addProblem(key, `station ${level >= 2 ? 'error' : 'warning'}: ${String(msg.message)}`);
      else console.info('station:', String(msg.message));
      break;
    }
    case 'removeStatus':
      if (Array.isArray(msg.statusIds)) for (const id of msg.statusIds) clearProblem(`status:${id}`);
      break;
    default:
      break;  // ops this page does not use
  }
}

function advertise(list) {
  const subscriptions = [];
  for (const ch of list) {
    if (!ch || !Number.isInteger(ch.id) || typeof ch.topic !== 'string') continue;
    const old = channels.get(ch.id);
    channels.set(ch.id, ch);
    const m = TOPIC_RE.exec(ch.topic);
    if (!m) continue;
    const [, rigName, kind] = m;
    const rig = ensureRig(rigName);
    if (old) {  // re-advertised: keep an identical subscription, replace a changed one
      const same = old.topic === ch.topic && old.schema === ch.schema && old.schemaName === ch.schemaName;
      const existing = [...subs.values()].find((s) => s.channelId === ch.id);
      if (existing && same) continue;
      if (existing) {
        subs.delete(existing.id);
        send({ op: 'unsubscribe', subscriptionIds: [existing.id] });
      }
    }
    const sub = subscription(ch, rig, kind);
    if (!sub) continue;
    subs.set(sub.id, sub);
    subscriptions.push({ id: sub.id, channelId: ch.id });
    rig.setSchema(kind, sub.schema);
  }
  stevi.subscribed = [...subs.values()].map((s) => s.topic).sort();
  if (subscriptions.length) send({ op: 'subscribe', subscriptions });
}

// The subscription to an advertised channel of `kind`, or null (a problem said why) when the
// channel does not have the schema the kind needs or its schema does not parse.
function subscription(ch, rig, kind) {
  const key = `channel:${ch.topic}`;
  if (ch.encoding !== 'protobuf' || ch.schemaName !== KINDS[kind]) {
    addProblem(key, `${ch.topic}: expected protobuf ${KINDS[kind]}, got ${ch.encoding} ${ch.schemaName}`);
    return null;
  }
  let schema, type;
  try {
    schema = Proto.schemaFromBase64(ch.schema || '');
    type = schema.type(ch.schemaName);
  } catch (e) {
    addProblem(key, `${ch.topic}: bad schema: ${e.message}`);
    return null;
  }
  clearProblem(key);
  return { id: nextSubId++, channelId: ch.id, topic: ch.topic, rig, kind, type, schema };
}

function unadvertise(ids) {
  for (const id of ids) {
    channels.delete(id);
    for (const s of [...subs.values()]) if (s.channelId === id) subs.delete(s.id);
  }
  stevi.subscribed = [...subs.values()].map((s) => s.topic).sort();
}

function onBinary(buf) {
  if (!(buf instanceof ArrayBuffer) || buf.byteLength < 1) return;
  const view = new DataView(buf);
  const op = view.getUint8(0);
  if (op !== 0x01) return;  // 0x02 time and the others: not used
  if (buf.byteLength < 13) {
    addProblem('socket-binary', `a message frame of ${buf.byteLength} bytes (needs at least 13)`);
    return;
  }
  const sub = subs.get(view.getUint32(1, true));
  if (!sub) return;  // unsubscribed meanwhile
  // Bytes 5..12 hold the station's receive time; the messages carry their own stamps.
  let msg;
  try {
    msg = sub.type.decode(new Uint8Array(buf, 13));
  } catch (e) {
    sub.rig.pub.decodeErrors += 1;
    addProblem(`decode:${sub.topic}`, `cannot decode ${sub.topic}: ${e.message}`);
    return;
  }
  try {
    sub.rig.onMessage(sub.kind, msg);
  } catch (e) {
    addProblem(`show:${sub.topic}`, `cannot show ${sub.topic}: ${e.message}`);
    console.error(e);
  }
}
