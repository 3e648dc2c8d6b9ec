#!/usr/bin/env node
'use strict';
// skinbrdf emulator harness: runs the RP2040 firmware image in rp2040js with a simulated camera
// and flash, and exposes the firmware's USB CDC port as a pseudo-terminal (or a TCP port).
// See README.md for the interface (stdout lines, stdin commands).

const path = require('path');
const net = require('net');
const readline = require('readline');
const { spawn } = require('child_process');
const { Board } = require('./lib/board');
const { Rig } = require('./lib/models');
const { loadPinmap } = require('./lib/pinmap');

const USAGE = `usage: node harness.js [--elf PATH] [--pinmap PATH] [--pty | --tcp PORT] [--speed X]
                       [--seed N] [--lag-us MIN,MAX] [--recycle-us N] [--fires-on hotshoe|trigger|both]
                       [--log error|warn|info|debug] [--keep-running]
  --elf       firmware ELF (default: $SKINBRDF_FIRMWARE_ELF, else the release build under
              $CARGO_TARGET_DIR or firmware/rp2040/target)
  --pty       bridge USB CDC to a new pseudo-terminal (default); prints "PORT /dev/pts/N"
  --tcp PORT  bridge USB CDC to a TCP server on 127.0.0.1:PORT (0 = any); prints "TCP 127.0.0.1:P"
  --speed X   simulated seconds per wall-clock second (default 1: real time; 0: as fast as possible)
  --keep-running  do not exit when stdin closes (default: exit, so a test's harness dies with it)`;

function parseArgs(argv) {
  const repo = path.join(__dirname, '..', '..');
  const targetDir = process.env.CARGO_TARGET_DIR || path.join(repo, 'firmware', 'rp2040', 'target');
  const o = {
    elf: process.env.SKINBRDF_FIRMWARE_ELF || path.join(targetDir, 'thumbv6m-none-eabi', 'release', 'skinbrdf-rp2040'),
    pinmap: undefined,
    bridge: 'pty',
    tcpPort: 0,
    speed: 1,
    camera: {},
    flash: {},
    log: 'error',
    exitOnEof: true,
  };
  for (let i = 2; i < argv.length; i++) {
    const a = argv[i];
    const val = () => {
      if (i + 1 >= argv.length) throw new Error(`${a} needs a value`);
      return argv[++i];
    };
    if (a === '--elf') o.elf = val();
    else if (a === '--pinmap') o.pinmap = val();
    else if (a === '--pty') o.bridge = 'pty';
    else if (a === '--tcp') {
      o.bridge = 'tcp';
      o.tcpPort = Number(val());
    } else if (a === '--speed') o.speed = Number(val());
    else if (a === '--seed') o.camera.seed = Number(val());
    else if (a === '--lag-us') {
      const [min, max] = val().split(',').map(Number);
      o.camera.lagMinUs = min;
      o.camera.lagMaxUs = max ?? min;
    } else if (a === '--recycle-us') o.flash.recycleUs = Number(val());
    else if (a === '--fires-on') o.flash.firesOn = val();
    else if (a === '--log') o.log = val();
    else if (a === '--keep-running') o.exitOnEof = false;
    else if (a === '-h' || a === '--help') {
      console.log(USAGE);
      process.exit(0);
    } else throw new Error(`unknown argument ${a}\n${USAGE}`);
  }
  if (!(o.speed >= 0)) throw new Error('--speed must be >= 0');
  return o;
}

/** One JSON line on stdout. */
function emit(obj) {
  if (obj.sim_ns !== undefined) obj.sim_us = obj.sim_ns / 1000;
  process.stdout.write(JSON.stringify(obj) + '\n');
}

function startBridge(opts, board) {
  return new Promise((resolve, reject) => {
    if (opts.bridge === 'tcp') {
      let socket = null;
      const server = net.createServer((s) => {
        if (socket) socket.destroy();
        socket = s;
        emit({ event: 'host_connected', sim_ns: board.nanos });
        s.on('data', (d) => board.sendToDevice(d));
        s.on('close', () => {
          if (socket === s) socket = null;
          emit({ event: 'host_disconnected', sim_ns: board.nanos });
        });
        s.on('error', () => {});
      });
      server.on('error', reject);
      server.listen(opts.tcpPort, '127.0.0.1', () => {
        board.onSerialData((d) => socket && socket.write(d));
        resolve({ line: `TCP 127.0.0.1:${server.address().port}`, close: () => server.close() });
      });
      return;
    }
    const child = spawn('python3', [path.join(__dirname, 'pty_bridge.py')], { stdio: ['pipe', 'pipe', 'pipe'] });
    child.on('error', reject);
    child.stdout.on('data', (d) => board.sendToDevice(d));
    board.onSerialData((d) => child.stdin.write(d));
    const rl = readline.createInterface({ input: child.stderr });
    rl.on('line', (line) => {
      if (line.startsWith('PTY ')) resolve({ line: `PORT ${line.slice(4)}`, close: () => child.kill() });
      else if (line.startsWith('DROPPED ')) emit({ event: 'bytes_dropped', count: Number(line.slice(8)) });
      else process.stderr.write(`pty_bridge: ${line}\n`);
    });
    child.on('exit', (code) => {
      if (!closing) {
        process.stderr.write(`pty_bridge exited (${code})\n`);
        process.exit(1);
      }
    });
  });
}

let closing = false;

async function main() {
  const opts = parseArgs(process.argv);
  const pins = loadPinmap(opts.pinmap);
  const board = new Board(opts.elf, { logLevel: opts.log });
  const rig = new Rig(board, pins, emit, { camera: opts.camera, flash: opts.flash });
  const bridge = await startBridge(opts, board);

  let announced = false;
  board.onConnected = () => {
    emit({ event: 'usb_configured', sim_ns: board.nanos });
    if (!announced) {
      announced = true;
      process.stdout.write(bridge.line + '\n');
    }
  };

  board.onReset((cause) => emit({ event: 'watchdog_reset', cause, sim_ns: board.nanos }));

  // Commands on stdin (one JSON object per line).
  const commands = readline.createInterface({ input: process.stdin });
  commands.on('line', (line) => {
    if (!line.trim()) return;
    let cmd;
    try {
      cmd = JSON.parse(line);
    } catch (e) {
      emit({ event: 'error', message: `bad command: ${e.message}` });
      return;
    }
    handle(cmd);
  });
  commands.on('close', () => {
    if (opts.exitOnEof) shutdown(0);
  });

  function handle(cmd) {
    const atNs = (c) =>
      c.at_us !== undefined ? Math.round(c.at_us * 1000) : board.nanos + Math.round((c.in_us ?? 0) * 1000);
    switch (cmd.cmd) {
      case 'time':
        emit({ event: 'time', sim_ns: board.nanos });
        break;
      case 'configure':
        rig.configure({ camera: cmd.camera, flash: cmd.flash });
        emit({ event: 'configured', camera: rig.camera, flash: rig.flash, sim_ns: board.nanos });
        break;
      case 'pulse': {
        // {"cmd":"pulse","signal":"xsync","at_us":N | "in_us":N,"width_us":W}
        if (!['xsync', 'photodiode', 'flash_ready'].includes(cmd.signal)) {
          emit({ event: 'error', message: `unknown signal ${cmd.signal}` });
          break;
        }
        const at = atNs(cmd);
        if (at < board.nanos) {
          emit({ event: 'error', message: `pulse at ${at} ns is in the past (now ${board.nanos} ns)` });
          break;
        }
        rig.pulse(cmd.signal, at, Math.round((cmd.width_us ?? 1000) * 1000));
        emit({ event: 'pulse_scheduled', signal: cmd.signal, at_ns: at, sim_ns: board.nanos });
        break;
      }
      case 'set': {
        // {"cmd":"set","signal":"flash_ready","asserted":true}
        if (!['xsync', 'photodiode', 'flash_ready'].includes(cmd.signal)) {
          emit({ event: 'error', message: `unknown signal ${cmd.signal}` });
          break;
        }
        rig.drive(cmd.signal, !!cmd.asserted);
        break;
      }
      case 'usb_reconnect':
        // Unplug and replug: bus reset, re-enumeration (the firmware sees link down, then up).
        board.reconnectUsb();
        emit({ event: 'usb_reset', sim_ns: board.nanos });
        break;
      case 'dtr':
        // {"cmd":"dtr","asserted":false}: the host closes (or reopens) the port.
        board.setDtr(!!cmd.asserted);
        emit({ event: 'dtr', asserted: !!cmd.asserted, sim_ns: board.nanos });
        break;
      case 'hang':
        // The firmware hangs (a runaway loop, interrupts masked): only the watchdog gets out.
        board.hang();
        emit({ event: 'hang', sim_ns: board.nanos });
        break;
      case 'speed':
        opts.speed = Number(cmd.value);
        rebase();
        break;
      case 'quit':
        shutdown(0);
        break;
      default:
        emit({ event: 'error', message: `unknown command ${cmd.cmd}` });
    }
  }

  // Pacing: simulated time follows wall-clock time x speed (or runs flat out with speed 0).
  let wallStart = process.hrtime.bigint();
  let simStart = board.nanos;
  function rebase() {
    wallStart = process.hrtime.bigint();
    simStart = board.nanos;
  }
  const SLICE_NS = 2_000_000; // at most 2 ms of simulated time per slice, then serve I/O
  function slice() {
    if (closing) return;
    let target;
    if (opts.speed > 0) {
      const wallNs = Number(process.hrtime.bigint() - wallStart);
      target = Math.min(simStart + wallNs * opts.speed, board.nanos + SLICE_NS);
    } else {
      target = board.nanos + SLICE_NS;
    }
    if (target > board.nanos) board.runUntil(target, 200_000);
    const ahead = opts.speed > 0 && board.nanos >= simStart + Number(process.hrtime.bigint() - wallStart) * opts.speed;
    if (ahead) setTimeout(slice, 1);
    else setImmediate(slice);
  }

  function shutdown(code) {
    if (closing) return;
    closing = true;
    bridge.close();
    emit({ event: 'exit', sim_ns: board.nanos, instructions: board.instructions });
    process.exit(code);
  }
  process.on('SIGTERM', () => shutdown(0));
  process.on('SIGINT', () => shutdown(0));

  emit({ event: 'started', elf: opts.elf, speed: opts.speed, camera: rig.camera, flash: rig.flash, sim_ns: board.nanos });
  slice();
}

main().catch((e) => {
  process.stderr.write(`harness: ${e.message}\n`);
  process.exit(1);
});
