// The parameter editor of a rig's controls (div.config-editor): every scalar leaf of the
// pipeline configuration (GET api/rigs/NAME/config) as an input [data-field=dotted.path] with a
// span.field-error[data-field] beside it, grouped by its top-level message; and the partial
// configuration of what was changed, for the POST.
//
// A leaf: {input, path, kind: 'bool'|'int'|'float'|'enum'|'string'|'list', origText}.

import { Proto, attrSelector, el } from './util.js';

export class ConfigEditor {
  constructor() {
    this.root = el('div', { class: 'config-editor' }, 'configuration not loaded');
    this.leaves = [];
    this.builtWithSchema = false;
  }

  // Every scalar leaf of the configuration, grouped by its top-level message. Types come from
  // the schema (stevi.v1.PipelineConfig, in the tracks channel's descriptor set) when known,
  // else from the JSON values.
  build(config, schema) {
    const open = new Set([...this.root.querySelectorAll('details[open]')].map((d) => d.dataset.group));
    const type = schema && schema.types.get('stevi.v1.PipelineConfig');
    this.builtWithSchema = Boolean(type);
    this.leaves = [];
    const groups = [];
    const general = [];
    const group = (key, items) => el('details', { class: 'config-group', 'data-group': key, open: open.has(key) },
      el('summary', {}, key), el('div', { class: 'fields' }, ...items));
    for (const [key, value] of Object.entries(config)) {
      if (key === 'algorithm') continue;  // its own select above
      const field = fieldOf(type, key);
      if (value !== null && typeof value === 'object' && !Array.isArray(value)) {
        const items = [];
        this.walk(value, field && field.messageType, key, items);
        groups.push(group(key, items));
      } else {
        general.push(this.leaf(key, value, field));
      }
    }
    if (general.length) groups.unshift(group('general', general));
    this.root.replaceChildren(...groups);
  }

  walk(obj, msgType, prefix, out) {
    for (const [key, value] of Object.entries(obj)) {
      const path = prefix ? `${prefix}.${key}` : key;
      const field = fieldOf(msgType, key);
      if (value !== null && typeof value === 'object' && !Array.isArray(value)) {
        this.walk(value, field && field.messageType, path, out);
      } else {
        out.push(this.leaf(path, value, field));
      }
    }
  }

  // The field of one leaf: its input, marked .changed while it differs from the loaded value.
  leaf(path, value, field) {
    const kind = leafKind(value, field);
    const input = leafInput(path, kind, value, field);
    const entry = { input, path, kind, origText: '' };
    input.addEventListener('input', () => input.classList.toggle('changed', valueOf(entry) !== entry.origText));
    input.addEventListener('change', () => input.classList.toggle('changed', valueOf(entry) !== entry.origText));
    entry.origText = valueOf(entry);
    this.leaves.push(entry);
    const label = path.split('.').slice(1).join('.') || path;
    return el('div', { class: 'field' },
      el('label', { title: path }, label, ' ', input),
      el('span', { class: 'field-error', 'data-field': path }));
  }

  // What was changed: {partial (the changed leaves as a nested object), changed (how many),
  // bad (how many do not parse; each says why beside its field and is marked .invalid)}.
  changes() {
    const partial = {};
    let changed = 0;
    let bad = 0;
    for (const entry of this.leaves) {
      if (valueOf(entry) === entry.origText) continue;
      let value;
      try {
        value = parsed(entry);
      } catch (e) {
        bad += 1;
        const span = this.root.querySelector(`span.field-error${attrSelector('data-field', entry.path)}`);
        if (span) span.textContent = e.message;
        entry.input.classList.add('invalid');
        continue;
      }
      const parts = entry.path.split('.');
      let o = partial;
      for (const p of parts.slice(0, -1)) o = (o[p] = o[p] || {});
      o[parts[parts.length - 1]] = value;
      changed += 1;
    }
    return { partial, changed, bad };
  }
}

function fieldOf(msgType, key) {
  if (!msgType) return undefined;
  return msgType.byName.get(key) || msgType.fields.find((f) => f.jsonName === key);
}

function leafKind(value, field) {
  const T = Proto.Type;
  if (field) {
    if (field.repeated) return 'list';
    if (field.type === T.BOOL) return 'bool';
    if (field.type === T.ENUM) return 'enum';
    if (field.type === T.STRING || field.type === T.BYTES) return 'string';
    if (field.type === T.DOUBLE || field.type === T.FLOAT) return 'float';
    return 'int';
  }
  if (Array.isArray(value)) return 'list';
  if (typeof value === 'boolean') return 'bool';
  if (typeof value === 'number') return 'float';
  return 'string';
}

function leafInput(path, kind, value, field) {
  let input;
  if (kind === 'bool') {
    input = el('input', { type: 'checkbox', 'data-field': path });
    input.checked = value === true;
  } else if (kind === 'enum') {
    const names = field.enumType.values.map((v) => v.name);
    input = el('select', { 'data-field': path },
      ...names.filter((x) => !x.endsWith('_UNSPECIFIED') || x === value).map((x) => el('option', { value: x }, x)));
    if (typeof value === 'number') value = field.enumType.byNumber.get(value) || String(value);
    if (!names.includes(value)) input.append(el('option', { value: String(value) }, String(value)));
    input.value = String(value);
  } else if (kind === 'list') {
    input = el('input', { type: 'text', 'data-field': path, 'data-kind': 'list', size: 10 });
    input.value = Array.isArray(value) ? value.join(', ') : '';
  } else if (kind === 'int' || kind === 'float') {
    input = el('input', { type: 'number', 'data-field': path, step: kind === 'int' ? 1 : 'any' });
    input.value = String(value);
  } else {
    input = el('input', { type: 'text', 'data-field': path });
    input.value = value === undefined || value === null ? '' : String(value);
  }
  return input;
}

// A leaf's value as text for change detection.
function valueOf(entry) {
  const { input, kind } = entry;
  if (kind === 'bool') return String(input.checked);
  if (kind === 'list') return input.value.split(',').map((x) => x.trim()).filter(Boolean).join(',');
  if (kind === 'int' || kind === 'float') return input.value.trim();
  return input.value;
}

// The value to send, or throws Error(message) for a bad entry.
function parsed(entry) {
  const { input, kind } = entry;
  if (kind === 'bool') return input.checked;
  if (kind === 'int' || kind === 'float') {
    const text = input.value.trim();
    const v = Number(text);
    if (text === '' || !Number.isFinite(v)) throw new Error('not a number');
    if (kind === 'int' && !Number.isInteger(v)) throw new Error('not a whole number');
    return v;
  }
  if (kind === 'list') {
    const items = input.value.split(',').map((x) => x.trim()).filter(Boolean);
    return items.map((x) => {
      const v = Number(x);
      if (!Number.isFinite(v)) throw new Error(`"${x}" is not a number`);
      return v;
    });
  }
  return input.value;
}
