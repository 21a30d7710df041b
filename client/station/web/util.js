// Shared helpers of the station page: building DOM nodes, formatting numbers and enum values.
// Nothing here keeps state or touches the page by itself.

// protobuf.js (a classic script loaded before the modules) defines window.SteviProto; undefined
// when it did not load (app.js reports that as a problem).
export const Proto = window.SteviProto;

// The colours of the track states, shared by the plan view and the map.
export const STATE_COLOUR = { CONFIRMED: '#ff5b5b', COASTING: '#f2b84b', TENTATIVE: '#9aa6b6' };

// el('div', {class: 'x', 'data-k': 'v', onclick: f}, 'text', child, ...): strings become text.
export function el(tag, attrs, ...children) {
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

export function fmt(v, digits) {
  return typeof v === 'number' && Number.isFinite(v) ? v.toFixed(digits) : '—';
}

export function fmtBytes(n) {
  if (!Number.isFinite(n)) return '—';
  if (n >= 1 << 30) return `${(n / (1 << 30)).toFixed(2)} GiB`;
  if (n >= 1 << 20) return `${(n / (1 << 20)).toFixed(1)} MiB`;
  if (n >= 1 << 10) return `${(n / (1 << 10)).toFixed(1)} KiB`;
  return `${n} B`;
}

// An enum value's name without its prefix ("TRACK_STATE_CONFIRMED" -> "CONFIRMED").
export function enumLabel(schema, enumName, number, prefix) {
  const name = schema ? schema.enumName(enumName, number) : String(number);
  return prefix && name.startsWith(prefix) ? name.slice(prefix.length) : name;
}

export function attrSelector(name, value) {
  return `[${name}="${CSS.escape(String(value))}"]`;
}

export function rigNumber(name) { return Number(name.slice(3)); }
