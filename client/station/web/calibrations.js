// A rig's stored calibrations in its controls (div.calibrations, GET api/rigs/NAME/calibrations):
// a row each with button.activate-calibration[data-id] (POST .../calibrations/activate, with the
// operator token), the store's problems, and div.calibration-error.

import { el, fmt } from './util.js';
import { api, errorText } from './api.js';

export class CalibrationsPanel {
  // `say(text)`: shows a result in the controls' result line.
  constructor(rigName, say) {
    this.rigName = rigName;
    this.say = say;
    this.loaded = false;
    this.list = el('div', { class: 'calibrations' }, 'not loaded');
    this.error = el('div', { class: 'calibration-error' });
    this.reload = el('button', { class: 'reload-calibrations', type: 'button' }, 'reload');
    this.reload.addEventListener('click', () => this.load());
  }

  async load() {
    let res;
    try {
      res = await api(`api/rigs/${this.rigName}/calibrations`);
    } catch (e) {
      this.error.textContent = `cannot list the calibrations: ${e.message}`;
      return;
    }
    if (!res.ok || !res.json) {
      this.error.textContent = `cannot list the calibrations: ${errorText(res)}`;
      return;
    }
    this.loaded = true;
    this.error.textContent = '';
    const list = Array.isArray(res.json.calibrations) ? res.json.calibrations : [];
    const activeId = typeof res.json.active_id === 'string' ? res.json.active_id : '';
    const rows = list.map((c) => this.row(c, activeId));
    const problems = Array.isArray(res.json.store_problems) ? res.json.store_problems : [];
    this.list.replaceChildren(
      rows.length ? el('table', { class: 'calibration-list' }, el('tbody', {}, ...rows)) : el('div', {}, 'no calibrations stored'),
      ...problems.map((p) => el('div', { class: 'store-problem' }, String(p))));
  }

  // The row of calibration summary `c`. Only the active calibration's button is disabled; with
  // no active one (activeId ''), every calibration can be activated (the server refuses a failed
  // one and says why).
  row(c, activeId) {
    const id = String(c.calibration_id || '');
    const active = c.active === true || (activeId !== '' && id === activeId);
    const created = Number(c.created_unix_ns) ? new Date(Number(c.created_unix_ns) / 1e6).toISOString().replace('T', ' ').slice(0, 19) : '—';
    const button = el('button', { class: 'activate-calibration', type: 'button', 'data-id': id, disabled: active }, active ? 'active' : 'activate');
    button.addEventListener('click', () => this.activate(id));
    return el('tr', { 'data-id': id, class: active ? 'active' : '' },
      el('td', { class: 'id' }, id), el('td', {}, created),
      el('td', {}, c.passed ? 'passed' : 'failed'),
      el('td', {}, `${fmt(Number(c.rms_px), 2)} px`), el('td', {}, `${fmt(Number(c.baseline_m), 3)} m`),
      el('td', {}, `${c.width || 0}×${c.height || 0}`), el('td', {}, button));
  }

  async activate(id) {
    this.error.textContent = '';
    let res;
    try {
      res = await api(`api/rigs/${this.rigName}/calibrations/activate`, { method: 'POST', body: { id }, control: true });
    } catch (e) {
      this.error.textContent = `cannot reach the station: ${e.message}`;
      return;
    }
    if (!res.ok) {
      this.error.textContent = `activation failed: ${errorText(res)}`;
      return;
    }
    this.say(`calibration ${id} activated`);
    this.load();
  }
}
