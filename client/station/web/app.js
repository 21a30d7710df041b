// The stevi station page: one panel per rig, fed by the station's Foxglove WebSocket channels
// (/rigK/tracks, /rigK/status, /rigK/image/annotated, /rigK/image/disparity, /rigK/vehicle) and
// its HTTP API (/api/...). Plain script, no build step, nothing from the internet.
//
// Everything received (messages, JSON, error texts) is untrusted: it reaches the page through
// textContent and attribute values only, never innerHTML.
//
// DOM hooks (for tests): #socket-state[data-state=open|closed|connecting]; #station-token-form
// (#station-token, #station-token-apply); #operator-token; #problems[data-count]; per rig
// section.rig[data-rig=rigK] with span.rig-state[data-state=up|down|connecting], .rig-address,
// .rig-error, .source-state, img.video[data-kind=annotated|disparity][data-seq][data-stamp],
// canvas.plan, div.map[data-geo=ok|none] + .map-message, a.export-geojson, a.export-kml,
// table.tracks[data-frame-id] > tbody > tr[data-track-id][data-state] > td.range[data-range-m],
// div.status [data-key], details.controls (select.algorithm, button.apply-algorithm,
// [data-field=dotted.path] inputs, span.field-error[data-field], button.apply-config,
// div.config-error, .control-result, select.snapshot-kind, button.snapshot, div.calibrations
// with button.activate-calibration[data-id]); the snapshot shows in .snapshot-overlay.
//
// window.stevi exposes the state for tests:
//   {rigs: {rig1: {name, address, lastFrame, lastStatus, lastVehicle, frames, decodeErrors,
//                  images: {annotated: n, disparity: n}, config}},
//    socketOpen, problems: [{key, message, count, time}], subscribed: [topics], serverInfo}
(function () {
  'use strict';

  const Proto = window.SteviProto;
  const GEO_STATUS_OK = 1;
  const TRAIL_S = 60;
  const RECONNECT_MIN_MS = 500;
  const RECONNECT_MAX_MS = 10000;
  const MAX_PROBLEMS = 50;
  const TOKEN_KEY = 'stevi.station_token';

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
  const RIG_RE = /^rig[0-9]+$/;
  // Used before a schema arrives (config.proto's Algorithm).
  const FALLBACK_ALGORITHMS = ['ALGORITHM_CANONICAL', 'ALGORITHM_STEVIE', 'ALGORITHM_STEVIS', 'ALGORITHM_STIXELS'];

  const stevi = {
    rigs: {},
    socketOpen: false,
    problems: [],
    subscribed: [],
    serverInfo: null,
  };
  window.stevi = stevi;

  // ---------------------------------------------------------------- small helpers

  // el('div', {class: 'x', 'data-k': 'v', onclick: f}, 'text', child, ...): strings become text.
  function el(tag, attrs, ...children) {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (v === undefined || v === null || v === false) continue;
      if (k === 'class') e.className = v;
      else if (k.startsWith('on') && typeof v === 'function') e.addEventListener(k.slice(2), v);
      else e.setAttribute(k, v === true ? '' : String(v));
    }
    for (const c of children) {
      if (c === undefined || c === null || c === false) continue;
      e.append(c instanceof Node ? c : document.createTextNode(String(c)));
    }
    return e;
  }

  function fmt(v, digits) {
    return typeof v === 'number' && Number.isFinite(v) ? v.toFixed(digits) : '—';
  }

  function fmtBytes(n) {
    if (!Number.isFinite(n)) return '—';
    if (n >= 1 << 30) return `${(n / (1 << 30)).toFixed(2)} GiB`;
    if (n >= 1 << 20) return `${(n / (1 << 20)).toFixed(1)} MiB`;
    if (n >= 1 << 10) return `${(n / (1 << 10)).toFixed(1)} KiB`;
    return `${n} B`;
  }

  // An enum value's name without its prefix ("TRACK_STATE_CONFIRMED" -> "CONFIRMED").
  function enumLabel(schema, enumName, number, prefix) {
    const name = schema ? schema.enumName(enumName, number) : String(number);
    return prefix && name.startsWith(prefix) ? name.slice(prefix.length) : name;
  }

  function attrSelector(name, value) {
    return `[${name}="${CSS.escape(String(value))}"]`;
  }

  function rigNumber(name) { return Number(name.slice(3)); }

  // ---------------------------------------------------------------- problems

  const problemCount = document.getElementById('problem-count');
  const problemList = document.getElementById('problem-list');
  const problemsBox = document.getElementById('problems');
  const problemWord = document.getElementById('problem-word');

  function addProblem(key, message) {
    let p = stevi.problems.find((x) => x.key === key);
    if (p) {
      p.count += 1;
      p.message = message;
      p.time = new Date();
    } else {
      p = { key, message, count: 1, time: new Date() };
      stevi.problems.push(p);
      if (stevi.problems.length > MAX_PROBLEMS) stevi.problems.shift();
    }
    renderProblems();
  }

  function clearProblem(key) {
    const i = stevi.problems.findIndex((x) => x.key === key);
    if (i >= 0) {
      stevi.problems.splice(i, 1);
      renderProblems();
    }
  }

  function renderProblems() {
    problemCount.textContent = String(stevi.problems.length);
    problemWord.textContent = stevi.problems.length === 1 ? 'problem' : 'problems';
    problemsBox.dataset.count = String(stevi.problems.length);
    problemList.replaceChildren(...stevi.problems.slice().reverse().map((p) =>
      el('li', { 'data-key': p.key },
        el('time', {}, p.time.toLocaleTimeString()), ' ', p.message,
        p.count > 1 ? el('span', { class: 'count' }, ` ×${p.count}`) : null)));
  }

  // ---------------------------------------------------------------- tokens and the HTTP API

  let stationToken = '';
  try { stationToken = sessionStorage.getItem(TOKEN_KEY) || ''; } catch (e) { /* storage off */ }
  let operatorToken = '';  // memory only; sent only with control POSTs

  const tokenForm = document.getElementById('station-token-form');
  const tokenInput = document.getElementById('station-token');
  const tokenMessage = document.getElementById('station-token-message');
  const operatorInput = document.getElementById('operator-token');

  operatorInput.addEventListener('input', () => { operatorToken = operatorInput.value.trim(); });
  document.getElementById('operator-form').addEventListener('submit', (ev) => ev.preventDefault());

  function showTokenPrompt(message) {
    tokenForm.hidden = false;
    tokenMessage.textContent = message;
    if (document.activeElement !== tokenInput) tokenInput.value = stationToken;
  }

  tokenForm.addEventListener('submit', (ev) => {
    ev.preventDefault();
    stationToken = tokenInput.value.trim();
    try {
      if (stationToken) sessionStorage.setItem(TOKEN_KEY, stationToken);
      else sessionStorage.removeItem(TOKEN_KEY);
    } catch (e) { /* storage off: the token lasts as long as the page */ }
    tokenMessage.textContent = 'checking…';
    refreshRigs();
    reconnectNow();
  });

  function apiUrl(path) { return new URL(path, document.baseURI).href; }

  // fetch() of the station's API with the station token. `control` adds the operator token.
  // Resolves to {status, ok, json, text, blob}; rejects only on network errors.
  async function api(path, { method = 'GET', body, control = false, as = 'json' } = {}) {
    const headers = {};
    if (stationToken) headers['Authorization'] = `Bearer ${stationToken}`;
    if (control && operatorToken) headers['X-Stevi-Operator-Token'] = operatorToken;
    if (body !== undefined) headers['Content-Type'] = 'application/json';
    const res = await fetch(apiUrl(path), {
      method, headers, body: body === undefined ? undefined : JSON.stringify(body), cache: 'no-store',
    });
    const out = { status: res.status, ok: res.ok, json: undefined, text: '', blob: undefined };
    if (res.ok && as === 'blob') {
      out.blob = await res.blob();
      return out;
    }
    out.text = await res.text();
    try { out.json = out.text ? JSON.parse(out.text) : undefined; } catch (e) { out.json = undefined; }
    if (res.status === 401 && method === 'GET') {
      showTokenPrompt(stationToken ? 'the station refused this token' : 'this station needs an access token');
    }
    return out;
  }

  // The message of an API error answer.
  function errorText(res) {
    if (res.json && typeof res.json.message === 'string') {
      return res.json.code ? `${res.json.code}: ${res.json.message}` : res.json.message;
    }
    return `HTTP ${res.status}${res.text ? `: ${res.text.slice(0, 200)}` : ''}`;
  }

  // Downloads an API resource as a file (with the token, so not through a plain link).
  async function download(path, filename) {
    const res = await api(path, { as: 'blob' });
    if (!res.ok) throw new Error(errorText(res));
    const url = URL.createObjectURL(res.blob);
    const a = el('a', { href: url, download: filename });
    document.body.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 10000);
  }

  // ---------------------------------------------------------------- rigs from /api/rigs

  let rigsRetry = null;
  let site = undefined;  // the site GeoJSON: undefined = not asked yet, null = none

  async function refreshRigs() {
    clearTimeout(rigsRetry);
    let res;
    try {
      res = await api('api/rigs');
    } catch (e) {
      addProblem('rigs', `cannot list the rigs: ${e.message}`);
      rigsRetry = setTimeout(refreshRigs, 5000);
      return;
    }
    if (res.status === 401) return;  // the prompt is shown
    if (!res.ok || !res.json || !Array.isArray(res.json.rigs)) {
      addProblem('rigs', `cannot list the rigs: ${errorText(res)}`);
      rigsRetry = setTimeout(refreshRigs, 5000);
      return;
    }
    clearProblem('rigs');
    tokenForm.hidden = true;
    tokenMessage.textContent = '';
    // The station cannot tell whether a server wants a token: its refusal says so, beside the
    // control that was refused.
    operatorInput.placeholder = 'for control calls';
    for (const r of res.json.rigs) {
      if (!r || typeof r.rig !== 'string' || !RIG_RE.test(r.rig)) continue;
      const rig = ensureRig(r.rig);
      if (typeof r.address === 'string') rig.setAddress(r.address);
    }
    if (site === undefined && res.json.site === true) loadSite();
  }

  async function loadSite() {
    site = null;
    let res;
    try {
      res = await api('api/site.geojson');
    } catch (e) {
      site = undefined;
      return;
    }
    if (res.status === 404) return;
    if (!res.ok || !res.json || typeof res.json !== 'object') {
      if (res.status !== 401) addProblem('site', `site overlay: ${errorText(res)}`);
      site = undefined;
      return;
    }
    site = res.json;
    for (const rig of rigs.values()) rig.map.setSite(site);
  }

  // ---------------------------------------------------------------- the WebSocket

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

  function connect() {
    clearTimeout(reconnectTimer);
    clearInterval(countdownTimer);
    setSocketState('connecting', 'connecting…');
    let sock;
    try {
      const url = new URL('./', location.href);
      url.protocol = location.protocol === 'https:' ? 'wss:' : 'ws:';
      url.hash = '';
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

  function reconnectNow() {
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
      const key = `channel:${ch.topic}`;
      if (ch.encoding !== 'protobuf' || ch.schemaName !== KINDS[kind]) {
        addProblem(key, `${ch.topic}: expected protobuf ${KINDS[kind]}, got ${ch.encoding} ${ch.schemaName}`);
        continue;
      }
      let schema, type;
      try {
        schema = Proto.schemaFromBase64(ch.schema || '');
        type = schema.type(ch.schemaName);
      } catch (e) {
        addProblem(key, `${ch.topic}: bad schema: ${e.message}`);
        continue;
      }
      clearProblem(key);
      const sub = { id: nextSubId++, channelId: ch.id, topic: ch.topic, rig, kind, type, schema };
      subs.set(sub.id, sub);
      subscriptions.push({ id: sub.id, channelId: ch.id });
      rig.setSchema(kind, schema);
    }
    stevi.subscribed = [...subs.values()].map((s) => s.topic).sort();
    if (subscriptions.length) send({ op: 'subscribe', subscriptions });
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

  // ---------------------------------------------------------------- rig panels

  const rigsMain = document.getElementById('rigs');
  const noRigs = document.getElementById('no-rigs');
  const rigs = new Map();

  function ensureRig(name) {
    let rig = rigs.get(name);
    if (rig) return rig;
    rig = new Rig(name);
    rigs.set(name, rig);
    const after = [...rigs.values()].filter((r) => rigNumber(r.name) > rigNumber(name))
      .sort((a, b) => rigNumber(a.name) - rigNumber(b.name))[0];
    rigsMain.insertBefore(rig.section, after ? after.section : null);
    noRigs.hidden = true;
    rig.controls.loadConfig();
    rig.controls.loadCalibrations();
    return rig;
  }

  const STATE_CLASS = { CONFIRMED: 'confirmed', TENTATIVE: 'tentative', COASTING: 'coasting' };

  class Rig {
    constructor(name) {
      this.name = name;
      this.pub = {
        name, address: '', lastFrame: undefined, lastStatus: undefined, lastVehicle: undefined,
        frames: 0, decodeErrors: 0, images: { annotated: 0, disparity: 0 }, config: undefined,
      };
      stevi.rigs[name] = this.pub;
      this.schemas = {};          // kind -> Schema
      this.imageUrls = {};        // kind -> object URL shown
      this.velocity = new Map();  // track id -> {x, y, t, vx, vy, n}
      this.renderPending = false;
      this.frameTimes = [];
      this.build();
    }

    build() {
      const n = this.name;
      this.stateEl = el('span', { class: 'rig-state', 'data-state': 'connecting' }, 'CONNECTING');
      this.addressEl = el('span', { class: 'rig-address' });
      this.errorEl = el('span', { class: 'rig-error' });
      this.sourceEl = el('span', { class: 'source-state', title: 'the stevi-server\'s source' }, 'source —');
      this.frameInfoEl = el('span', { class: 'frame-info' });
      const header = el('header', { class: 'rig-header' },
        el('h2', { class: 'rig-name' }, n), this.addressEl, this.stateEl, this.sourceEl, this.errorEl,
        el('span', { class: 'spacer' }), this.frameInfoEl);

      const videoBox = (kind, label) => {
        const img = el('img', { class: 'video', 'data-kind': kind, alt: `${n} ${label}`, 'data-seq': '0' });
        const caption = el('figcaption', {}, label);
        const placeholder = el('div', { class: 'video-placeholder' }, `no ${label} image yet`);
        img.addEventListener('load', () => {
          caption.textContent = `${label} · ${img.naturalWidth}×${img.naturalHeight}`;
        });
        img.addEventListener('error', () => {
          if (img.getAttribute('src')) addProblem(`image:${n}:${kind}`, `${n}: cannot show the ${label} image`);
        });
        return { box: el('figure', { class: 'box video-box' }, img, placeholder, caption), img, placeholder };
      };
      this.videos = { annotated: videoBox('annotated', 'annotated'), disparity: videoBox('disparity', 'disparity') };

      this.planCanvas = el('canvas', { class: 'plan', width: 400, height: 300 });
      const planBox = el('figure', { class: 'box plan-box' }, this.planCanvas,
        el('figcaption', { title: 'top-down in the body frame: x forward (up), y right' }, 'plan · body frame, x forward'));
      this.plan = new PlanView(this.planCanvas);

      const mapDiv = el('div', { class: 'map' });
      const mapMessage = el('div', { class: 'map-message' }, 'waiting for track frames…');
      const geojsonLink = el('a', { class: 'export-geojson', href: `api/rigs/${n}/export.geojson`, download: `${n}-tracks.geojson` }, 'GeoJSON');
      const kmlLink = el('a', { class: 'export-kml', href: `api/rigs/${n}/export.kml`, download: `${n}-tracks.kml` }, 'KML');
      for (const [a, file] of [[geojsonLink, `${n}-tracks.geojson`], [kmlLink, `${n}-tracks.kml`]]) {
        a.addEventListener('click', (ev) => {
          if (!stationToken) return;  // a plain link does
          ev.preventDefault();
          download(a.getAttribute('href'), file).catch((e) => addProblem(`export:${n}`, `${n}: export failed: ${e.message}`));
        });
      }
      const fitButton = el('button', { class: 'map-fit', type: 'button', title: 'follow the vehicle again' }, 'fit');
      const mapBox = el('figure', { class: 'box map-box' }, mapDiv, mapMessage,
        el('figcaption', {}, el('span', { title: 'local metres around the first vehicle fix, north up' }, 'map · north up'), el('span', { class: 'spacer' }),
          fitButton, ' export ', geojsonLink, ' ', kmlLink));
      this.map = new RigMap(mapDiv, mapMessage);
      fitButton.addEventListener('click', () => this.map.follow());
      if (site) this.map.setSite(site);

      this.table = el('table', { class: 'tracks' },
        el('thead', {}, el('tr', {}, ...['id', 'state', 'range', 'rate', 'TTC', 'lat', 'lon', 'alt']
          .map((h) => el('th', {}, h)))),
        el('tbody'));
      this.tbody = this.table.tBodies[0];
      this.tableCaption = el('div', { class: 'tracks-caption' }, 'no track frame yet');
      const tracksBox = el('div', { class: 'box tracks-box' }, this.tableCaption, el('div', { class: 'table-scroll' }, this.table));

      this.statusEl = el('div', { class: 'status box' });
      this.renderStatus();

      this.controls = new Controls(this);

      this.section = el('section', { class: 'rig', 'data-rig': n },
        header,
        el('div', { class: 'rig-body' },
          this.videos.annotated.box, this.videos.disparity.box, planBox, mapBox, tracksBox,
          this.statusEl, this.controls.root));
    }

    setAddress(address) {
      this.pub.address = address;
      this.addressEl.textContent = address;
    }

    setStale(stale) { this.section.classList.toggle('stale', stale); }

    setSchema(kind, schema) {
      this.schemas[kind] = schema;
      if (kind === 'tracks') this.controls.schemaArrived(schema);
    }

    onMessage(kind, msg) {
      switch (kind) {
        case 'tracks': this.onTrackFrame(msg); break;
        case 'status': this.onStatus(msg); break;
        case 'image/annotated': this.onImage('annotated', msg); break;
        case 'image/disparity': this.onImage('disparity', msg); break;
        case 'vehicle': this.pub.lastVehicle = msg; this.map.setFix(msg); break;
        default: break;
      }
    }

    // ---- images

    onImage(kind, msg) {
      const v = this.videos[kind];
      const format = (msg.format || 'jpeg').toLowerCase();
      const type = { jpeg: 'image/jpeg', jpg: 'image/jpeg', png: 'image/png', webp: 'image/webp', avif: 'image/avif' }[format] || 'image/jpeg';
      const url = URL.createObjectURL(new Blob([msg.data], { type }));
      const previous = this.imageUrls[kind];
      this.imageUrls[kind] = url;
      v.img.src = url;
      if (previous) URL.revokeObjectURL(previous);  // the shown image stays until the new one loads
      const count = this.pub.images[kind] + 1;
      this.pub.images[kind] = count;
      const ts = msg.timestamp || { seconds: 0, nanos: 0 };
      v.img.dataset.seq = String(count);
      v.img.dataset.stamp = `${ts.seconds}.${String(ts.nanos).padStart(9, '0')}`;
      v.placeholder.hidden = true;
    }

    // ---- status

    onStatus(s) {
      this.pub.lastStatus = s;
      if (s.address) this.setAddress(s.address);
      const schema = this.schemas.status;
      const name = enumLabel(schema, 'stevi.v1.StationRigStatus.Connection', s.connection, 'CONNECTION_');
      const state = { UP: 'up', DOWN: 'down', CONNECTING: 'connecting' }[name] ||
        ({ 1: 'connecting', 2: 'up', 3: 'down' }[s.connection] || 'connecting');
      if (state === 'up' && this.stateEl.dataset.state !== 'up') {  // came up: fetch what failed
        if (!this.controls.config) this.controls.loadConfig();
        if (!this.controls.calibrationsLoaded) this.controls.loadCalibrations();
      }
      this.stateEl.dataset.state = state;
      this.stateEl.textContent = state.toUpperCase();
      if (state === 'down') {
        this.errorEl.textContent = `${s.error || 'down'} (for ${fmt(s.down_for_s, 0)} s)`;
      } else if (state === 'connecting' && s.error) {
        this.errorEl.textContent = s.error;
      } else {
        this.errorEl.textContent = '';
      }
      if (s.server) {
        const src = enumLabel(schema, 'stevi.v1.SourceState', s.server.source_state, 'SOURCE_STATE_');
        this.sourceEl.textContent = `source ${src}`;
        this.sourceEl.dataset.state = src.toLowerCase();
      } else {
        this.sourceEl.textContent = 'source —';
        delete this.sourceEl.dataset.state;
      }
      this.renderStatus();
    }

    renderStatus() {
      const s = this.pub.lastStatus;
      const srv = s && s.server;
      const f = this.pub.lastFrame;
      const schema = this.schemas.status;
      const rows = [];
      const row = (key, label, value, title) => rows.push(
        el('div', { class: 'status-row' }, el('span', { class: 'k' }, label),
          el('span', { class: 'v', 'data-key': key, title }, value)));
      if (srv) {
        const src = enumLabel(schema, 'stevi.v1.SourceState', srv.source_state, 'SOURCE_STATE_');
        row('source', 'source', `${src}${srv.source ? ` — ${srv.source}` : ''}${srv.source_error ? ` (${srv.source_error})` : ''}`);
        row('fps', 'fps in / out', `${fmt(srv.fps_in, 1)} / ${fmt(srv.fps_out, 1)}`);
        row('dropped', 'dropped', `capture ${srv.frames_dropped_capture} · subscriber ${f ? f.dropped_frames : '—'}`,
          'frames the server replaced before processing; TrackFrames this station lost');
        row('failed', 'failed', String(srv.frames_failed));
        row('timings', 'stages ms', srv.timings.length
          ? srv.timings.map((t) => `${t.stage} ${fmt(t.ms, 1)}`).join(' · ') : '—');
        const p = srv.pairing;
        row('pairing', 'pairing', p && (p.pairs || p.unpaired_dropped || p.incomplete_dropped)
          ? `${p.pairs} pairs · unpaired ${p.unpaired_dropped} · incomplete ${p.incomplete_dropped} · ` +
            `skew ${fmt(p.last_skew_ns / 1e6, 2)} ms (max ${fmt(p.max_abs_skew_ns / 1e6, 2)}) · reconnects ${p.reconnects}`
          : '— (one source)');
        const r = srv.recording;
        row('recording', 'recording', r && r.active
          ? `REC ${r.frames_written} frames, ${fmtBytes(r.bytes_written)}${r.frames_dropped ? `, ${r.frames_dropped} dropped` : ''} → ${r.dir}`
          : (r && r.stop_reason ? `off (last: ${r.stop_reason})` : 'off'));
        row('algorithm', 'algorithm', `${enumLabel(schema, 'stevi.v1.Algorithm', srv.algorithm, 'ALGORITHM_')} · calibration ${srv.calibration_id || '—'}`);
        row('image', 'image', srv.processed_width
          ? `${srv.image_width}×${srv.image_height}${srv.binning > 1 ? ` binned ×${srv.binning} → ${srv.processed_width}×${srv.processed_height}` : ''}`
          : '—');
        row('uptime', 'uptime', `${fmt(srv.uptime_s / 3600, 2)} h · workers ${srv.pipeline_workers}`);
      } else {
        row('source', 'source', s ? 'no server status' : '—');
      }
      row('station', 'station', s
        ? `tracks ${fmt(s.track_frames_per_s, 1)}/s · previews ${fmt(s.previews_per_s, 1)}/s · reconnects ${s.reconnects}`
        : '—');
      this.statusEl.replaceChildren(...rows);
    }

    // ---- track frames

    onTrackFrame(f) {
      this.pub.lastFrame = f;
      this.pub.frames += 1;
      const now = performance.now();
      this.frameTimes.push(now);
      while (this.frameTimes.length > 1 && now - this.frameTimes[0] > 3000) this.frameTimes.shift();
      this.updateVelocities(f);
      this.map.addFrame(f, this.schemas.tracks);
      this.scheduleRender();
    }

    // Relative velocity of each track in the body frame, for the plan's arrows: the change of
    // position_body over time, smoothed. (Track.velocity_cam is filtered but in the camera frame,
    // and rotating it needs PipelineConfig.mount; velocity_ned is over the ground, not relative to
    // us. The position_body differences need neither and are what the plan shows moving.)
    updateVelocities(f) {
      const t = f.capture_time_ns ? f.capture_time_ns / 1e9 : f.capture_unix_time_ns / 1e9;
      const seen = new Set();
      for (const tr of f.tracks) {
        if (!tr.position_body) continue;
        seen.add(tr.track_id);
        const x = tr.position_body.x_m;
        const y = tr.position_body.y_m;
        const v = this.velocity.get(tr.track_id);
        if (!v) {
          this.velocity.set(tr.track_id, { x, y, t, vx: 0, vy: 0, n: 0 });
          continue;
        }
        const dt = t - v.t;
        if (dt > 0 && dt <= 1.5) {
          const vx = (x - v.x) / dt;
          const vy = (y - v.y) / dt;
          const a = v.n ? 0.3 : 1;
          v.vx += a * (vx - v.vx);
          v.vy += a * (vy - v.vy);
          v.n += 1;
        } else if (dt > 1.5 || dt < 0) {
          v.n = 0;
        }
        v.x = x; v.y = y; v.t = t;
      }
      for (const id of [...this.velocity.keys()]) if (!seen.has(id)) this.velocity.delete(id);
    }

    scheduleRender() {
      if (this.renderPending) return;
      this.renderPending = true;
      const run = () => {
        if (!this.renderPending) return;
        this.renderPending = false;
        this.render();
      };
      requestAnimationFrame(run);
      setTimeout(run, 200);  // when the page is hidden, rAF does not run
    }

    render() {
      const f = this.pub.lastFrame;
      if (!f) return;
      const schema = this.schemas.tracks;
      const stateName = (n) => enumLabel(schema, 'stevi.v1.TrackState', n, 'TRACK_STATE_');
      const tracks = f.tracks.slice().sort((a, b) => a.range_m - b.range_m);
      this.table.dataset.frameId = String(f.frame_id);
      this.tbody.replaceChildren(...tracks.map((t) => {
        const state = stateName(t.state);
        const g = t.geodetic;
        return el('tr', { 'data-track-id': String(t.track_id), 'data-state': STATE_CLASS[state] || 'other' },
          el('td', { class: 'id' }, String(t.track_id)),
          el('td', { class: 'state' }, state),
          el('td', { class: 'range', 'data-range-m': String(t.range_m) }, `${fmt(t.range_m, 1)} ± ${fmt(t.range_sigma_m, 1)} m`),
          el('td', { class: 'rate' }, `${fmt(t.range_rate_mps, 1)} m/s`),
          el('td', { class: 'ttc' }, t.time_to_collision_s !== undefined ? `${fmt(t.time_to_collision_s, 1)} s` : '—'),
          el('td', { class: 'lat' }, g ? fmt(g.lat_deg, 6) : '—'),
          el('td', { class: 'lon' }, g ? fmt(g.lon_deg, 6) : '—'),
          el('td', { class: 'alt' }, g ? fmt(g.alt_m, 1) : '—'));
      }));
      const alg = enumLabel(schema, 'stevi.v1.Algorithm', f.algorithm, 'ALGORITHM_');
      this.tableCaption.textContent = `frame ${f.frame_id} · ${f.tracks.length} track${f.tracks.length === 1 ? '' : 's'} · ${alg}`;
      const times = this.frameTimes;
      const hz = times.length > 1 ? (times.length - 1) / ((times[times.length - 1] - times[0]) / 1000) : 0;
      this.frameInfoEl.textContent = `frame ${f.frame_id} · ${fmt(hz, 1)} Hz`;
      this.plan.draw(f, this.velocity, stateName);
      this.map.render();
      this.renderStatus();
    }
  }

  // ---------------------------------------------------------------- the plan view

  const STATE_COLOUR = { CONFIRMED: '#ff5b5b', COASTING: '#f2b84b', TENTATIVE: '#9aa6b6' };

  // Top-down, body frame: x forward up the screen, y right. Rings every 10 m (coarser when there
  // would be too many), the range scan's field of view and free space, the tracks.
  class PlanView {
    constructor(canvas) {
      this.canvas = canvas;
      this.last = null;
      if (typeof ResizeObserver !== 'undefined') {
        new ResizeObserver(() => { if (this.last) this.draw(...this.last); else this.draw(null); }).observe(canvas);
      }
      this.draw(null);
    }

    draw(frame, velocity, stateName) {
      this.last = frame ? [frame, velocity, stateName] : null;
      const c = this.canvas;
      const dpr = window.devicePixelRatio || 1;
      const w = Math.max(50, c.clientWidth || 400);
      const h = Math.max(50, c.clientHeight || 300);
      if (c.width !== Math.round(w * dpr) || c.height !== Math.round(h * dpr)) {
        c.width = Math.round(w * dpr);
        c.height = Math.round(h * dpr);
      }
      const g = c.getContext('2d');
      g.setTransform(dpr, 0, 0, dpr, 0, 0);
      g.fillStyle = '#0d1117';
      g.fillRect(0, 0, w, h);
      g.font = '11px system-ui, sans-serif';
      if (!frame) {
        g.fillStyle = '#8b949e';
        g.fillText('waiting for track frames…', 10, 20);
        return;
      }
      const scan = frame.range_scan;
      const tracks = frame.tracks.filter((t) => t.position_body);
      let maxRange = 20;
      if (scan && scan.max_range_m > 0) maxRange = Math.max(maxRange, scan.max_range_m);
      let behind = false;
      for (const t of tracks) {
        const r = Math.hypot(t.position_body.x_m, t.position_body.y_m);
        maxRange = Math.max(maxRange, r * 1.1);
        if (t.position_body.x_m < 0) behind = true;
      }
      const scanStart = scan ? scan.start_azimuth_deg : 0;
      const scanEnd = scan ? scan.start_azimuth_deg + scan.bin_width_deg * scan.range_m.length : 0;
      if (scan && (scanStart < -90 || scanEnd > 90)) behind = true;
      // Origin at the bottom when everything is ahead, else in the middle.
      const ox = w / 2;
      const oy = behind ? h / 2 : h - 14;
      const s = Math.min(behind ? h / 2 - 8 : h - 24, w / 2 - 8) / maxRange;  // px per metre
      const P = (x, y) => [ox + y * s, oy - x * s];
      const A = (azDeg, r) => {
        const a = (azDeg * Math.PI) / 180;
        return P(r * Math.cos(a), r * Math.sin(a));
      };

      // Range rings.
      let step = 10;
      while (maxRange / step > 12) step = step < 50 ? step * 2.5 : step * 2;
      g.strokeStyle = '#263040';
      g.fillStyle = '#6e7b8b';
      g.lineWidth = 1;
      // Labels on a bearing left of the field of view, clear of the tracks.
      const labelAz = Math.min(-50, (scan ? scanStart : 0) - 10);
      g.textAlign = 'right';
      for (let r = step; r <= maxRange + 1e-6; r += step) {
        g.beginPath();
        g.arc(ox, oy, r * s, 0, 2 * Math.PI);
        g.stroke();
        const [lx, ly] = A(labelAz, r);
        g.fillText(`${r} m`, lx - 2, ly - 2);
      }
      g.textAlign = 'left';
      g.beginPath();
      g.moveTo(ox, oy); g.lineTo(ox, oy - maxRange * s);
      g.moveTo(ox - maxRange * s, oy); g.lineTo(ox + maxRange * s, oy);
      g.stroke();

      // The range scan: field of view, free space to the nearest range per bin, obstacles.
      if (scan && scan.range_m.length && scan.bin_width_deg > 0) {
        const far = scan.max_range_m > 0 ? scan.max_range_m : maxRange;
        g.beginPath();
        g.moveTo(ox, oy);
        scan.range_m.forEach((r, i) => {
          const a0 = scanStart + i * scan.bin_width_deg;
          const rr = r > 0 ? r : far;
          g.lineTo(...A(a0, rr));
          g.lineTo(...A(a0 + scan.bin_width_deg, rr));
        });
        g.closePath();
        g.fillStyle = 'rgba(63, 185, 80, 0.13)';
        g.fill();
        // Field of view edges.
        g.strokeStyle = 'rgba(88, 166, 255, 0.6)';
        g.setLineDash([4, 4]);
        g.beginPath();
        g.moveTo(ox, oy); g.lineTo(...A(scanStart, far));
        g.moveTo(ox, oy); g.lineTo(...A(scanEnd, far));
        g.stroke();
        g.setLineDash([]);
        // The scan as a polyline of the per-bin nearest ranges (clear bins at the far limit).
        g.strokeStyle = 'rgba(63, 185, 80, 0.7)';
        g.beginPath();
        scan.range_m.forEach((r, i) => {
          const p = A(scanStart + (i + 0.5) * scan.bin_width_deg, r > 0 ? r : far);
          if (i === 0) g.moveTo(...p); else g.lineTo(...p);
        });
        g.stroke();
        // Occupied bins.
        g.strokeStyle = '#ff7b54';
        g.lineWidth = 3;
        scan.range_m.forEach((r, i) => {
          if (!(r > 0)) return;
          const a0 = scanStart + i * scan.bin_width_deg;
          g.beginPath();
          g.moveTo(...A(a0, r));
          g.lineTo(...A(a0 + scan.bin_width_deg, r));
          g.stroke();
        });
        g.lineWidth = 1;
      } else {
        g.fillStyle = '#6e7b8b';
        g.fillText('no range scan', 8, 14);
      }

      // The vehicle.
      g.fillStyle = '#58a6ff';
      g.beginPath();
      g.moveTo(ox, oy - 8); g.lineTo(ox - 5, oy + 5); g.lineTo(ox + 5, oy + 5);
      g.closePath();
      g.fill();

      // Tracks, nearest drawn last (on top).
      const sorted = tracks.slice().sort((a, b) => b.range_m - a.range_m);
      g.font = '11px ui-monospace, monospace';
      for (const t of sorted) {
        const state = stateName(t.state);
        const colour = STATE_COLOUR[state] || '#9aa6b6';
        const [px, py] = P(t.position_body.x_m, t.position_body.y_m);
        const v = velocity.get(t.track_id);
        if (v && v.n > 0) {  // where it will be in 2 s
          const [qx, qy] = P(t.position_body.x_m + 2 * v.vx, t.position_body.y_m + 2 * v.vy);
          g.strokeStyle = colour;
          g.lineWidth = 1.5;
          g.beginPath(); g.moveTo(px, py); g.lineTo(qx, qy); g.stroke();
          const ang = Math.atan2(qy - py, qx - px);
          g.beginPath();
          g.moveTo(qx, qy);
          g.lineTo(qx - 6 * Math.cos(ang - 0.4), qy - 6 * Math.sin(ang - 0.4));
          g.lineTo(qx - 6 * Math.cos(ang + 0.4), qy - 6 * Math.sin(ang + 0.4));
          g.closePath();
          g.fillStyle = colour;
          g.fill();
          g.lineWidth = 1;
        }
        g.beginPath();
        g.arc(px, py, 5, 0, 2 * Math.PI);
        if (state === 'COASTING') {
          g.strokeStyle = colour; g.lineWidth = 2; g.stroke(); g.lineWidth = 1;
        } else {
          g.fillStyle = colour; g.fill();
        }
        g.fillStyle = '#e6edf3';
        let label = `${t.track_id}`;
        if (t.time_to_collision_s !== undefined) label += ` TTC ${t.time_to_collision_s.toFixed(1)} s`;
        g.fillText(label, px + 8, py - 6);
      }
      g.fillStyle = '#6e7b8b';
      g.font = '11px system-ui, sans-serif';
      g.fillText(`${tracks.length} track${tracks.length === 1 ? '' : 's'} · range ${fmt(maxRange, 0)} m`, 8, h - 4);
    }
  }

  // ---------------------------------------------------------------- the map

  const EARTH_R = 6378137;  // WGS84 equatorial radius, m; flat earth around the first fix

  // Leaflet without tiles, CRS.Simple in local metres (LatLng = [north, east]) around the first
  // vehicle fix: the vehicle with its heading, the tracks' geodetic positions and their last
  // minute, and the site overlay.
  class RigMap {
    constructor(div, message) {
      this.div = div;
      this.message = message;
      this.origin = null;   // [lat, lon] of the first fix
      this.trails = new Map();  // track id -> {points: [[t, north, east]], line, marker}
      this.vehiclePath = [];
      this.pending = null;
      this.siteLayer = null;
      this.site = null;
      this.following = true;
      this.lastFit = 0;
      this.ok = typeof window.L !== 'undefined' && window.L.map;
      if (!this.ok) {
        this.setMessage('map unavailable: Leaflet did not load (leaflet/leaflet.js)');
        div.classList.add('map-unavailable');
        return;
      }
      const L = window.L;
      this.map = L.map(div, {
        crs: L.CRS.Simple, attributionControl: false, minZoom: -8, maxZoom: 6, zoomSnap: 0.25,
        zoomDelta: 0.5, zoomAnimation: false, fadeAnimation: false, markerZoomAnimation: false,
      });
      this.map.setView([0, 0], 0);
      L.control.scale({ imperial: false, maxWidth: 120 }).addTo(this.map);
      this.trailLayer = L.layerGroup().addTo(this.map);
      this.trackLayer = L.layerGroup().addTo(this.map);
      this.vehicleLine = L.polyline([], { color: '#58a6ff', weight: 1.5, opacity: 0.6, interactive: false }).addTo(this.map);
      this.arrow = el('div', { class: 'vehicle-arrow' });
      this.vehicle = L.marker([0, 0], {
        icon: L.divIcon({ className: 'vehicle-icon', html: this.arrow, iconSize: [20, 20], iconAnchor: [10, 10] }),
        interactive: false, keyboard: false,
      });
      for (const ev of ['mousedown', 'wheel', 'touchstart']) {
        div.addEventListener(ev, () => { this.following = false; }, { passive: true });
      }
      if (typeof ResizeObserver !== 'undefined') {
        new ResizeObserver(() => this.map.invalidateSize(false)).observe(div);
      }
    }

    setMessage(text) {
      this.message.textContent = text;
      this.message.hidden = !text;
    }

    follow() {
      this.following = true;
      this.lastFit = 0;
      this.render();
    }

    toLocal(lat, lon) {
      const [lat0, lon0] = this.origin;
      const k = Math.PI / 180;
      return [(lat - lat0) * k * EARTH_R, (lon - lon0) * k * EARTH_R * Math.cos(lat0 * k)];
    }

    setOrigin(lat, lon) {
      if (this.origin) return;
      this.origin = [lat, lon];
      if (this.site) this.setSite(this.site);
    }

    setSite(geojson) {
      this.site = geojson;
      if (!this.ok || !this.origin) return;
      const L = window.L;
      if (this.siteLayer) this.siteLayer.remove();
      try {
        this.siteLayer = L.geoJSON(geojson, {
          coordsToLatLng: (c) => L.latLng(...this.toLocal(Number(c[1]), Number(c[0]))),
          style: () => ({ color: '#a371f7', weight: 1.5, opacity: 0.8, fillOpacity: 0.08 }),
          pointToLayer: (feature, latlng) => L.circleMarker(latlng, { radius: 4, color: '#a371f7' }),
          onEachFeature: (feature, layer) => {
            const name = feature && feature.properties && feature.properties.name;
            if (typeof name === 'string' && name) layer.bindTooltip(el('span', {}, name));
          },
        }).addTo(this.map);
        this.siteLayer.bringToBack();
        clearProblem('site-draw');
      } catch (e) {
        addProblem('site-draw', `site overlay: ${e.message}`);
      }
    }

    // A foxglove.LocationFix: used for the vehicle only while the frames have none.
    setFix(fix) {
      if (!this.ok || !Number.isFinite(fix.latitude) || !Number.isFinite(fix.longitude)) return;
      this.fix = fix;
      this.setOrigin(fix.latitude, fix.longitude);
    }

    addFrame(f, schema) {
      const t = f.capture_unix_time_ns ? f.capture_unix_time_ns / 1e9 : Date.now() / 1000;
      const geo = f.geo_status === GEO_STATUS_OK && f.vehicle && f.vehicle.position;
      this.pending = { f, schema, geo };
      if (this.lastT !== undefined && t < this.lastT - 1) this.clearTrails();  // a replay looped
      this.lastT = t;
      if (!geo) return;
      const p = f.vehicle.position;
      this.setOrigin(p.lat_deg, p.lon_deg);
      const [vn, ve] = this.toLocal(p.lat_deg, p.lon_deg);
      this.vehiclePath.push([t, vn, ve]);
      for (const tr of f.tracks) {
        if (!tr.geodetic) continue;
        let trail = this.trails.get(tr.track_id);
        if (!trail) {
          trail = { points: [], line: null, marker: null, state: null };
          this.trails.set(tr.track_id, trail);
        }
        trail.points.push([t, ...this.toLocal(tr.geodetic.lat_deg, tr.geodetic.lon_deg)]);
      }
      // The last minute only.
      const cutoff = t - TRAIL_S;
      const prune = (pts) => { let i = 0; while (i < pts.length && pts[i][0] < cutoff) ++i; if (i) pts.splice(0, i); };
      prune(this.vehiclePath);
      for (const [id, trail] of [...this.trails]) {
        prune(trail.points);
        if (!trail.points.length) {
          if (trail.line) trail.line.remove();
          if (trail.marker) trail.marker.remove();
          this.trails.delete(id);
        }
      }
    }

    clearTrails() {
      for (const trail of this.trails.values()) {
        if (trail.line) trail.line.remove();
        if (trail.marker) trail.marker.remove();
      }
      this.trails.clear();
      this.vehiclePath = [];
    }

    render() {
      const pend = this.pending;
      if (!pend) return;
      const { f, schema, geo } = pend;
      if (!this.ok) return;  // the message says Leaflet is missing
      if (!geo) {
        const status = enumLabel(schema, 'stevi.v1.GeoStatus', f.geo_status, '');
        this.setMessage(`no georeferenced positions (geo_status: ${status})${f.geo_message ? `: ${f.geo_message}` : ''}`);
        this.div.dataset.geo = 'none';
      } else {
        this.setMessage('');
        this.div.dataset.geo = 'ok';
      }
      if (!this.origin) return;
      const L = window.L;
      const stateName = (n) => enumLabel(schema, 'stevi.v1.TrackState', n, 'TRACK_STATE_');
      const current = new Set(geo ? f.tracks.filter((t) => t.geodetic).map((t) => t.track_id) : []);
      for (const [id, trail] of this.trails) {
        const latlngs = trail.points.map((p) => [p[1], p[2]]);
        if (!trail.line) trail.line = L.polyline(latlngs, { weight: 1.5, opacity: 0.7, interactive: false }).addTo(this.trailLayer);
        else trail.line.setLatLngs(latlngs);
        const tr = current.has(id) ? f.tracks.find((t) => t.track_id === id) : undefined;
        const state = tr ? stateName(tr.state) : 'GONE';
        const colour = STATE_COLOUR[state] || '#6e7b8b';
        trail.line.setStyle({ color: colour });
        if (tr) {
          const last = latlngs[latlngs.length - 1];
          if (!trail.marker) {
            trail.marker = L.circleMarker(last, { radius: 6, weight: 2 }).addTo(this.trackLayer);
            trail.marker.bindTooltip(el('span', {}, String(id)), { permanent: true, direction: 'right', className: 'track-label', offset: [6, 0] });
          }
          trail.marker.setLatLng(last);
          trail.marker.setStyle({ color: colour, fillColor: colour, fillOpacity: state === 'COASTING' ? 0.1 : 0.8 });
          trail.marker.getElement && trail.marker.getElement() && trail.marker.getElement().setAttribute('data-track-id', String(id));
        } else if (trail.marker) {
          trail.marker.remove();
          trail.marker = null;
        }
      }
      let vpos = null;
      let heading = 0;
      if (geo) {
        const p = f.vehicle.position;
        vpos = this.toLocal(p.lat_deg, p.lon_deg);
        heading = f.vehicle.yaw_deg;
      } else if (this.fix) {
        vpos = this.toLocal(this.fix.latitude, this.fix.longitude);
        heading = this.fix.heading || 0;
      }
      if (vpos) {
        this.vehicle.setLatLng(vpos);
        if (!this.map.hasLayer(this.vehicle)) this.vehicle.addTo(this.map);
        this.arrow.style.transform = `rotate(${Number(heading) || 0}deg)`;
        this.vehicleLine.setLatLngs(this.vehiclePath.map((p) => [p[1], p[2]]));
      }
      const now = performance.now();
      if (this.following && vpos && now - this.lastFit > 1000) {
        this.lastFit = now;
        let b = L.latLngBounds([vpos, vpos]);
        for (const id of current) {
          const pts = this.trails.get(id).points;
          const last = pts[pts.length - 1];
          b = b.extend([last[1], last[2]]);
        }
        const pad = 25;  // at least 50 m across
        b = b.extend([vpos[0] - pad, vpos[1] - pad]).extend([vpos[0] + pad, vpos[1] + pad]);
        this.map.fitBounds(b, { padding: [16, 16], animate: false });
      }
    }
  }

  // ---------------------------------------------------------------- controls

  // The parameter editor's leaves: {input, path, kind: 'bool'|'int'|'float'|'enum'|'string'|'list', orig}.
  class Controls {
    constructor(rig) {
      this.rig = rig;
      this.schema = null;
      this.config = undefined;
      this.leaves = [];
      this.builtWithSchema = false;
      this.calibrationsLoaded = false;

      this.algorithm = el('select', { class: 'algorithm', 'aria-label': 'algorithm' });
      this.fillAlgorithms();
      const applyAlgorithm = el('button', { class: 'apply-algorithm', type: 'button' }, 'apply');
      applyAlgorithm.addEventListener('click', () => this.applyAlgorithm());
      this.result = el('div', { class: 'control-result', role: 'status' });

      this.editor = el('div', { class: 'config-editor' }, 'configuration not loaded');
      this.configError = el('div', { class: 'config-error' });
      const applyConfig = el('button', { class: 'apply-config', type: 'button' }, 'apply changes');
      applyConfig.addEventListener('click', () => this.applyConfig());
      const reload = el('button', { class: 'reload-config', type: 'button' }, 'reload');
      reload.addEventListener('click', () => this.loadConfig());

      this.snapshotKind = el('select', { class: 'snapshot-kind', 'aria-label': 'snapshot kind' },
        ...['annotated', 'disparity', 'left'].map((k) => el('option', { value: k }, k)));
      const snapshot = el('button', { class: 'snapshot', type: 'button' }, 'snapshot');
      snapshot.addEventListener('click', () => this.snapshot());

      this.calibrations = el('div', { class: 'calibrations' }, 'not loaded');
      this.calibrationError = el('div', { class: 'calibration-error' });
      const reloadCal = el('button', { class: 'reload-calibrations', type: 'button' }, 'reload');
      reloadCal.addEventListener('click', () => this.loadCalibrations());

      this.root = el('details', { class: 'controls box' },
        el('summary', {}, 'controls'),
        el('div', { class: 'control-row' },
          el('label', {}, 'algorithm ', this.algorithm), applyAlgorithm,
          el('span', { class: 'field-error', 'data-field': 'algorithm' }),
          el('span', { class: 'spacer' }),
          this.snapshotKind, snapshot),
        this.result,
        el('h3', {}, 'parameters ', reload),
        this.editor,
        el('div', { class: 'control-row' }, applyConfig),
        this.configError,
        el('h3', {}, 'calibrations ', reloadCal),
        this.calibrations,
        this.calibrationError);
      this.root.addEventListener('toggle', () => {
        if (!this.root.open) return;
        if (!this.config) this.loadConfig();
        if (!this.calibrationsLoaded) this.loadCalibrations();
      });
    }

    schemaArrived(schema) {
      this.schema = schema;
      this.fillAlgorithms();
      if (this.config && !this.builtWithSchema) this.buildEditor(this.config);
    }

    algorithmNames() {
      const e = this.schema && this.schema.enums.get('stevi.v1.Algorithm');
      const names = e ? e.values.map((v) => v.name).filter((x) => !x.endsWith('_UNSPECIFIED')) : FALLBACK_ALGORITHMS;
      return names;
    }

    fillAlgorithms() {
      const current = this.algorithm.value || (this.config && this.config.algorithm);
      this.algorithm.replaceChildren(...this.algorithmNames().map((name) =>
        el('option', { value: name }, name.replace(/^ALGORITHM_/, ''))));
      if (current) this.algorithm.value = current;
    }

    say(text, isError) {
      this.result.textContent = text;
      this.result.classList.toggle('error', Boolean(isError));
    }

    async loadConfig() {
      let res;
      try {
        res = await api(`api/rigs/${this.rig.name}/config`);
      } catch (e) {
        this.configError.textContent = `cannot load the configuration: ${e.message}`;
        return;
      }
      if (!res.ok || !res.json || typeof res.json !== 'object') {
        this.configError.textContent = `cannot load the configuration: ${errorText(res)}`;
        return;
      }
      this.configError.textContent = '';
      this.setConfig(res.json);
    }

    setConfig(config) {
      this.config = config;
      this.rig.pub.config = config;
      if (typeof config.algorithm === 'string') {
        this.fillAlgorithms();
        this.algorithm.value = config.algorithm;
      }
      this.buildEditor(config);
    }

    // Every scalar leaf of the configuration, grouped by its top-level message. Types come from
    // the schema (stevi.v1.PipelineConfig, in the tracks channel's descriptor set) when known,
    // else from the JSON values.
    buildEditor(config) {
      const open = new Set([...this.editor.querySelectorAll('details[open]')].map((d) => d.dataset.group));
      const T = Proto.Type;
      const type = this.schema && this.schema.types.get('stevi.v1.PipelineConfig');
      this.builtWithSchema = Boolean(type);
      this.leaves = [];
      const groups = [];
      const general = [];
      const fieldOf = (msgType, key) => {
        if (!msgType) return undefined;
        return msgType.byName.get(key) || msgType.fields.find((f) => f.jsonName === key);
      };
      const leaf = (path, value, field) => {
        let kind;
        if (field) {
          if (field.repeated) kind = 'list';
          else if (field.type === T.BOOL) kind = 'bool';
          else if (field.type === T.ENUM) kind = 'enum';
          else if (field.type === T.STRING || field.type === T.BYTES) kind = 'string';
          else if (field.type === T.DOUBLE || field.type === T.FLOAT) kind = 'float';
          else kind = 'int';
        } else if (Array.isArray(value)) kind = 'list';
        else if (typeof value === 'boolean') kind = 'bool';
        else if (typeof value === 'number') kind = 'float';
        else kind = 'string';
        let input;
        if (kind === 'bool') {
          input = el('input', { type: 'checkbox', 'data-field': path });
          input.checked = value === true;
        } else if (kind === 'enum') {
          const names = field.enumType.values.map((v) => v.name);
          input = el('select', { 'data-field': path },
            ...names.filter((x) => !x.endsWith('_UNSPECIFIED') || x === value).map((x) => el('option', { value: x }, x)));
          if (typeof value === 'number') value = field.enumType.byNumber.get(value) || String(value);
          if (!names.includes(value)) input.append(el('option', { value: String(value) }, String(value)));
          input.value = String(value);
        } else if (kind === 'list') {
          input = el('input', { type: 'text', 'data-field': path, 'data-kind': 'list', size: 10 });
          input.value = Array.isArray(value) ? value.join(', ') : '';
        } else if (kind === 'int' || kind === 'float') {
          input = el('input', { type: 'number', 'data-field': path, step: kind === 'int' ? 1 : 'any' });
          input.value = String(value);
        } else {
          input = el('input', { type: 'text', 'data-field': path });
          input.value = value === undefined || value === null ? '' : String(value);
        }
        input.addEventListener('input', () => input.classList.toggle('changed', this.valueOf(entry) !== entry.origText));
        input.addEventListener('change', () => input.classList.toggle('changed', this.valueOf(entry) !== entry.origText));
        const entry = { input, path, kind, origText: '' };
        entry.origText = this.valueOf(entry);
        this.leaves.push(entry);
        const label = path.split('.').slice(1).join('.') || path;
        return el('div', { class: 'field' },
          el('label', { title: path }, label, ' ', input),
          el('span', { class: 'field-error', 'data-field': path }));
      };
      const walk = (obj, msgType, prefix, out) => {
        for (const [key, value] of Object.entries(obj)) {
          const path = prefix ? `${prefix}.${key}` : key;
          const field = fieldOf(msgType, key);
          if (value !== null && typeof value === 'object' && !Array.isArray(value)) {
            walk(value, field && field.messageType, path, out);
          } else {
            out.push(leaf(path, value, field));
          }
        }
      };
      for (const [key, value] of Object.entries(config)) {
        if (key === 'algorithm') continue;  // its own select above
        const field = fieldOf(type, key);
        if (value !== null && typeof value === 'object' && !Array.isArray(value)) {
          const items = [];
          walk(value, field && field.messageType, key, items);
          groups.push(el('details', { class: 'config-group', 'data-group': key, open: open.has(key) },
            el('summary', {}, key), el('div', { class: 'fields' }, ...items)));
        } else {
          general.push(leaf(key, value, field));
        }
      }
      if (general.length) {
        groups.unshift(el('details', { class: 'config-group', 'data-group': 'general', open: open.has('general') },
          el('summary', {}, 'general'), el('div', { class: 'fields' }, ...general)));
      }
      this.editor.replaceChildren(...groups);
    }

    // A leaf's value as text for change detection, or throws for an unparsable number.
    valueOf(entry) {
      const { input, kind } = entry;
      if (kind === 'bool') return String(input.checked);
      if (kind === 'list') return input.value.split(',').map((x) => x.trim()).filter(Boolean).join(',');
      if (kind === 'int' || kind === 'float') return input.value.trim();
      return input.value;
    }

    // The value to send, or throws Error(message) for a bad entry.
    parsed(entry) {
      const { input, kind } = entry;
      if (kind === 'bool') return input.checked;
      if (kind === 'int' || kind === 'float') {
        const text = input.value.trim();
        const v = Number(text);
        if (text === '' || !Number.isFinite(v)) throw new Error('not a number');
        if (kind === 'int' && !Number.isInteger(v)) throw new Error('not a whole number');
        return v;
      }
      if (kind === 'list') {
        const items = input.value.split(',').map((x) => x.trim()).filter(Boolean);
        return items.map((x) => {
          const v = Number(x);
          if (!Number.isFinite(v)) throw new Error(`"${x}" is not a number`);
          return v;
        });
      }
      return input.value;
    }

    clearErrors() {
      for (const e of this.root.querySelectorAll('span.field-error')) e.textContent = '';
      for (const e of this.root.querySelectorAll('.invalid')) e.classList.remove('invalid');
      this.configError.textContent = '';
      this.say('');
    }

    showProblems(res) {
      const problems = res.json && Array.isArray(res.json.problems) ? res.json.problems : [];
      const unmatched = [];
      for (const p of problems) {
        const field = p && typeof p.field === 'string' ? p.field : '';
        const message = p && typeof p.message === 'string' ? p.message : String(p && p.message);
        const span = field ? this.root.querySelector(`span.field-error${attrSelector('data-field', field)}`) : null;
        if (span) {
          span.textContent = span.textContent ? `${span.textContent}; ${message}` : message;
          const input = this.root.querySelector(`${field === 'algorithm' ? 'select.algorithm' : `[data-field]:not(span)${attrSelector('data-field', field)}`}`);
          if (input) input.classList.add('invalid');
        } else {
          unmatched.push(field ? `${field}: ${message}` : message);
        }
      }
      if (!problems.length) unmatched.push(errorText(res));
      this.configError.replaceChildren(...unmatched.map((m) => el('div', {}, m)));
    }

    async post(partial) {
      let res;
      try {
        res = await api(`api/rigs/${this.rig.name}/config`, { method: 'POST', body: partial, control: true });
      } catch (e) {
        this.configError.textContent = `cannot reach the station: ${e.message}`;
        return false;
      }
      if (res.ok && res.json && typeof res.json === 'object') {
        this.setConfig(res.json);
        return true;
      }
      this.showProblems(res);
      return false;
    }

    async applyAlgorithm() {
      this.clearErrors();
      const value = this.algorithm.value;
      if (await this.post({ algorithm: value })) this.say(`algorithm ${value.replace(/^ALGORITHM_/, '')} applied`);
    }

    async applyConfig() {
      this.clearErrors();
      const partial = {};
      let changed = 0;
      let bad = 0;
      for (const entry of this.leaves) {
        if (this.valueOf(entry) === entry.origText) continue;
        let value;
        try {
          value = this.parsed(entry);
        } catch (e) {
          bad += 1;
          const span = this.editor.querySelector(`span.field-error${attrSelector('data-field', entry.path)}`);
          if (span) span.textContent = e.message;
          entry.input.classList.add('invalid');
          continue;
        }
        const parts = entry.path.split('.');
        let o = partial;
        for (const p of parts.slice(0, -1)) o = (o[p] = o[p] || {});
        o[parts[parts.length - 1]] = value;
        changed += 1;
      }
      if (bad) return;
      if (!changed) {
        this.say('nothing changed');
        return;
      }
      if (await this.post(partial)) this.say(`${changed} field${changed === 1 ? '' : 's'} applied`);
    }

    async snapshot() {
      const kind = this.snapshotKind.value;
      this.say(`fetching the ${kind} snapshot…`);
      let res;
      try {
        res = await api(`api/rigs/${this.rig.name}/snapshot?kind=${encodeURIComponent(kind)}`, { as: 'blob' });
      } catch (e) {
        this.say(`snapshot failed: ${e.message}`, true);
        return;
      }
      if (!res.ok) {
        this.say(`snapshot failed: ${errorText(res)}`, true);
        return;
      }
      this.say('');
      showSnapshot(this.rig.name, kind, res.blob);
    }

    async loadCalibrations() {
      let res;
      try {
        res = await api(`api/rigs/${this.rig.name}/calibrations`);
      } catch (e) {
        this.calibrationError.textContent = `cannot list the calibrations: ${e.message}`;
        return;
      }
      if (!res.ok || !res.json) {
        this.calibrationError.textContent = `cannot list the calibrations: ${errorText(res)}`;
        return;
      }
      this.calibrationsLoaded = true;
      this.calibrationError.textContent = '';
      const list = Array.isArray(res.json.calibrations) ? res.json.calibrations : [];
      const activeId = typeof res.json.active_id === 'string' ? res.json.active_id : '';
      const rows = list.map((c) => {
        const id = String(c.calibration_id || '');
        const active = c.active === true || (activeId && id === activeId);
        const created = Number(c.created_unix_ns) ? new Date(Number(c.created_unix_ns) / 1e6).toISOString().replace('T', ' ').slice(0, 19) : '—';
        const button = el('button', { class: 'activate-calibration', type: 'button', 'data-id': id, disabled: active }, active ? 'active' : 'activate');
        button.addEventListener('click', () => this.activate(id));
        return el('tr', { 'data-id': id, class: active ? 'active' : '' },
          el('td', { class: 'id' }, id), el('td', {}, created),
          el('td', {}, c.passed ? 'passed' : 'failed'),
          el('td', {}, `${fmt(Number(c.rms_px), 2)} px`), el('td', {}, `${fmt(Number(c.baseline_m), 3)} m`),
          el('td', {}, `${c.width || 0}×${c.height || 0}`), el('td', {}, button));
      });
      const problems = Array.isArray(res.json.store_problems) ? res.json.store_problems : [];
      this.calibrations.replaceChildren(
        rows.length ? el('table', { class: 'calibration-list' }, el('tbody', {}, ...rows)) : el('div', {}, 'no calibrations stored'),
        ...problems.map((p) => el('div', { class: 'store-problem' }, String(p))));
    }

    async activate(id) {
      this.calibrationError.textContent = '';
      let res;
      try {
        res = await api(`api/rigs/${this.rig.name}/calibrations/activate`, { method: 'POST', body: { id }, control: true });
      } catch (e) {
        this.calibrationError.textContent = `cannot reach the station: ${e.message}`;
        return;
      }
      if (!res.ok) {
        this.calibrationError.textContent = `activation failed: ${errorText(res)}`;
        return;
      }
      this.say(`calibration ${id} activated`);
      this.loadCalibrations();
    }
  }

  // A snapshot over the page, with a download link.
  function showSnapshot(rigName, kind, blob) {
    const old = document.querySelector('.snapshot-overlay');
    if (old) old.dispatchEvent(new Event('close'));
    const url = URL.createObjectURL(blob);
    const stamp = new Date().toISOString().replace(/[:.]/g, '-');
    const close = el('button', { class: 'snapshot-close', type: 'button' }, 'close');
    const overlay = el('div', { class: 'snapshot-overlay', 'data-rig': rigName, 'data-kind': kind },
      el('div', { class: 'snapshot-bar' },
        el('span', {}, `${rigName} ${kind} snapshot`), el('span', { class: 'spacer' }),
        el('a', { class: 'snapshot-download', href: url, download: `${rigName}-${kind}-${stamp}.png` }, 'download'),
        close),
      el('img', { class: 'snapshot-image', src: url, alt: `${rigName} ${kind} snapshot` }));
    const done = () => { overlay.remove(); URL.revokeObjectURL(url); };
    overlay.addEventListener('close', done);
    close.addEventListener('click', done);
    overlay.addEventListener('click', (ev) => { if (ev.target === overlay) done(); });
    document.body.append(overlay);
  }

  document.addEventListener('keydown', (ev) => {
    if (ev.key !== 'Escape') return;
    const o = document.querySelector('.snapshot-overlay');
    if (o) o.dispatchEvent(new Event('close'));
  });

  // ---------------------------------------------------------------- start

  if (!Proto) {
    addProblem('protobuf', 'protobuf.js did not load: nothing can be decoded');
  }
  renderProblems();
  refreshRigs();
  connect();
})();
