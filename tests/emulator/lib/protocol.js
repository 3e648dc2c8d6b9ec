'use strict';
// A small JavaScript implementation of the wire protocol (docs/protocol.md), for the emulator's
// own tests: COBS(postcard payload ‖ CRC-32 LE) ‖ 0x00. It covers every request and every
// device message of protocol version 1. `test/protocol.test.js` checks it against the golden
// vectors of docs/protocol.md, so it cannot silently drift from the Rust crate.

const PROTOCOL_VERSION = 1;
const MAX_FRAME_LEN = 1024;

// ------------------------------------------------------------------------------ CRC-32/ISO-HDLC

const CRC_TABLE = (() => {
  const t = new Uint32Array(256);
  for (let n = 0; n < 256; n++) {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    t[n] = c >>> 0;
  }
  return t;
})();

function crc32(bytes) {
  let c = 0xffffffff;
  for (const b of bytes) c = CRC_TABLE[(c ^ b) & 0xff] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

// ------------------------------------------------------------------------------ COBS

function cobsEncode(data) {
  const out = [0];
  let codeIdx = 0;
  let code = 1;
  for (const b of data) {
    if (b === 0) {
      out[codeIdx] = code;
      codeIdx = out.length;
      out.push(0);
      code = 1;
    } else {
      out.push(b);
      code++;
      if (code === 0xff) {
        out[codeIdx] = code;
        codeIdx = out.length;
        out.push(0);
        code = 1;
      }
    }
  }
  out[codeIdx] = code;
  return out;
}

function cobsDecode(data) {
  const out = [];
  let i = 0;
  while (i < data.length) {
    const code = data[i];
    if (code === 0) throw new Error('COBS: zero byte inside a frame');
    if (i + code > data.length + 1) throw new Error('COBS: truncated block');
    for (let j = 1; j < code; j++) out.push(data[i + j]);
    i += code;
    if (code < 0xff && i < data.length) out.push(0);
  }
  return out;
}

// ------------------------------------------------------------------------------ postcard

class Writer {
  constructor() {
    this.bytes = [];
  }
  varint(v) {
    // u32/u64 as LEB128; Numbers are exact up to 2^53, enough for device microseconds.
    if (!Number.isSafeInteger(v) || v < 0) throw new Error(`varint out of range: ${v}`);
    do {
      let b = v % 128;
      v = Math.floor(v / 128);
      if (v > 0) b |= 0x80;
      this.bytes.push(b);
    } while (v > 0);
    return this;
  }
  bool(b) {
    this.bytes.push(b ? 1 : 0);
    return this;
  }
  str(s) {
    const b = Buffer.from(s, 'utf8');
    this.varint(b.length);
    for (const x of b) this.bytes.push(x);
    return this;
  }
}

class Reader {
  constructor(bytes) {
    this.b = bytes;
    this.i = 0;
  }
  byte() {
    if (this.i >= this.b.length) throw new Error('postcard: unexpected end');
    return this.b[this.i++];
  }
  varint() {
    let v = 0;
    let mul = 1;
    for (let n = 0; n < 10; n++) {
      const b = this.byte();
      v += (b & 0x7f) * mul;
      if (!(b & 0x80)) return v;
      mul *= 128;
    }
    throw new Error('postcard: varint too long');
  }
  bool() {
    const b = this.byte();
    if (b > 1) throw new Error(`postcard: bad bool ${b}`);
    return b === 1;
  }
  option(f) {
    return this.bool() ? f() : null;
  }
  str() {
    const n = this.varint();
    const s = Buffer.from(this.b.slice(this.i, this.i + n)).toString('utf8');
    this.i += n;
    return s;
  }
}

// ------------------------------------------------------------------------------ messages

const REQUESTS = ['Hello', 'ReadClock', 'LoadPlan', 'Run', 'Abort', 'AckRecords', 'FetchRecords', 'Ping', 'SetWatchdog', 'GetStatus'];
const ROLES = ['Measurement', 'LightPosition', 'ReferenceStandard', 'StandardPosition'];
const FLASH_MODES = ['CameraHotShoe', 'ControllerOnXsync'];
const EXHAUSTED = ['AbortSession', 'SkipShot'];
const KINDS = ['Board', 'Simulator', 'Emulator'];
const STATES = ['Idle', 'Ready', 'Running', 'Completed', 'Aborted'];
const PLAN_PROBLEMS = ['NoGroups', 'ZeroCount', 'ZeroShutterPulse', 'ZeroXsyncTimeout', 'ZeroFlashWindow', 'ZeroFlashTriggerPulse', 'TooManyShots'];
const OUTCOMES = ['Ok', 'MissingXsync', 'MissingFlash', 'FlashNotReady', 'Aborted'];
const FAULT_KINDS = ['MissingXsync', 'MissingFlash', 'FlashNotReady', 'RetriesExhausted', 'HostSilent'];
const LOG_LEVELS = ['Debug', 'Info', 'Warn', 'Error'];
const SESSION_OUTCOMES = ['Completed', 'Aborted', 'Faulted'];

function idx(list, name) {
  const i = list.indexOf(name);
  if (i < 0) throw new Error(`unknown variant ${name}`);
  return i;
}

/** Payload of `Request { seq, body }`; body = { type: 'Hello', protocol_version } etc. */
function encodeRequestPayload(seq, body) {
  const w = new Writer().varint(seq).varint(idx(REQUESTS, body.type));
  switch (body.type) {
    case 'Hello':
      w.varint(body.protocol_version);
      break;
    case 'LoadPlan': {
      const p = body.plan;
      w.varint(p.groups.length);
      for (const g of p.groups) {
        w.str(g.label).varint(idx(ROLES, g.role)).varint(g.count);
        for (const k of ['min_interval_us', 'pre_focus_us', 'shutter_pulse_us', 'xsync_timeout_us', 'flash_ready_timeout_us', 'flash_window_us']) w.varint(g[k]);
        w.varint(idx(FLASH_MODES, g.flash_mode));
      }
      w.varint(p.policy.max_retries).varint(idx(EXHAUSTED, p.policy.on_exhausted));
      w.varint(p.flash_trigger_pulse_us);
      break;
    }
    case 'Run':
      w.varint(body.first_group).varint(body.last_group);
      break;
    case 'AckRecords':
      w.varint(body.next_index);
      break;
    case 'FetchRecords':
      w.varint(body.from_index);
      break;
    case 'SetWatchdog':
      w.varint(body.timeout_us);
      break;
    default:
      break;
  }
  return w.bytes;
}

function frame(payload) {
  const crc = crc32(payload);
  const withCrc = payload.concat([crc & 0xff, (crc >>> 8) & 0xff, (crc >>> 16) & 0xff, crc >>> 24]);
  return Buffer.from(cobsEncode(withCrc).concat([0]));
}

function encodeRequest(seq, body) {
  return frame(encodeRequestPayload(seq, body));
}

function decodeResponseBody(r) {
  const v = r.varint();
  switch (v) {
    case 0:
      return {
        type: 'Hello',
        protocol_version: r.varint(),
        firmware_version: r.str(),
        serial: r.str(),
        kind: KINDS[r.varint()],
        clock_us: r.varint(),
      };
    case 1:
      return { type: 'Clock', device_us: r.varint() };
    case 2:
      return { type: 'PlanLoaded', total_shots: r.varint() };
    case 3:
      return { type: 'Running', first_index: r.varint() };
    case 4:
      return { type: 'Aborted', was_running: r.bool() };
    case 5:
      return { type: 'Acked', unacked: r.varint() };
    case 6:
      return { type: 'Fetching', count: r.varint() };
    case 7:
      return { type: 'Pong', device_us: r.varint() };
    case 8:
      return { type: 'WatchdogSet', timeout_us: r.varint() };
    case 9:
      return {
        type: 'Status',
        now_us: r.varint(),
        state: STATES[r.varint()],
        next_index: r.varint(),
        unacked: r.varint(),
        oldest_unacked: r.option(() => r.varint()),
        flash_ready: r.bool(),
        bad_frames: r.varint(),
        dropped_messages: r.varint(),
        watchdog_us: r.varint(),
      };
    default:
      throw new Error(`unknown ResponseBody ${v}`);
  }
}

function decodeDeviceError(r) {
  const v = r.varint();
  switch (v) {
    case 0:
      return { type: 'VersionMismatch', device: r.varint(), host: r.varint() };
    case 1:
      return { type: 'HandshakeRequired' };
    case 2:
      return { type: 'Busy' };
    case 3:
      return { type: 'NoPlan' };
    case 4:
      return { type: 'InvalidPlan', group: r.varint(), problem: PLAN_PROBLEMS[r.varint()] };
    case 5:
      return { type: 'BadGroupRange', groups: r.varint(), next_group: r.varint() };
    case 6:
      return { type: 'UnackedRecords', unacked: r.varint() };
    case 7:
      return { type: 'AckBeyondEnd', next_index: r.varint() };
    case 8:
      return { type: 'AlreadyAcked', oldest_held: r.varint() };
    case 9:
      return { type: 'SessionAborted' };
    default:
      throw new Error(`unknown DeviceError ${v}`);
  }
}

function decodeEvent(r) {
  const v = r.varint();
  const opt = () => r.option(() => r.varint());
  switch (v) {
    case 0:
      return {
        type: 'Record',
        index: r.varint(),
        group: r.varint(),
        shot: r.varint(),
        attempt: r.varint(),
        role: ROLES[r.varint()],
        started_us: r.varint(),
        shutter_command_us: opt(),
        xsync_us: opt(),
        flash_fired_us: opt(),
        recycle_us: opt(),
        outcome: OUTCOMES[r.varint()],
      };
    case 1:
      return { type: 'FlashReady', at_us: r.varint(), ready: r.bool(), recycle_us: opt() };
    case 2:
      return { type: 'Fault', at_us: r.varint(), kind: FAULT_KINDS[r.varint()], index: opt() };
    case 3:
      return { type: 'Log', at_us: r.varint(), level: LOG_LEVELS[r.varint()], text: r.str() };
    case 4:
      return { type: 'GroupsDone', at_us: r.varint(), last_group: r.varint(), next_index: r.varint() };
    case 5:
      return { type: 'SessionDone', at_us: r.varint(), outcome: SESSION_OUTCOMES[r.varint()], records: r.varint() };
    default:
      throw new Error(`unknown Event ${v}`);
  }
}

/** Decodes a DeviceMessage payload: { kind: 'Response', seq, ok?, err? } or { kind: 'Event', ... }. */
function decodeDeviceMessagePayload(bytes) {
  const r = new Reader(bytes);
  const v = r.varint();
  let msg;
  if (v === 0) {
    const seq = r.varint();
    const res = r.varint();
    if (res === 0) msg = { kind: 'Response', seq, ok: decodeResponseBody(r) };
    else if (res === 1) msg = { kind: 'Response', seq, err: decodeDeviceError(r) };
    else throw new Error(`bad Result tag ${res}`);
  } else if (v === 1) {
    msg = { kind: 'Event', event: decodeEvent(r) };
  } else throw new Error(`unknown DeviceMessage ${v}`);
  if (r.i !== bytes.length) throw new Error(`${bytes.length - r.i} trailing bytes`);
  return msg;
}

/** Frame body (between delimiters) -> payload, checking the CRC. */
function unframe(body) {
  const decoded = cobsDecode(body);
  if (decoded.length < 4) throw new Error('frame shorter than its CRC');
  const payload = decoded.slice(0, -4);
  const c = decoded.slice(-4);
  const got = (c[0] | (c[1] << 8) | (c[2] << 16) | (c[3] << 24)) >>> 0;
  if (got !== crc32(payload)) throw new Error('CRC mismatch');
  return payload;
}

/** Streaming decoder: push bytes, get decoded device messages (or errors) back. */
class FrameDecoder {
  constructor() {
    this.buf = [];
  }
  push(bytes) {
    const out = [];
    for (const b of bytes) {
      if (b !== 0) {
        if (this.buf.length < MAX_FRAME_LEN) this.buf.push(b);
        continue;
      }
      if (this.buf.length === 0) continue;
      const body = this.buf;
      this.buf = [];
      try {
        out.push(decodeDeviceMessagePayload(unframe(body)));
      } catch (e) {
        out.push({ kind: 'Error', message: e.message });
      }
    }
    return out;
  }
}

module.exports = {
  PROTOCOL_VERSION,
  MAX_FRAME_LEN,
  crc32,
  cobsEncode,
  cobsDecode,
  encodeRequest,
  encodeRequestPayload,
  decodeDeviceMessagePayload,
  unframe,
  frame,
  FrameDecoder,
};
