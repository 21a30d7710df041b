// The tokens and the station's HTTP API (/api/...): the station token (#station-token-form,
// kept in sessionStorage, sent as Authorization: Bearer and in the socket's URL), the operator
// token (#operator-token, memory only, sent only with control POSTs), api(), downloads.

import { el } from './util.js';

const TOKEN_KEY = 'stevi.station_token';

let stationToken = '';
try { stationToken = sessionStorage.getItem(TOKEN_KEY) || ''; } catch (e) { /* storage off */ }
let operatorToken = '';  // memory only; sent only with control POSTs

const tokenForm = document.getElementById('station-token-form');
const tokenInput = document.getElementById('station-token');
const tokenMessage = document.getElementById('station-token-message');
const operatorInput = document.getElementById('operator-token');

export function getStationToken() { return stationToken; }

// Wires the two token forms; `onStationToken` runs when a station token is applied.
export function initTokenForms(onStationToken) {
  operatorInput.addEventListener('input', () => { operatorToken = operatorInput.value.trim(); });
  document.getElementById('operator-form').addEventListener('submit', (ev) => ev.preventDefault());
  tokenForm.addEventListener('submit', (ev) => {
    ev.preventDefault();
    stationToken = tokenInput.value.trim();
    try {
      if (stationToken) sessionStorage.setItem(TOKEN_KEY, stationToken);
      else sessionStorage.removeItem(TOKEN_KEY);
    } catch (e) { /* storage off: the token lasts as long as the page */ }
    tokenMessage.textContent = 'checking…';
    onStationToken();
  });
}

function showTokenPrompt(message) {
  tokenForm.hidden = false;
  tokenMessage.textContent = message;
  if (document.activeElement !== tokenInput) tokenInput.value = stationToken;
}

// The station accepted the station token (it listed the rigs): the prompt goes.
export function tokenAccepted() {
  tokenForm.hidden = true;
  tokenMessage.textContent = '';
  // The station cannot tell whether a server wants a token: its refusal says so, beside the
  // control that was refused.
  operatorInput.placeholder = 'for control calls';
}

function apiUrl(path) { return new URL(path, document.baseURI).href; }

// fetch() of the station's API with the station token. `control` adds the operator token.
// Resolves to {status, ok, json, text, blob}; rejects only on network errors.
export async function api(path, { method = 'GET', body, control = false, as = 'json' } = {}) {
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
export function errorText(res) {
  if (res.json && typeof res.json.message === 'string') {
    return res.json.code ? `${res.json.code}: ${res.json.message}` : res.json.message;
  }
  return `HTTP ${res.status}${res.text ? `: ${res.text.slice(0, 200)}` : ''}`;
}

// Downloads an API resource as a file (with the token, so not through a plain link).
export async function download(path, filename) {
  const res = await api(path, { as: 'blob' });
  if (!res.ok) throw new Error(errorText(res));
  const url = URL.createObjectURL(res.blob);
  const a = el('a', { href: url, download: filename });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
}
