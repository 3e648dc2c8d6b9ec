'use strict';
// The pin map has one source (hardware/pinmap.toml); the firmware's build script generates its
// pin constants from it and refuses to build when the human-readable copies disagree. This test
// checks the same agreement from outside the firmware build, and that the harness drives the
// pins the firmware uses.
const test = require('node:test');
const assert = require('node:assert/strict');
const fs = require('fs');
const path = require('path');
const { loadPinmap } = require('../lib/pinmap');

const repo = path.join(__dirname, '..', '..', '..');

/** `| name | GPn |` rows of a Markdown table (or a `//!` doc table). */
function tableRows(text) {
  const rows = {};
  for (let line of text.split('\n')) {
    line = line.replace(/^\s*\/\/!/, '').trim();
    if (!line.startsWith('|')) continue;
    const cells = line.split('|').map((c) => c.trim().replace(/`/g, ''));
    const m = cells[2] && cells[2].match(/^GP(\d+)$/);
    if (m) rows[cells[1]] = Number(m[1]);
  }
  return rows;
}

test('pinmap.toml, wiring.md and the firmware header agree', () => {
  const pins = loadPinmap();
  const expected = Object.fromEntries(Object.entries(pins).map(([k, v]) => [k, v.gpio]));
  assert.equal(Object.keys(expected).length, 7);
  for (const file of ['hardware/wiring.md', 'firmware/rp2040/src/main.rs']) {
    assert.deepEqual(tableRows(fs.readFileSync(path.join(repo, file), 'utf8')), expected, file);
  }
});

test('pin map is valid: distinct GPIOs, inputs pulled, outputs not', () => {
  const pins = loadPinmap();
  const gpios = Object.values(pins).map((p) => p.gpio);
  assert.equal(new Set(gpios).size, gpios.length);
  for (const [name, p] of Object.entries(pins)) {
    assert.ok(p.gpio >= 0 && p.gpio <= 29, `${name}: GP${p.gpio}`);
    assert.ok(['high', 'low'].includes(p.active), `${name}: active`);
    if (p.direction === 'input') assert.ok(['up', 'down', 'none'].includes(p.pull), `${name}: pull`);
    else assert.equal(p.pull, undefined, `${name}: outputs have no pull`);
  }
});
