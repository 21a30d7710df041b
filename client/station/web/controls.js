// A rig's controls (details.controls): the algorithm switch (select.algorithm,
// button.apply-algorithm), the parameter editor (config_editor.js, button.apply-config), the
// snapshot (select.snapshot-kind, button.snapshot) and the calibrations (calibrations.js). The
// changes are POSTed to api/rigs/NAME/config with the operator token; the server's refusals
// show beside their field (span.field-error[data-field]) or in div.config-error, results in
// .control-result.

import { attrSelector, el } from './util.js';
import { api, errorText } from './api.js';
import { CalibrationsPanel } from './calibrations.js';
import { ConfigEditor } from './config_editor.js';
import { showSnapshot } from './snapshot.js';

// Used before a schema arrives (config.proto's Algorithm).
const FALLBACK_ALGORITHMS = ['ALGORITHM_CANONICAL', 'ALGORITHM_STEVIE', 'ALGORITHM_STEVIS', 'ALGORITHM_STIXELS'];

export class Controls {
  constructor(rig) {
    this.rig = rig;
    this.schema = null;
    this.config = undefined;

    this.algorithm = el('select', { class: 'algorithm', 'aria-label': 'algorithm' });
    this.fillAlgorithms();
    const applyAlgorithm = el('button', { class: 'apply-algorithm', type: 'button' }, 'apply');
    applyAlgorithm.addEventListener('click', () => this.applyAlgorithm());
    this.result = el('div', { class: 'control-result', role: 'status' });

    this.editor = new ConfigEditor();
    this.configError = el('div', { class: 'config-error' });
    const applyConfig = el('button', { class: 'apply-config', type: 'button' }, 'apply changes');
    applyConfig.addEventListener('click', () => this.applyConfig());
    const reload = el('button', { class: 'reload-config', type: 'button' }, 'reload');
    reload.addEventListener('click', () => this.loadConfig());

    this.snapshotKind = el('select', { class: 'snapshot-kind', 'aria-label': 'snapshot kind' },
      ...['annotated', 'disparity', 'left'].map((k) => el('option', { value: k }, k)));
    const snapshot = el('button', { class: 'snapshot', type: 'button' }, 'snapshot');
    snapshot.addEventListener('click', () => this.snapshot());

    this.calibrations = new CalibrationsPanel(rig.name, (text) => this.say(text));

    this.root = el('details', { class: 'controls box' },
      el('summary', {}, 'controls'),
      el('div', { class: 'control-row' },
        el('label', {}, 'algorithm ', this.algorithm), applyAlgorithm,
        el('span', { class: 'field-error', 'data-field': 'algorithm' }),
        el('span', { class: 'spacer' }),
        this.snapshotKind, snapshot),
      this.result,
      el('h3', {}, 'parameters ', reload),
      this.editor.root,
      el('div', { class: 'control-row' }, applyConfig),
      this.configError,
      el('h3', {}, 'calibrations ', this.calibrations.reload),
      this.calibrations.list,
      this.calibrations.error);
    this.root.addEventListener('toggle', () => {
      if (!this.root.open) return;
      if (!this.config) this.loadConfig();
      if (!this.calibrationsLoaded) this.loadCalibrations();
    });
  }

  get calibrationsLoaded() { return this.calibrations.loaded; }

  loadCalibrations() { return this.calibrations.load(); }

  schemaArrived(schema) {
    this.schema = schema;
    this.fillAlgorithms();
    if (this.config && !this.editor.builtWithSchema) this.editor.build(this.config, this.schema);
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
    this.editor.build(config, this.schema);
  }

  clearErrors() {
    for (const e of this.root.querySelectorAll('span.field-error')) e.textContent = '';
    for (const e of this.root.querySelectorAll('.invalid')) e.classList.remove('invalid');
    this.configError.textContent = '';
    this.say('');
  }

  // The server's refusal: each problem beside its field when there is one, else in the error line.
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
    const { partial, changed, bad } = this.editor.changes();
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
}
