'use strict';
// The harness's JavaScript codec against the golden vectors of docs/protocol.md.
const test = require('node:test');
const assert = require('node:assert/strict');
const p = require('../lib/protocol');

const hex = (s) => Buffer.from(s.replace(/\s+/g, ''), 'hex');

test('CRC-32 check value', () => {
  assert.equal(p.crc32(Buffer.from('123456789')), 0xcbf43926);
});

test('request golden vectors', () => {
  assert.deepEqual(p.encodeRequest(1, { type: 'Ping' }), hex('07 01 07 1d b6 a6 c6 00'));
  assert.deepEqual(p.encodeRequest(0, { type: 'Hello', protocol_version: 1 }), hex('01 01 06 01 84 e9 46 88 00'));
  assert.deepEqual(p.encodeRequest(300, { type: 'ReadClock' }), hex('08 ac 02 01 02 2f 12 6a 00'));
  const plan = {
    groups: [{
      label: 'm', role: 'Measurement', count: 30, min_interval_us: 2_000_000, pre_focus_us: 300_000,
      shutter_pulse_us: 100_000, xsync_timeout_us: 500_000, flash_ready_timeout_us: 5_000_000,
      flash_window_us: 20_000, flash_mode: 'ControllerOnXsync',
    }],
    policy: { max_retries: 2, on_exhausted: 'SkipShot' },
    flash_trigger_pulse_us: 1000,
  };
  assert.deepEqual(
    p.encodeRequest(2, { type: 'LoadPlan', plan }),
    hex(`06 02 02 01 01 6d 1e 1e 80 89 7a e0 a7 12 a0 8d 06 a0 c2 1e c0 96 b1 02 a0 9c 01
         01 02 01 e8 07 7f 9b dc ff 00`),
  );
});

test('device message golden vectors', () => {
  const dec = new p.FrameDecoder();
  const [hello] = dec.push(hex('01 01 01 01 18 01 05 30 2e 31 2e 30 08 53 49 4d 2d 30 30 30 31 01 d2 09 31 db c3 7d 00'));
  assert.deepEqual(hello, {
    kind: 'Response', seq: 0,
    ok: { type: 'Hello', protocol_version: 1, firmware_version: '0.1.0', serial: 'SIM-0001', kind: 'Simulator', clock_us: 1234 },
  });
  const [mismatch] = dec.push(hex('01 01 02 01 07 01 02 ab 96 6b fe 00'));
  assert.deepEqual(mismatch, { kind: 'Response', seq: 0, err: { type: 'VersionMismatch', device: 1, host: 2 } });
  const [record] = dec.push(hex(`02 01 04 05 01 02 01 1c 80 e4 97 d0 12 01 a0 f1 9d d0 12 01 a0 e2 a2 d0 12
        01 d2 e2 a2 d0 12 01 e0 c6 5b 05 72 55 ff 15 00`));
  assert.deepEqual(record.event, {
    type: 'Record', index: 5, group: 1, shot: 2, attempt: 0, role: 'Measurement', started_us: 5_000_000_000,
    shutter_command_us: 5_000_100_000, xsync_us: 5_000_180_000, flash_fired_us: 5_000_180_050,
    recycle_us: 1_500_000, outcome: 'Ok',
  });
  const [ready] = dec.push(hex('11 01 01 87 80 80 80 10 01 01 e0 c6 5b 85 4c ae d6 00'));
  assert.deepEqual(ready.event, { type: 'FlashReady', at_us: 2 ** 32 + 7, ready: true, recycle_us: 1_500_000 });
});

test('decoder survives garbage and a corrupted frame', () => {
  const dec = new p.FrameDecoder();
  const good = hex('01 01 02 01 07 01 02 ab 96 6b fe 00');
  const bad = Buffer.from(good);
  bad[5] ^= 0x40;
  // Garbage without a delimiter joins the next frame and spoils it; the one after is intact.
  const out = dec.push(Buffer.concat([hex('ff 13 37'), good, bad, good]));
  assert.deepEqual(out.map((m) => m.kind), ['Error', 'Error', 'Response']);
  assert.equal(out[2].err.type, 'VersionMismatch');
});
