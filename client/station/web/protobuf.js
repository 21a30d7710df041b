// A small generic protobuf decoder driven by the schemas a Foxglove WebSocket server advertises
// (a serialized google.protobuf.FileDescriptorSet, base64 in the advertise message).
//
// The descriptor set itself is decoded with this same decoder, from a hand-written bootstrap
// schema that holds the few descriptor.proto fields we need (their field numbers are fixed by
// descriptor.proto). The result of decode() is a plain object keyed by the proto field names:
//  - scalars absent from the wire take their defaults (0, "", false, an empty Uint8Array, the
//    enum's first value); proto3 `optional` and oneof members stay undefined when absent;
//  - absent message fields are undefined; repeated fields are arrays ([] when absent);
//  - enums are numbers (SteviProto.Schema.enumName turns them into names);
//  - int64/uint64/fixed64 are Numbers, exact below 2^53;
//  - bytes are Uint8Array views into the input (copy them to keep them past the input's life);
//  - a field seen twice: a scalar takes the last value, a message is merged (as protobuf does);
//  - unknown fields (and known numbers with the wrong wire type, as protobuf does) are skipped;
//    truncated or malformed input throws a DecodeError.
//
// A classic script (no module) so that it loads from file:// as well; it defines
// window.SteviProto, and module.exports under Node.
(function (root) {
  'use strict';

  // FieldDescriptorProto.Type.
  const T = {
    DOUBLE: 1, FLOAT: 2, INT64: 3, UINT64: 4, INT32: 5, FIXED64: 6, FIXED32: 7, BOOL: 8,
    STRING: 9, GROUP: 10, MESSAGE: 11, BYTES: 12, UINT32: 13, ENUM: 14, SFIXED32: 15,
    SFIXED64: 16, SINT32: 17, SINT64: 18,
  };
  const LABEL_REPEATED = 3;
  const TWO_32 = 4294967296;
  const MAX_DEPTH = 64;

  // Wire type of each scalar type when not packed.
  function wireTypeOf(type) {
    switch (type) {
      case T.DOUBLE: case T.FIXED64: case T.SFIXED64: return 1;
      case T.FLOAT: case T.FIXED32: case T.SFIXED32: return 5;
      case T.STRING: case T.BYTES: case T.MESSAGE: return 2;
      case T.GROUP: return 3;
      default: return 0;
    }
  }

  class DecodeError extends Error {
    constructor(message) {
      super(message);
      this.name = 'DecodeError';
    }
  }

  const utf8 = new TextDecoder('utf-8');

  // A cursor over a Uint8Array.
  class Reader {
    constructor(bytes) {
      this.buf = bytes;
      this.pos = 0;
      this.view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    }

    need(n, end, what) {
      if (this.pos + n > end) {
        throw new DecodeError(`truncated ${what} at byte ${this.pos} (needs ${n}, ${end - this.pos} left)`);
      }
    }

    // A varint as two unsigned 32-bit halves: [lo, hi].
    varint64(end) {
      let lo = 0;
      let hi = 0;
      let shift = 0;
      for (let i = 0; i < 10; ++i) {
        if (this.pos >= end) throw new DecodeError(`truncated varint at byte ${this.pos}`);
        const b = this.buf[this.pos++];
        if (shift < 28) {
          lo |= (b & 0x7f) << shift;
        } else if (shift === 28) {
          lo |= (b & 0x0f) << 28;
          hi |= (b & 0x7f) >>> 4;
        } else {
          hi |= (b & 0x7f) << (shift - 32);
        }
        shift += 7;
        if ((b & 0x80) === 0) return [lo >>> 0, hi >>> 0];
      }
      throw new DecodeError(`varint longer than 10 bytes at byte ${this.pos}`);
    }

    // Unsigned varint that must fit 32 bits (tags, lengths).
    varint32(end) {
      const [lo, hi] = this.varint64(end);
      if (hi !== 0) throw new DecodeError(`varint too large at byte ${this.pos}`);
      return lo;
    }

    fixed64(end) {
      this.need(8, end, 'fixed64');
      const lo = this.view.getUint32(this.pos, true);
      const hi = this.view.getUint32(this.pos + 4, true);
      this.pos += 8;
      return [lo, hi];
    }

    skip(wireType, end, fieldNumber, depth) {
      switch (wireType) {
        case 0: this.varint64(end); return;
        case 1: this.need(8, end, 'fixed64'); this.pos += 8; return;
        case 5: this.need(4, end, 'fixed32'); this.pos += 4; return;
        case 2: {
          const len = this.varint32(end);
          this.need(len, end, 'length-delimited field');
          this.pos += len;
          return;
        }
        case 3: {  // a group: skip up to its end tag
          if (depth > MAX_DEPTH) throw new DecodeError('groups nested too deeply');
          for (;;) {
            if (this.pos >= end) throw new DecodeError(`truncated group ${fieldNumber}`);
            const tag = this.varint32(end);
            const wt = tag & 7;
            if ((tag >>> 3) === 0) throw new DecodeError(`field number 0 at byte ${this.pos}`);
            if (wt === 4) {
              if ((tag >>> 3) !== fieldNumber) throw new DecodeError(`mismatched end of group ${fieldNumber}`);
              return;
            }
            this.skip(wt, end, tag >>> 3, depth + 1);
          }
        }
        default:
          throw new DecodeError(`invalid wire type ${wireType} at byte ${this.pos}`);
      }
    }
  }

  function unsigned64([lo, hi]) { return hi * TWO_32 + lo; }

  function signed64([lo, hi]) {
    if (hi & 0x80000000) {  // two's complement negative: -(~x + 1)
      let nlo = (~lo >>> 0) + 1;
      let nhi = ~hi >>> 0;
      if (nlo === TWO_32) { nlo = 0; nhi = (nhi + 1) >>> 0; }
      return -(nhi * TWO_32 + nlo);
    }
    return hi * TWO_32 + lo;
  }

  function zigzag64([lo, hi]) {
    const negative = lo & 1;
    const mlo = ((lo >>> 1) | (hi << 31)) >>> 0;
    const mhi = hi >>> 1;
    const magnitude = mhi * TWO_32 + mlo;
    return negative ? -magnitude - 1 : magnitude;
  }

  // Reads one value of a scalar type (wire type already checked by the caller).
  function readScalar(r, type, end) {
    switch (type) {
      case T.DOUBLE: r.need(8, end, 'double'); { const v = r.view.getFloat64(r.pos, true); r.pos += 8; return v; }
      case T.FLOAT: r.need(4, end, 'float'); { const v = r.view.getFloat32(r.pos, true); r.pos += 4; return v; }
      case T.FIXED32: r.need(4, end, 'fixed32'); { const v = r.view.getUint32(r.pos, true); r.pos += 4; return v; }
      case T.SFIXED32: r.need(4, end, 'sfixed32'); { const v = r.view.getInt32(r.pos, true); r.pos += 4; return v; }
      case T.FIXED64: return unsigned64(r.fixed64(end));
      case T.SFIXED64: return signed64(r.fixed64(end));
      case T.INT64: return signed64(r.varint64(end));
      case T.UINT64: return unsigned64(r.varint64(end));
      case T.SINT64: return zigzag64(r.varint64(end));
      case T.INT32: case T.ENUM: return r.varint64(end)[0] | 0;
      case T.UINT32: return r.varint64(end)[0];
      case T.SINT32: { const lo = r.varint64(end)[0]; return (lo >>> 1) ^ -(lo & 1); }
      case T.BOOL: { const [lo, hi] = r.varint64(end); return lo !== 0 || hi !== 0; }
      case T.STRING: {
        const len = r.varint32(end);
        r.need(len, end, 'string');
        const s = utf8.decode(r.buf.subarray(r.pos, r.pos + len));
        r.pos += len;
        return s;
      }
      case T.BYTES: {
        const len = r.varint32(end);
        r.need(len, end, 'bytes');
        const b = r.buf.subarray(r.pos, r.pos + len);
        r.pos += len;
        return b;
      }
      default:
        throw new DecodeError(`unsupported field type ${type}`);
    }
  }

  function isPackable(type) {
    return type !== T.STRING && type !== T.BYTES && type !== T.MESSAGE && type !== T.GROUP;
  }

  function defaultOf(field) {
    switch (field.type) {
      case T.STRING: return '';
      case T.BYTES: return new Uint8Array(0);
      case T.BOOL: return false;
      case T.ENUM: return field.enumType && field.enumType.values.length ? field.enumType.values[0].number : 0;
      default: return 0;
    }
  }

  // Decodes the fields in r up to `end` into obj (a new message, or one being merged into).
  function decodeInto(type, r, end, obj, depth) {
    if (depth > MAX_DEPTH) throw new DecodeError(`messages nested deeper than ${MAX_DEPTH}`);
    while (r.pos < end) {
      const tag = r.varint32(end);
      const number = tag >>> 3;
      const wt = tag & 7;
      if (number === 0) throw new DecodeError(`field number 0 at byte ${r.pos}`);
      const field = type.byNumber.get(number);
      if (!field) {
        r.skip(wt, end, number, depth);
        continue;
      }
      if (field.type === T.MESSAGE) {
        if (wt !== 2) { r.skip(wt, end, number, depth); continue; }  // as protobuf: unknown
        const len = r.varint32(end);
        r.need(len, end, `${type.fullName}.${field.name}`);
        const subEnd = r.pos + len;
        const sub = field.messageType;
        if (field.repeated) {
          const m = sub.newObject();
          decodeInto(sub, r, subEnd, m, depth + 1);
          obj[field.name].push(m);
        } else {
          let m = obj[field.name];
          if (m === undefined) { m = sub.newObject(); obj[field.name] = m; }
          decodeInto(sub, r, subEnd, m, depth + 1);
        }
        r.pos = subEnd;
        continue;
      }
      if (field.type === T.GROUP) {  // proto2 groups: not used by our schemas; skip
        r.skip(wt, end, number, depth);
        continue;
      }
      if (field.repeated && wt === 2 && isPackable(field.type)) {
        const len = r.varint32(end);
        r.need(len, end, `${type.fullName}.${field.name} (packed)`);
        const packedEnd = r.pos + len;
        const out = obj[field.name];
        while (r.pos < packedEnd) out.push(readScalar(r, field.type, packedEnd));
        continue;
      }
      if (wt !== wireTypeOf(field.type)) {  // a known number with the wrong wire type: protobuf
        r.skip(wt, end, number, depth);     // treats it as an unknown field
        continue;
      }
      const v = readScalar(r, field.type, end);
      if (field.repeated) obj[field.name].push(v); else obj[field.name] = v;
    }
    if (r.pos !== end) throw new DecodeError(`${type.fullName}: field overruns its message`);
  }

  // One message type of a schema.
  class MessageType {
    constructor(fullName, fields) {
      this.fullName = fullName;
      this.fields = fields;  // [{name, number, type, repeated, presence, typeName, messageType?, enumType?}]
      this.byNumber = new Map();
      this.byName = new Map();
      for (const f of fields) { this.byNumber.set(f.number, f); this.byName.set(f.name, f); }
    }

    // A new object with every default set.
    newObject() {
      const o = {};
      for (const f of this.fields) {
        if (f.repeated) o[f.name] = [];
        else if (f.type === T.MESSAGE || f.type === T.GROUP || f.presence) o[f.name] = undefined;
        else o[f.name] = defaultOf(f);
      }
      return o;
    }

    decode(bytes) {
      if (!(bytes instanceof Uint8Array)) throw new DecodeError('decode needs a Uint8Array');
      const r = new Reader(bytes);
      const o = this.newObject();
      decodeInto(this, r, bytes.length, o, 0);
      return o;
    }
  }

  // The message and enum types of a FileDescriptorSet, by full name (no leading dot).
  class Schema {
    constructor() {
      this.types = new Map();   // full name -> MessageType
      this.enums = new Map();   // full name -> {fullName, values: [{name, number}], byNumber: Map, byName: Map}
      this.files = [];          // file names
    }

    type(fullName) {
      const t = this.types.get(fullName.replace(/^\./, ''));
      if (!t) throw new DecodeError(`schema has no message type ${fullName}`);
      return t;
    }

    decode(fullName, bytes) { return this.type(fullName).decode(bytes); }

    // The name of an enum value, or String(number) when the enum has none for it.
    enumName(enumFullName, number) {
      const e = this.enums.get(enumFullName.replace(/^\./, ''));
      const v = e && e.byNumber.get(number);
      return v !== undefined ? v : String(number);
    }

    // The enum of a message's field: schema.fieldEnum('stevi.v1.Track', 'state').
    fieldEnum(messageFullName, fieldName) {
      const t = this.types.get(messageFullName);
      const f = t && t.byName.get(fieldName);
      return f && f.enumType ? f.enumType : undefined;
    }
  }

  function makeEnum(fullName, values) {
    const e = { fullName, values, byNumber: new Map(), byName: new Map() };
    for (const v of values) {
      if (!e.byNumber.has(v.number)) e.byNumber.set(v.number, v.name);  // first alias wins
      e.byName.set(v.name, v.number);
    }
    return e;
  }

  // Resolves a type_name the protobuf way: ".a.b.C" is absolute; "C" is searched from the
  // innermost scope outwards.
  function resolveName(name, scope, known) {
    if (name.startsWith('.')) return known(name.slice(1)) ? name.slice(1) : undefined;
    let parts = scope ? scope.split('.') : [];
    for (;;) {
      const candidate = parts.length ? `${parts.join('.')}.${name}` : name;
      if (known(candidate)) return candidate;
      if (!parts.length) return undefined;
      parts = parts.slice(0, -1);
    }
  }

  // Builds a Schema from a decoded FileDescriptorSet (bootstrap-decoded plain objects).
  function buildSchema(fds) {
    const schema = new Schema();
    const pending = [];  // [fullName, DescriptorProto, proto3]
    function addEnum(prefix, e) {
      const fullName = prefix ? `${prefix}.${e.name}` : e.name;
      schema.enums.set(fullName, makeEnum(fullName, e.value.map((v) => ({ name: v.name, number: v.number }))));
    }
    function addMessage(prefix, m, proto3) {
      const fullName = prefix ? `${prefix}.${m.name}` : m.name;
      pending.push([fullName, m, proto3]);
      for (const n of m.nested_type) addMessage(fullName, n, proto3);
      for (const e of m.enum_type) addEnum(fullName, e);
    }
    for (const file of fds.file) {
      schema.files.push(file.name);
      const proto3 = file.syntax === 'proto3';
      for (const m of file.message_type) addMessage(file.package, m, proto3);
      for (const e of file.enum_type) addEnum(file.package, e);
    }
    // Create every type, then resolve the references (types may refer to later ones).
    const fieldLists = [];
    for (const [fullName, m] of pending) {
      const fields = m.field.map((f) => ({
        name: f.name,
        number: f.number,
        type: f.type,
        repeated: f.label === LABEL_REPEATED,
        // proto3 optional and real oneof members have presence: absent = undefined.
        presence: Boolean(f.proto3_optional) || f.oneof_index !== undefined,
        typeName: f.type_name,
        jsonName: f.json_name,
        oneofIndex: f.oneof_index,
      }));
      fieldLists.push([fullName, fields]);
      schema.types.set(fullName, new MessageType(fullName, fields));
    }
    for (const [fullName, fields] of fieldLists) {
      const scope = fullName;
      for (const f of fields) {
        if (f.type === T.MESSAGE || f.type === T.GROUP) {
          const resolved = resolveName(f.typeName, scope, (n) => schema.types.has(n));
          if (!resolved) throw new DecodeError(`${fullName}.${f.name}: unknown message type ${f.typeName}`);
          f.messageType = schema.types.get(resolved);
        } else if (f.type === T.ENUM) {
          const resolved = resolveName(f.typeName, scope, (n) => schema.enums.has(n));
          if (!resolved) throw new DecodeError(`${fullName}.${f.name}: unknown enum type ${f.typeName}`);
          f.enumType = schema.enums.get(resolved);
        } else if (f.type === undefined || f.type < 1 || f.type > 18) {
          // descriptor.proto leaves type unset when type_name names a message or enum that
          // protoc has not resolved: decide by what the name resolves to.
          const asMsg = f.typeName && resolveName(f.typeName, scope, (n) => schema.types.has(n));
          const asEnum = f.typeName && resolveName(f.typeName, scope, (n) => schema.enums.has(n));
          if (asMsg) { f.type = T.MESSAGE; f.messageType = schema.types.get(asMsg); }
          else if (asEnum) { f.type = T.ENUM; f.enumType = schema.enums.get(asEnum); }
          else throw new DecodeError(`${fullName}.${f.name}: unknown field type`);
        }
      }
    }
    return schema;
  }

  // The bootstrap: the parts of google/protobuf/descriptor.proto we read.
  function bootstrapSchema() {
    const S = (name, number, extra) => Object.assign({ name, number, type: T.STRING, repeated: false, presence: false }, extra);
    const schema = new Schema();
    const def = (fullName, fields) => schema.types.set(fullName, new MessageType(fullName, fields));
    const P = 'google.protobuf.';
    def(`${P}FileDescriptorSet`, [S('file', 1, { type: T.MESSAGE, repeated: true, typeName: `${P}FileDescriptorProto` })]);
    def(`${P}FileDescriptorProto`, [
      S('name', 1), S('package', 2), S('dependency', 3, { repeated: true }),
      S('message_type', 4, { type: T.MESSAGE, repeated: true, typeName: `${P}DescriptorProto` }),
      S('enum_type', 5, { type: T.MESSAGE, repeated: true, typeName: `${P}EnumDescriptorProto` }),
      S('syntax', 12),
    ]);
    def(`${P}DescriptorProto`, [
      S('name', 1),
      S('field', 2, { type: T.MESSAGE, repeated: true, typeName: `${P}FieldDescriptorProto` }),
      S('nested_type', 3, { type: T.MESSAGE, repeated: true, typeName: `${P}DescriptorProto` }),
      S('enum_type', 4, { type: T.MESSAGE, repeated: true, typeName: `${P}EnumDescriptorProto` }),
      S('oneof_decl', 8, { type: T.MESSAGE, repeated: true, typeName: `${P}OneofDescriptorProto` }),
    ]);
    def(`${P}OneofDescriptorProto`, [S('name', 1)]);
    def(`${P}FieldDescriptorProto`, [
      S('name', 1),
      S('number', 3, { type: T.INT32 }),
      S('label', 4, { type: T.INT32 }),
      S('type', 5, { type: T.INT32, presence: true }),
      S('type_name', 6),
      S('oneof_index', 9, { type: T.INT32, presence: true }),
      S('json_name', 10),
      S('proto3_optional', 17, { type: T.BOOL }),
    ]);
    def(`${P}EnumDescriptorProto`, [
      S('name', 1),
      S('value', 2, { type: T.MESSAGE, repeated: true, typeName: `${P}EnumValueDescriptorProto` }),
    ]);
    def(`${P}EnumValueDescriptorProto`, [S('name', 1), S('number', 2, { type: T.INT32 })]);
    for (const t of schema.types.values()) {
      for (const f of t.fields) if (f.type === T.MESSAGE) f.messageType = schema.types.get(f.typeName);
    }
    return schema;
  }

  const BOOTSTRAP = bootstrapSchema();

  // base64 (standard or URL-safe, padding optional) -> Uint8Array. Throws on bad input.
  function base64ToBytes(text) {
    const clean = String(text).replace(/\s+/g, '').replace(/-/g, '+').replace(/_/g, '/');
    let bin;
    try {
      bin = atob(clean);
    } catch (e) {
      throw new DecodeError('schema is not valid base64');
    }
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; ++i) out[i] = bin.charCodeAt(i);
    return out;
  }

  // Parses a serialized FileDescriptorSet (Uint8Array) into a Schema.
  function parseFileDescriptorSet(bytes) {
    return buildSchema(BOOTSTRAP.decode('google.protobuf.FileDescriptorSet', bytes));
  }

  // Schemas by their base64 text: channels sharing a schema share its parse.
  const cache = new Map();
  function schemaFromBase64(b64) {
    let s = cache.get(b64);
    if (!s) {
      s = parseFileDescriptorSet(base64ToBytes(b64));
      if (cache.size > 64) cache.clear();
      cache.set(b64, s);
    }
    return s;
  }

  const api = {
    DecodeError, Schema, MessageType, Type: T,
    parseFileDescriptorSet, schemaFromBase64, base64ToBytes,
  };
  root.SteviProto = api;
  if (typeof module !== 'undefined' && module.exports) module.exports = api;
})(typeof window !== 'undefined' ? window : globalThis);
