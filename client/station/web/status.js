// A rig's status (stevi.v1.StationRigStatus from /rigK/status): its connection state, error and
// source state in the rig's header, and the status box (div.status, a row per [data-key]).

import { el, enumLabel, fmt, fmtBytes } from './util.js';

// The connection state of a StationRigStatus: 'up', 'down' or 'connecting'.
export function connectionState(s, schema) {
  const name = enumLabel(schema, 'stevi.v1.StationRigStatus.Connection', s.connection, 'CONNECTION_');
  return { UP: 'up', DOWN: 'down', CONNECTING: 'connecting' }[name] ||
    ({ 1: 'connecting', 2: 'up', 3: 'down' }[s.connection] || 'connecting');
}

// Shows the status in the header's {stateEl, errorEl, sourceEl}.
export function showHeaderStatus(header, s, state, schema) {
  const { stateEl, errorEl, sourceEl } = header;
  stateEl.dataset.state = state;
  stateEl.textContent = state.toUpperCase();
  if (state === 'down') {
    errorEl.textContent = `${s.error || 'down'} (for ${fmt(s.down_for_s, 0)} s)`;
  } else if (state === 'connecting' && s.error) {
    errorEl.textContent = s.error;
  } else {
    errorEl.textContent = '';
  }
  if (s.server) {
    const src = enumLabel(schema, 'stevi.v1.SourceState', s.server.source_state, 'SOURCE_STATE_');
    sourceEl.textContent = `source ${src}`;
    sourceEl.dataset.state = src.toLowerCase();
  } else {
    sourceEl.textContent = 'source —';
    delete sourceEl.dataset.state;
  }
}

// Fills the status box from the last status `s` and the last TrackFrame `f` (either may be
// undefined).
export function renderStatus(statusEl, s, f, schema) {
  const srv = s && s.server;
  const rows = [];
  const row = (key, label, value, title) => rows.push(
    el('div', { class: 'status-row' }, el('span', { class: 'k' }, label),
      el('span', { class: 'v', 'data-key': key, title }, value)));
  if (srv) {
    serverRows(row, srv, f, schema);
  } else {
    row('source', 'source', s ? 'no server status' : '—');
  }
  row('station', 'station', s
    ? `tracks ${fmt(s.track_frames_per_s, 1)}/s · previews ${fmt(s.previews_per_s, 1)}/s · reconnects ${s.reconnects}`
    : '—');
  statusEl.replaceChildren(...rows);
}

// The rows of the stevi-server's own status (stevi.v1.GetStatusResponse).
function serverRows(row, srv, f, schema) {
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
}
