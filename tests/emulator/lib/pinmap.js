'use strict';
// Reads hardware/pinmap.toml (the one pin map the firmware is generated from). Only the subset
// of TOML that file uses: `[pins.NAME]` tables with `key = "string"` or `key = integer`.

const fs = require('fs');
const path = require('path');

const DEFAULT_PATH = path.join(__dirname, '..', '..', '..', 'hardware', 'pinmap.toml');

function parsePinmap(text, file = 'pinmap.toml') {
  const pins = {};
  let current = null;
  text.split('\n').forEach((raw, i) => {
    const line = raw.replace(/#.*$/, '').trim();
    if (!line) return;
    const table = line.match(/^\[pins\.([a-z_]+)\]$/);
    if (table) {
      current = pins[table[1]] = {};
      return;
    }
    if (line.startsWith('[')) {
      current = null;
      return;
    }
    const kv = line.match(/^([a-z_]+)\s*=\s*(?:"([^"]*)"|(\d+))$/);
    if (!kv) throw new Error(`${file}:${i + 1}: cannot parse \`${raw}\``);
    if (current) current[kv[1]] = kv[2] !== undefined ? kv[2] : Number(kv[3]);
  });
  for (const [name, p] of Object.entries(pins)) {
    if (typeof p.gpio !== 'number') throw new Error(`${file}: pin \`${name}\` has no gpio`);
    p.activeHigh = p.active === 'high';
  }
  return pins;
}

function loadPinmap(file = DEFAULT_PATH) {
  return parsePinmap(fs.readFileSync(file, 'utf8'), file);
}

module.exports = { loadPinmap, parsePinmap, DEFAULT_PATH };
