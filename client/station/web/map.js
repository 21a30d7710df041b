// A rig's map (div.map[data-geo=ok|none] + .map-message): Leaflet without tiles, CRS.Simple in
// local metres (LatLng = [north, east]) around the first vehicle fix: the vehicle with its
// heading, the tracks' geodetic positions and their last minute, and the site overlay. Its box
// holds the "fit" button and the export links (a.export-geojson, a.export-kml).

import { STATE_COLOUR, el, enumLabel } from './util.js';
import { addProblem, clearProblem } from './problems.js';
import { download, getStationToken } from './api.js';

const GEO_STATUS_OK = 1;
const TRAIL_S = 60;
const EARTH_R = 6378137;  // WGS84 equatorial radius, m; flat earth around the first fix

// The map's box for rig `n`: {box, map}.
export function buildMapBox(n) {
  const mapDiv = el('div', { class: 'map' });
  const mapMessage = el('div', { class: 'map-message' }, 'waiting for track frames…');
  const geojsonLink = el('a', { class: 'export-geojson', href: `api/rigs/${n}/export.geojson`, download: `${n}-tracks.geojson` }, 'GeoJSON');
  const kmlLink = el('a', { class: 'export-kml', href: `api/rigs/${n}/export.kml`, download: `${n}-tracks.kml` }, 'KML');
  for (const [a, file] of [[geojsonLink, `${n}-tracks.geojson`], [kmlLink, `${n}-tracks.kml`]]) {
    a.addEventListener('click', (ev) => {
      if (!getStationToken()) return;  // a plain link does
      ev.preventDefault();
      download(a.getAttribute('href'), file).catch((e) => addProblem(`export:${n}`, `${n}: export failed: ${e.message}`));
    });
  }
  const fitButton = el('button', { class: 'map-fit', type: 'button', title: 'follow the vehicle again' }, 'fit');
  const box = el('figure', { class: 'box map-box' }, mapDiv, mapMessage,
    el('figcaption', {}, el('span', { title: 'local metres around the first vehicle fix, north up' }, 'map · north up'), el('span', { class: 'spacer' }),
      fitButton, ' export ', geojsonLink, ' ', kmlLink));
  const map = new RigMap(mapDiv, mapMessage);
  fitButton.addEventListener('click', () => map.follow());
  return { box, map };
}

export class RigMap {
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
    this.prune(t - TRAIL_S);
  }

  // Drops what is older than `cutoff` (s): the map shows the last minute only.
  prune(cutoff) {
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
    const current = new Set(geo ? f.tracks.filter((t) => t.geodetic).map((t) => t.track_id) : []);
    this.renderTrails(f, schema, current);
    const vpos = this.renderVehicle(f, geo);
    const now = performance.now();
    if (this.following && vpos && now - this.lastFit > 1000) {
      this.lastFit = now;
      this.fit(vpos, current);
    }
  }

  // Each trail's line, and a marker for the tracks in the frame (`current`: their ids).
  renderTrails(f, schema, current) {
    const L = window.L;
    const stateName = (n) => enumLabel(schema, 'stevi.v1.TrackState', n, 'TRACK_STATE_');
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
        const element = trail.marker.getElement && trail.marker.getElement();
        if (element) element.setAttribute('data-track-id', String(id));
      } else if (trail.marker) {
        trail.marker.remove();
        trail.marker = null;
      }
    }
  }

  // The vehicle from the frame, else from the last LocationFix; its local position or null.
  renderVehicle(f, geo) {
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
    return vpos;
  }

  // Zooms to the vehicle and the current tracks, at least 50 m across.
  fit(vpos, current) {
    const L = window.L;
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
