// Unit tests of the console's own logic (console/tiles.js, the feed parser of console/api.js),
// run by `node --test` with no browser.

import assert from 'node:assert/strict';
import { test } from 'node:test';
import { parseEvent, revisionOf } from '../../console/api.js';
import {
  affects,
  angles,
  channelColour,
  direction,
  inRect,
  nearest,
  parseCorrespondences,
  pinchRatio,
  pullEdits,
  rate,
  span,
  wrap,
} from '../../console/tiles.js';

// A 5×3 screen over a 1000×500 image whose directions are linear in the pixel:
// phi = 0.1°·(x − 500), theta = −0.1°·(y − 250).
function linearScreen() {
  const features = [];
  for (let r = 0; r < 3; r++) {
    for (let c = 0; c < 5; c++) {
      const [x, y] = [c / 4, r / 2];
      features.push({ x, y, phi: 0.1 * (x * 1000 - 500), theta: -0.1 * (y * 500 - 250), scale: 1, f: 1 });
    }
  }
  return { layout: { columns: 5, features } };
}

test('a drag pulls the content: the feature shows what was d pixels back', () => {
  const t = linearScreen();
  const [e] = pullEdits(t, [{ column: 2, row: 1 }], 30, -20, 1000, 500);
  // Centre feature: phi 0, theta 0; what was at (470, 270): phi −3, theta −2.
  assert.deepEqual(e, { op: 'set_feature', column: 2, row: 1, phi: -3, theta: -2 });
});

test('rates are one-sided at the edge and skip invalid neighbours', () => {
  const t = linearScreen();
  const j = rate(t, 0, 0, 1000, 500);
  assert.ok(Math.abs(j[0][0] - 0.1) < 1e-12 && Math.abs(j[1][1] + 0.1) < 1e-12);
  t.layout.features[1].valid = false; // (1, 0)
  const k = rate(t, 0, 0, 1000, 500);
  assert.equal(k, null, 'no usable neighbour along the row: no rate');
  assert.deepEqual(pullEdits(t, [{ column: 0, row: 0 }], 1, 0, 1000, 500), []);
  assert.deepEqual(pullEdits(t, [{ column: 1, row: 0 }], 1, 0, 1000, 500), [], 'invalid features are not edited');
});

test('phi differences wrap across ±180°', () => {
  assert.equal(wrap(190), -170);
  assert.equal(wrap(-180), 180);
  const t = linearScreen();
  for (const f of t.layout.features) f.phi = wrap(f.phi + 179.9);
  const j = rate(t, 2, 1, 1000, 500);
  assert.ok(Math.abs(j[0][0] - 0.1) < 1e-9, `${j[0][0]}`);
});

test('picking: nearest within reach, rectangles, spans', () => {
  const t = linearScreen();
  assert.deepEqual(nearest(t, 505, 245, 1000, 500, 10), { column: 2, row: 1 });
  assert.equal(nearest(t, 380, 125, 1000, 500, 10), null);
  const picks = inRect(t, [600, 600], [240, -10], 1000, 500);
  assert.deepEqual(span(picks), { columns: [1, 2], rows: [0, 2] });
  assert.equal(span([]), null);
});

test('correspondences from CSV with a header, and refused lines named', () => {
  const doc = parseCorrespondences('px,py,x,y,z\n# a comment\n1,2,3,4,5\n6;7;8;9;10\n', 'p.csv', [1920, 1080]);
  assert.deepEqual(doc, {
    points: [
      { pixel: [1, 2], world: [3, 4, 5] },
      { pixel: [6, 7], world: [8, 9, 10] },
    ],
    resolution: [1920, 1080],
  });
  assert.throws(() => parseCorrespondences('1,2,3,4,5\n1,2,x,4,5\n', 'p.csv'), /line 2/);
  assert.throws(() => parseCorrespondences('1,2,3,4\n', 'p.csv'), /five numbers, got 4/);
  assert.throws(() => parseCorrespondences('{"pts": []}', 'p.json'), /no "points"/);
  assert.equal(parseCorrespondences('{"points": [], "model": "auto"}', 'p.json').model, 'auto');
});

test('the feed: events parsed, comments skipped, changes routed to their channel', () => {
  assert.deepEqual(parseEvent('event: change\ndata: {"kind":"tiles","channel":"c","revision":3}'), {
    name: 'change',
    data: { kind: 'tiles', channel: 'c', revision: 3 },
  });
  assert.equal(parseEvent(':keep-alive'), null);
  assert.equal(parseEvent('event: change\ndata: {broken'), null);
  assert.ok(affects({ kind: 'tiles', channel: 'c' }, 'c'));
  assert.ok(!affects({ kind: 'tiles', channel: 'd' }, 'c'));
  assert.ok(affects({ kind: 'rig', revision: 2 }, 'c'));
  assert.ok(!affects({ kind: 'proposal', channel: 'c', id: 1 }, 'c'));
  assert.equal(revisionOf('"12"'), 12);
  assert.equal(revisionOf('W/"4"'), 4);
  assert.equal(revisionOf('"abc-1.2"'), null);
});

test('channel colours match the daemon ids card and differ between neighbours', () => {
  // src/content/testcard.rs, channel_colour(0) and (1).
  assert.equal(channelColour(0), 'rgb(200, 40, 40)');
  assert.notEqual(channelColour(1), channelColour(2));
});

test('a pinch: the ratio of the fingers\' distances, only with two fingers down', () => {
  const two = new Map([
    [1, [0, 0]],
    [2, [100, 0]],
  ]);
  assert.equal(pinchRatio(two, 1, -50, 0), 1.5);
  assert.equal(pinchRatio(new Map([[1, [0, 0]]]), 1, 5, 5), null);
  assert.equal(pinchRatio(two, 3, 0, 0), null, 'a pointer not down');
});

test('directions and their azimuth and elevation, as the daemon frames them', () => {
  const close = (a, b) => a.every((v, k) => Math.abs(v - b[k]) < 1e-12);
  assert.ok(close(direction(0, 0), [0, 0, -1]), 'ahead is −z');
  assert.ok(close(direction(90, 0), [1, 0, 0]), 'right is +x');
  assert.ok(close(direction(0, 90), [0, 1, 0]));
  for (const [az, el] of [[-135, 20], [170, -45], [30, 80]]) {
    assert.ok(close(angles(direction(az, el)), [az, el]), `${az}, ${el}`);
  }
  assert.ok(close(angles([0.2, 0, -0.2]), [45, 0]), 'any length');
  assert.equal(angles([0, 0, 0]), null);
});
