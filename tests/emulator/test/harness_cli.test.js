'use strict';
// The harness as other programs use it: spawn it, read `PORT /dev/pts/N`, talk over the pty.
const test = require('node:test');
const assert = require('node:assert/strict');
const fs = require('fs');
const path = require('path');
const readline = require('readline');
const tty = require('tty');
const { spawn } = require('child_process');
const proto = require('../lib/protocol');
const { EmulatedDevice, defaultElf } = require('../lib/device');

const skip = EmulatedDevice.elfExists() ? false : `firmware ELF not built (${defaultElf()})`;

test('harness over a pty: PORT line, handshake, commands and JSON events', { skip, timeout: 60_000 }, async () => {
  const child = spawn(process.execPath, [path.join(__dirname, '..', 'harness.js'), '--elf', defaultElf(), '--speed', '0'], {
    stdio: ['pipe', 'pipe', 'inherit'],
  });
  const lines = readline.createInterface({ input: child.stdout });
  const events = [];
  let onLine = null;
  lines.on('line', (l) => {
    if (l.startsWith('{')) events.push(JSON.parse(l));
    if (onLine) onLine(l);
  });
  const waitLine = (pred) =>
    new Promise((resolve) => {
      onLine = (l) => {
        if (pred(l)) {
          onLine = null;
          resolve(l);
        }
      };
    });
  try {
    const portLine = await waitLine((l) => l.startsWith('PORT '));
    const port = portLine.slice(5).trim();
    assert.match(port, /^\/dev\//);
    const fd = fs.openSync(port, 'r+');
    // tty.ReadStream reads the pty without blocking a thread, so it can be closed cleanly.
    const stream = new tty.ReadStream(fd);
    stream.setRawMode(true);
    const dec = new proto.FrameDecoder();
    const got = [];
    stream.on('data', (d) => got.push(...dec.push(d)));
    fs.writeSync(fd, Buffer.from([0]));
    fs.writeSync(fd, proto.encodeRequest(1, { type: 'Hello', protocol_version: proto.PROTOCOL_VERSION }));
    for (let i = 0; i < 200 && !got.some((m) => m.seq === 1); i++) await new Promise((r) => setTimeout(r, 25));
    const hello = got.find((m) => m.seq === 1);
    assert.ok(hello, 'no Hello response over the pty');
    assert.equal(hello.ok.kind, 'Emulator');
    child.stdin.write(JSON.stringify({ cmd: 'time' }) + '\n');
    const timeLine = await waitLine((l) => l.includes('"event":"time"'));
    assert.ok(JSON.parse(timeLine).sim_us > 0);
    assert.ok(events.some((e) => e.event === 'usb_configured'));
    stream.destroy();
  } finally {
    child.stdin.end();
    child.kill();
  }
});
