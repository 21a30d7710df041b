// A rig's plan view (canvas.plan): top-down, body frame, x forward up the screen, y right. Rings
// every 10 m (coarser when there would be too many), the range scan's field of view and free
// space, the vehicle, and the tracks with where they will be in 2 s.

import { STATE_COLOUR, fmt } from './util.js';

export class PlanView {
  constructor(canvas) {
    this.canvas = canvas;
    this.last = null;
    if (typeof ResizeObserver !== 'undefined') {
      new ResizeObserver(() => { if (this.last) this.draw(...this.last); else this.draw(null); }).observe(canvas);
    }
    this.draw(null);
  }

  // Draws TrackFrame `frame` (null: a waiting text); `velocity`: track id -> {vx, vy, n} in the
  // body frame; `stateName(n)` names a TrackState without its prefix.
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
    const v = layout(scan, tracks, w, h);
    drawRings(g, v, scan);
    if (scan && scan.range_m.length && scan.bin_width_deg > 0) {
      drawScan(g, v, scan);
    } else {
      g.fillStyle = '#6e7b8b';
      g.fillText('no range scan', 8, 14);
    }
    drawVehicle(g, v);
    drawTracks(g, v, tracks, velocity, stateName);
    g.fillStyle = '#6e7b8b';
    g.font = '11px system-ui, sans-serif';
    g.fillText(`${tracks.length} track${tracks.length === 1 ? '' : 's'} · range ${fmt(v.maxRange, 0)} m`, 8, h - 4);
  }
}

// The view of a w x h canvas: {maxRange, ox, oy (the origin), s (px per metre), scanStart,
// P(x, y) (body metres to pixels), A(azimuth deg, range) (polar to pixels)}.
function layout(scan, tracks, w, h) {
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
  return { maxRange, ox, oy, s, scanStart, scanEnd, P, A };
}

// Range rings with their labels, and the axes.
function drawRings(g, v, scan) {
  const { maxRange, ox, oy, s, A } = v;
  let step = 10;
  while (maxRange / step > 12) step = step < 50 ? step * 2.5 : step * 2;
  g.strokeStyle = '#263040';
  g.fillStyle = '#6e7b8b';
  g.lineWidth = 1;
  // Labels on a bearing left of the field of view, clear of the tracks.
  const labelAz = Math.min(-50, (scan ? v.scanStart : 0) - 10);
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
}

// The range scan: field of view, free space to the nearest range per bin, obstacles.
function drawScan(g, v, scan) {
  const { ox, oy, A, scanStart, scanEnd } = v;
  const far = scan.max_range_m > 0 ? scan.max_range_m : v.maxRange;
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
}

// The vehicle, a triangle at the origin pointing forward.
function drawVehicle(g, v) {
  const { ox, oy } = v;
  g.fillStyle = '#58a6ff';
  g.beginPath();
  g.moveTo(ox, oy - 8); g.lineTo(ox - 5, oy + 5); g.lineTo(ox + 5, oy + 5);
  g.closePath();
  g.fill();
}

// Tracks, nearest drawn last (on top).
function drawTracks(g, v, tracks, velocity, stateName) {
  const sorted = tracks.slice().sort((a, b) => b.range_m - a.range_m);
  g.font = '11px ui-monospace, monospace';
  for (const t of sorted) {
    const state = stateName(t.state);
    const colour = STATE_COLOUR[state] || '#9aa6b6';
    const [px, py] = v.P(t.position_body.x_m, t.position_body.y_m);
    const vel = velocity.get(t.track_id);
    if (vel && vel.n > 0) drawArrow(g, v, t, vel, colour);
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
}

// An arrow from track `t` to where it will be in 2 s at its relative velocity `vel`.
function drawArrow(g, v, t, vel, colour) {
  const [px, py] = v.P(t.position_body.x_m, t.position_body.y_m);
  const [qx, qy] = v.P(t.position_body.x_m + 2 * vel.vx, t.position_body.y_m + 2 * vel.vy);
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
