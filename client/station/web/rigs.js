// The rigs the station serves (GET api/rigs): a Rig panel each in #rigs, ordered by number, and
// the site overlay (GET api/site.geojson) they all draw on their maps.

import { rigNumber } from './util.js';
import { addProblem, clearProblem } from './problems.js';
import { api, errorText, tokenAccepted } from './api.js';
import { Rig } from './rig.js';

const RIG_RE = /^rig[0-9]+$/;

const rigsMain = document.getElementById('rigs');
const noRigs = document.getElementById('no-rigs');
export const rigs = new Map();  // name -> Rig

let rigsRetry = null;
let site = undefined;  // the site GeoJSON: undefined = not asked yet, null = none

export function ensureRig(name) {
  let rig = rigs.get(name);
  if (rig) return rig;
  rig = new Rig(name);
  if (site) rig.map.setSite(site);
  rigs.set(name, rig);
  const after = [...rigs.values()].filter((r) => rigNumber(r.name) > rigNumber(name))
    .sort((a, b) => rigNumber(a.name) - rigNumber(b.name))[0];
  rigsMain.insertBefore(rig.section, after ? after.section : null);
  noRigs.hidden = true;
  rig.controls.loadConfig();
  rig.controls.loadCalibrations();
  return rig;
}

export async function refreshRigs() {
  clearTimeout(rigsRetry);
  let res;
  try {
    res = await api('api/rigs');
  } catch (e) {
    addProblem('rigs', `cannot list the rigs: ${e.message}`);
    retryRigsLater();
    return;
  }
  if (res.status === 401) return;  // the prompt is shown
  if (!res.ok || !res.json || !Array.isArray(res.json.rigs)) {
    addProblem('rigs', `cannot list the rigs: ${errorText(res)}`);
    retryRigsLater();
    return;
  }
  clearProblem('rigs');
  tokenAccepted();
  for (const r of res.json.rigs) {
    if (!r || typeof r.rig !== 'string' || !RIG_RE.test(r.rig)) continue;
    const rig = ensureRig(r.rig);
    if (typeof r.address === 'string') rig.setAddress(r.address);
  }
  if (site === undefined && res.json.site === true) loadSite();
}

// One retry pending at most: refreshRigs calls that overlap (the socket opening, a new token)
// each end here on a failure.
function retryRigsLater() {
  clearTimeout(rigsRetry);
  rigsRetry = setTimeout(refreshRigs, 5000);
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
