// A rig's track table: a row per track of the last TrackFrame, nearest first
// (table.tracks[data-frame-id] > tbody > tr[data-track-id][data-state] > td.range[data-range-m]).

import { el, enumLabel, fmt } from './util.js';

const STATE_CLASS = { CONFIRMED: 'confirmed', TENTATIVE: 'tentative', COASTING: 'coasting' };

export class TracksTable {
  constructor() {
    this.table = el('table', { class: 'tracks' },
      el('thead', {}, el('tr', {}, ...['id', 'state', 'range', 'rate', 'TTC', 'lat', 'lon', 'alt']
        .map((h) => el('th', {}, h)))),
      el('tbody'));
    this.tbody = this.table.tBodies[0];
    this.caption = el('div', { class: 'tracks-caption' }, 'no track frame yet');
    this.box = el('div', { class: 'box tracks-box' }, this.caption, el('div', { class: 'table-scroll' }, this.table));
  }

  // Shows TrackFrame `f`; `stateName(n)` names a TrackState without its prefix.
  render(f, schema, stateName) {
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
    this.caption.textContent = `frame ${f.frame_id} · ${f.tracks.length} track${f.tracks.length === 1 ? '' : 's'} · ${alg}`;
  }
}
