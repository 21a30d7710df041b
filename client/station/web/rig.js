// One rig's panel (section.rig[data-rig=rigK]): its header (name, address, connection state,
// source state, error, frame rate) and its boxes: the annotated and disparity videos (video.js),
// the plan view (plan_view.js), the map (map.js), the track table (tracks_table.js), the status
// (status.js) and the controls (controls.js). The socket hands it each decoded message
// (onMessage); track frames are drawn at most once an animation frame.

import { el, enumLabel, fmt } from './util.js';
import { stevi } from './state.js';
import { Controls } from './controls.js';
import { buildMapBox } from './map.js';
import { PlanView } from './plan_view.js';
import { connectionState, renderStatus, showHeaderStatus } from './status.js';
import { TracksTable } from './tracks_table.js';
import { VideoPanel } from './video.js';

export class Rig {
  constructor(name) {
    this.name = name;
    this.pub = {
      name, address: '', lastFrame: undefined, lastStatus: undefined, lastVehicle: undefined,
      frames: 0, decodeErrors: 0, images: { annotated: 0, disparity: 0 }, config: undefined,
    };
    stevi.rigs[name] = this.pub;
    this.schemas = {};          // kind -> Schema
    this.velocity = new Map();  // track id -> {x, y, t, vx, vy, n}
    this.renderPending = false;
    this.frameTimes = [];
    this.build();
  }

  build() {
    const n = this.name;
    this.header = {
      stateEl: el('span', { class: 'rig-state', 'data-state': 'connecting' }, 'CONNECTING'),
      errorEl: el('span', { class: 'rig-error' }),
      sourceEl: el('span', { class: 'source-state', title: 'the stevi-server\'s source' }, 'source —'),
    };
    this.addressEl = el('span', { class: 'rig-address' });
    this.frameInfoEl = el('span', { class: 'frame-info' });
    const { stateEl, errorEl, sourceEl } = this.header;
    const header = el('header', { class: 'rig-header' },
      el('h2', { class: 'rig-name' }, n), this.addressEl, stateEl, sourceEl, errorEl,
      el('span', { class: 'spacer' }), this.frameInfoEl);

    this.videos = {
      annotated: new VideoPanel(n, 'annotated', 'annotated'),
      disparity: new VideoPanel(n, 'disparity', 'disparity'),
    };

    const planCanvas = el('canvas', { class: 'plan', width: 400, height: 300 });
    const planBox = el('figure', { class: 'box plan-box' }, planCanvas,
      el('figcaption', { title: 'top-down in the body frame: x forward (up), y right' }, 'plan · body frame, x forward'));
    this.plan = new PlanView(planCanvas);

    const { box: mapBox, map } = buildMapBox(n);
    this.map = map;

    this.table = new TracksTable();

    this.statusEl = el('div', { class: 'status box' });
    this.renderStatus();

    this.controls = new Controls(this);

    this.section = el('section', { class: 'rig', 'data-rig': n },
      header,
      el('div', { class: 'rig-body' },
        this.videos.annotated.box, this.videos.disparity.box, planBox, mapBox, this.table.box,
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

  onImage(kind, msg) {
    const count = this.pub.images[kind] + 1;
    this.videos[kind].show(msg, count);
    this.pub.images[kind] = count;
  }

  onStatus(s) {
    this.pub.lastStatus = s;
    if (s.address) this.setAddress(s.address);
    const state = connectionState(s, this.schemas.status);
    if (state === 'up' && this.header.stateEl.dataset.state !== 'up') {  // came up: fetch what failed
      if (!this.controls.config) this.controls.loadConfig();
      if (!this.controls.calibrationsLoaded) this.controls.loadCalibrations();
    }
    showHeaderStatus(this.header, s, state, this.schemas.status);
    this.renderStatus();
  }

  renderStatus() {
    renderStatus(this.statusEl, this.pub.lastStatus, this.pub.lastFrame, this.schemas.status);
  }

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
    this.table.render(f, schema, stateName);
    const times = this.frameTimes;
    const hz = times.length > 1 ? (times.length - 1) / ((times[times.length - 1] - times[0]) / 1000) : 0;
    this.frameInfoEl.textContent = `frame ${f.frame_id} · ${fmt(hz, 1)} Hz`;
    this.plan.draw(f, this.velocity, stateName);
    this.map.render();
    this.renderStatus();
  }
}
