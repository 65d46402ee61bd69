// The console end to end: Debian's Chromium, driven by playwright-core, against the real daemon
// on port 0 with a fresh data directory. Each step leaves a screenshot of every page under
// target/console-e2e/ when it fails. Run by scripts/console-test (which installs Chromium and
// playwright-core); OMNIWARP_BIN names the binary (default target/release/omniwarp).

import assert from 'node:assert/strict';
import { spawn, execFileSync } from 'node:child_process';
import { mkdtempSync, mkdirSync, readFileSync, writeFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { after, before, test } from 'node:test';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const root = resolve(dirname(fileURLToPath(import.meta.url)), '../..');
const bin = process.env.OMNIWARP_BIN || join(root, 'target/release/omniwarp');
const shots = join(root, 'target/console-e2e');
const chromiumPath = process.env.CHROMIUM || '/usr/bin/chromium';
// What a headless Chromium needs on a machine with no GPU and a closed network.
const chromiumArgs = [
  '--no-sandbox',
  '--disable-gpu',
  '--disable-quic',
  '--no-first-run',
  '--disable-background-networking',
  '--disable-component-update',
  '--disable-sync',
];

// Starts the daemon (on port 0 unless told) and resolves with its base address once it listens.
function daemon(args, bind = '127.0.0.1:0') {
  const child = spawn(bin, ['serve', '--bind', bind, ...args], { stdio: ['ignore', 'pipe', 'pipe'] });
  let log = '';
  child.stderr.on('data', (d) => (log += d));
  const base = new Promise((ok, fail) => {
    let out = '';
    child.stdout.on('data', (d) => {
      out += d;
      const m = /listening on (http:\/\/[\d.:]+)/.exec(out);
      if (m) ok(m[1]);
    });
    child.on('exit', (code) => fail(new Error(`the daemon exited (${code}): ${log}`)));
  });
  return { child, base };
}

let work, data, server, base, browser, a, b;
const pages = [];

async function open(context) {
  const page = await context.newPage();
  page.on('pageerror', (e) => console.error(`page error: ${e.message}`));
  pages.push(page);
  await page.goto(`${base}/`);
  await page.waitForSelector('#channels li >> nth=2');
  await page.waitForFunction(() => document.querySelector('#feed-state').textContent === 'live');
  return page;
}

// A step of the scenario: on failure, a screenshot of every page open, named after the step.
async function step(name, fn) {
  try {
    await fn();
  } catch (e) {
    mkdirSync(shots, { recursive: true });
    await Promise.all(
      pages.map((p, k) => p.screenshot({ path: join(shots, `${name}-${k}.png`), fullPage: true }).catch(() => {})),
    );
    throw e;
  }
}

async function api(path, init) {
  const resp = await fetch(`${base}${path}`, init);
  assert.ok(resp.ok, `${path}: ${resp.status} ${await resp.clone().text()}`);
  return resp.json();
}

async function feature(channel, column, row, revision) {
  const q = revision ? `?revision=${revision}` : '';
  const { tiles } = await api(`/v1/channels/${channel}/tiles${q}`);
  return tiles.layout.features[row * tiles.layout.columns + column];
}

function revisionOnDisk(resource) {
  const script = 'import sqlite3,sys;c=sqlite3.connect(sys.argv[1]);print(c.execute("select revision from resources where name=?",(sys.argv[2],)).fetchone()[0])';
  return Number(execFileSync('python3', ['-c', script, join(data, 'omniwarp.db'), resource]).toString().trim());
}

async function handle(page, column, row) {
  const box = await page.locator(`#overlay circle[data-column="${column}"][data-row="${row}"]`).boundingBox();
  assert.ok(box, `feature ${column}, ${row} has a handle`);
  return [box.x + box.width / 2, box.y + box.height / 2];
}

async function drag(page, column, row, dx, dy) {
  const [x, y] = await handle(page, column, row);
  await page.mouse.move(x, y);
  await page.mouse.down();
  await page.mouse.move(x + dx / 2, y + dy / 2, { steps: 4 });
  await page.mouse.move(x + dx, y + dy, { steps: 4 });
  await page.mouse.up();
}

// Waits for a console to show tile revision n: a client's own edit may queue for a worker, so
// it gets 10 s; another client's edit must arrive over the feed and be read back within 2 s of
// the editing console showing it (on this 2-core machine, with Chromium and the daemon's
// renders sharing the cores; about 0.1 s when idle).
const tilesRevision = (page, n, timeout = 10000) =>
  page.waitForFunction((n) => document.querySelector('#tiles-revision').textContent.startsWith(`tiles revision ${n}`), n, { timeout });
const seen = (page, n) => tilesRevision(page, n, 2000);

async function selectChannel(page, id) {
  await page.click(`#channels li[data-channel="${id}"] button`);
  await page.waitForFunction((id) => document.querySelector('#channel-title').textContent === id, id);
  await page.waitForSelector('#overlay circle');
}

before(async () => {
  work = mkdtempSync(join(tmpdir(), 'omniwarp-console-'));
  data = join(work, 'data');
  server = daemon(['--demo', '--data', data]);
  base = await server.base;
  browser = await chromium.launch({ executablePath: chromiumPath, args: chromiumArgs });
  a = await browser.newContext({ viewport: { width: 1280, height: 900 }, acceptDownloads: true });
  b = await browser.newContext({ viewport: { width: 1280, height: 900 } });
});

after(async () => {
  if (browser) await browser.close();
  if (server) server.child.kill();
  rmSync(work, { recursive: true, force: true });
});

let pageA, pageB;

test('the console loads: channels, the rig in 3D, the feed live, a preview', async () => {
  await step('load', async () => {
    pageA = await open(a);
    assert.equal(await pageA.locator('#channels li').count(), 3);
    await pageA.waitForSelector('#preview[data-etag]');
    await pageA.click('[data-tab=overview]');
    // The rig view drew something besides its background.
    const drawn = await pageA.evaluate(() => {
      const c = document.querySelector('#rig3d');
      const px = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
      let lit = 0;
      for (let k = 0; k < px.length; k += 4) if (px[k] + px[k + 1] + px[k + 2] > 150) lit++;
      return lit;
    });
    assert.ok(drawn > 500, `${drawn} pixels of the rig drawn`);
    // The projectors hang side by side: their names are placed apart, not over each other.
    const labels = await pageA.evaluate(() => window.omniwarp.rig.labels);
    assert.deepEqual(labels.map((l) => l.text).sort(), ['centre', 'left', 'right']);
    for (const [k, p] of labels.entries()) {
      for (const q of labels.slice(k + 1)) {
        const apart = p.x + p.w <= q.x || q.x + q.w <= p.x || p.y + p.h <= q.y || q.y + q.h <= p.y;
        assert.ok(apart, `labels ${p.text} and ${q.text} overlap: ${JSON.stringify(labels)}`);
      }
    }
    // The plan beneath it: the figures and the picture of the current rig revision.
    await pageA.waitForSelector('#plan[data-revision]');
    assert.match(await pageA.textContent('#plan-summary'), /lit by no projector .* overlap/);
    const width = await pageA.evaluate(() => document.querySelector('#plan').naturalWidth);
    assert.equal(width, 900);
    await pageA.click('[data-tab=channel]');
  });
});

test('dragging a feature changes the preview and the tile revision on disk', async () => {
  await step('drag', async () => {
    await selectChannel(pageA, 'centre');
    await pageA.waitForSelector('#preview[data-etag]');
    const etag = await pageA.getAttribute('#preview', 'data-etag');
    const beforeShot = await pageA.locator('#preview').screenshot();
    const was = await feature('centre', 16, 9);
    await drag(pageA, 16, 9, 15, 0);
    await tilesRevision(pageA, 2);
    await pageA.waitForFunction((e) => document.querySelector('#preview').dataset.etag !== e, etag);
    const afterShot = await pageA.locator('#preview').screenshot();
    assert.notEqual(Buffer.compare(beforeShot, afterShot), 0, 'the preview changed');
    const now = await feature('centre', 16, 9);
    // Dragged right: the feature now shows what was to its left.
    assert.ok(now.phi < was.phi - 0.5, `phi ${was.phi} → ${now.phi}`);
    assert.equal(revisionOnDisk('channels/centre/tiles'), 2);
  });
});

test('two technicians: a conflict is shown and resolved, no acknowledged edit lost', async () => {
  await step('conflict', async () => {
    pageB = await open(b);
    // B shows left (tiles revision 1) first. Until centre's own tiles and preview arrive,
    // nothing of left may stay under centre's title: a press on a stale handle would edit
    // centre with left's features and revision. Centre's requests are held back to look.
    let release;
    const held = new Promise((r) => (release = r));
    await pageB.route('**/v1/channels/centre/**', async (route) => {
      await held;
      await route.continue();
    });
    await pageB.click('#channels li[data-channel="centre"] button');
    await pageB.waitForFunction(() => document.querySelector('#channel-title').textContent === 'centre');
    assert.equal(await pageB.locator('#overlay circle').count(), 0, "no handles before centre's tiles");
    assert.equal(await pageB.textContent('#tiles-revision'), 'loading the tiles…');
    assert.equal(await pageB.getAttribute('#preview', 'data-etag'), null, "left's preview is not shown as centre's");
    release();
    await pageB.unrouteAll({ behavior: 'wait' });
    await selectChannel(pageB, 'centre');
    await tilesRevision(pageB, 2);
    // B types into the feature's form at revision 2 …
    await pageB.click(`#overlay circle[data-column="16"][data-row="9"]`);
    await pageB.waitForSelector('#feature-form:not([hidden])');
    await pageB.fill('#feature-form input[name=phi]', '-3.5');
    // … A moves the same feature (revision 3), and B sees it within a second.
    await drag(pageA, 16, 9, 0, 12);
    await tilesRevision(pageA, 3);
    await seen(pageB, 3);
    const fromA = await feature('centre', 16, 9, 3);
    assert.match(await pageB.textContent('#feature-base'), /typed against revision 2; revision 3 is newer/);
    await pageB.click('#feature-form button[type=submit]');
    await pageB.waitForSelector('#conflict:not([hidden])');
    assert.match(await pageB.textContent('#conflict-text'), /revision 3 while you edited revision 2/);
    // Both changed the same feature: the daemon refuses to merge, and says so.
    await pageB.click('#conflict-merge');
    await pageB.waitForFunction(() => /could not merge/.test(document.querySelector('#conflict-text').textContent));
    await pageB.click('#conflict-reapply');
    await tilesRevision(pageB, 4);
    await seen(pageA, 4);
    assert.equal((await feature('centre', 16, 9, 4)).phi, -3.5);
    assert.deepEqual(await feature('centre', 16, 9, 3), fromA, "A's revision is kept in the history");

    // Edits of different features merge: B at revision 4, A's edit of another feature first.
    await pageB.click(`#overlay circle[data-column="8"][data-row="6"]`);
    await pageB.fill('#feature-form input[name=theta]', '19.5');
    await drag(pageA, 20, 12, -10, 0);
    await tilesRevision(pageA, 5);
    await seen(pageB, 5);
    const movedByA = await feature('centre', 20, 12, 5);
    await pageB.click('#feature-form button[type=submit]');
    await pageB.waitForSelector('#conflict-merge:not([hidden])');
    await pageB.click('#conflict-merge');
    await tilesRevision(pageB, 6);
    assert.equal((await feature('centre', 8, 6)).theta, 19.5);
    assert.deepEqual(await feature('centre', 20, 12), movedByA, "A's edit survives the merge");
  });
});

test('undo and redo through the history routes', async () => {
  await step('undo', async () => {
    const five = await feature('centre', 8, 6, 5);
    const six = await feature('centre', 8, 6, 6);
    await tilesRevision(pageA, 6);
    await pageA.click('#tiles-undo');
    await tilesRevision(pageA, 7);
    assert.deepEqual(await feature('centre', 8, 6), five);
    await pageA.click('#tiles-redo');
    await tilesRevision(pageA, 8);
    assert.deepEqual(await feature('centre', 8, 6), six);
    await pageA.waitForFunction(() => /redo channels\/centre\/tiles → 8/.test(document.querySelector('#history').textContent));
  });
});

test('a region picked by rectangle moves as one; rapid keyboard nudges queue, not conflict; a revert from the history', async () => {
  await step('region', async () => {
    const [x0, y0] = await handle(pageA, 10, 8);
    const [x1, y1] = await handle(pageA, 12, 10);
    // The Region button (a touch screen's Shift): the rectangle replaces the picks …
    await pageA.click('#band-mode');
    await pageA.mouse.move(x0 - 4, y0 - 4);
    await pageA.mouse.down();
    await pageA.mouse.move(x1 + 4, y1 + 4, { steps: 4 });
    await pageA.mouse.up();
    assert.equal(await pageA.locator('#overlay circle.picked').count(), 9);
    // … and Shift-drag adds to them.
    const [x2, y2] = await handle(pageA, 14, 8);
    await pageA.keyboard.down('Shift');
    await pageA.mouse.move(x2 - 4, y2 - 4);
    await pageA.mouse.down();
    await pageA.mouse.move(x2 + 4, y2 + 4, { steps: 2 });
    await pageA.mouse.up();
    await pageA.keyboard.up('Shift');
    assert.equal(await pageA.locator('#overlay circle.picked').count(), 10);
    const eight = await api('/v1/channels/centre/tiles?revision=8');
    for (let k = 0; k < 3; k++) await pageA.keyboard.press('ArrowLeft');
    await tilesRevision(pageA, 11);
    assert.ok(await pageA.locator('#conflict').isHidden(), 'no conflict with its own nudges');
    const nine = await api('/v1/channels/centre/tiles?revision=9');
    const changed = eight.tiles.layout.features.filter((f, k) => f.phi !== nine.tiles.layout.features[k].phi);
    assert.equal(changed.length, 10, 'the first nudge moved the ten picked features');
    // Any revision in the history but the current one can be made current again, on a second
    // press: the first only asks.
    await pageA.waitForFunction(() => /channels\/centre\/tiles → 11/.test(document.querySelector('#history').textContent));
    const newest = pageA.locator('#history li', { hasText: 'channels/centre/tiles → 11' }).first();
    assert.equal(await newest.locator('button.revert').count(), 0, 'no revert on the current revision');
    assert.equal(await newest.locator('.current').count(), 1);
    const revert = '#history button.revert[data-resource="channels/centre/tiles"][data-revision="2"]';
    await pageA.click(revert);
    assert.match(await pageA.textContent(revert), /press again/);
    await pageA.waitForTimeout(500);
    assert.equal((await api('/v1/channels/centre/tiles')).revision, 11, 'one press reverts nothing');
    await pageA.click(revert);
    await tilesRevision(pageA, 12);
    const two = await api('/v1/channels/centre/tiles?revision=2');
    assert.deepEqual((await api('/v1/channels/centre/tiles')).tiles.layout, two.tiles.layout);
  });
});

test('a nudge queued behind a write is not sent to the channel opened meanwhile', async () => {
  await step('queued', async () => {
    const left = (await api('/v1/channels/left/tiles')).revision;
    const centre = (await api('/v1/channels/centre/tiles')).revision;
    // Centre's first nudge is held on its way to the daemon; the second queues behind it; then
    // left is opened. The second was worked out from centre's tiles: it must not go to left.
    let release;
    const held = new Promise((r) => (release = r));
    await pageA.route('**/v1/channels/centre/tiles', async (route) => {
      if (route.request().method() === 'PATCH') await held;
      await route.continue();
    });
    const [x, y] = await handle(pageA, 16, 9);
    await pageA.mouse.click(x, y);
    await pageA.keyboard.press('ArrowRight');
    await pageA.keyboard.press('ArrowRight');
    await selectChannel(pageA, 'left');
    release();
    await pageA.waitForFunction(() => /an edit of centre was not sent/.test(document.querySelector('#notice').textContent), null, {
      timeout: 10000,
    });
    await pageA.unrouteAll({ behavior: 'wait' });
    assert.equal((await api('/v1/channels/left/tiles')).revision, left, 'left untouched');
    const now = await api('/v1/channels/centre/tiles');
    assert.equal(now.revision, centre + 1, `the nudge sent went to centre: ${centre} → ${now.revision}; ${await pageA.textContent('#notice')}`);
    await selectChannel(pageA, 'centre');
  });
});

test('a test card sent to a channel is what it puts out, seen by every console', async () => {
  await step('pattern', async () => {
    await pageA.click('[data-show=grid]');
    await pageA.waitForSelector('#output[data-show=grid]');
    assert.equal((await api('/v1/channels/centre/show')).show, 'grid');
    await pageB.waitForFunction(() => document.querySelector('#showing').textContent === 'grid', null, { timeout: 2000 });
    const png = await (await fetch(`${base}/v1/channels/centre/output.png?scale=8`)).arrayBuffer();
    assert.equal(Buffer.from(png).subarray(1, 4).toString(), 'PNG');
  });
});

test('a render node that reports is listed, and its error shown', async () => {
  await step('nodes', async () => {
    const report = { outputs: [{ channel: 'left', showing: '"x"', frames: 1 }], fps: 1, error: 'cannot reach the daemon' };
    const put = await fetch(`${base}/v1/nodes/wall-7`, {
      method: 'PUT',
      headers: { 'Content-Type': 'application/json' },
      body: JSON.stringify(report),
    });
    assert.equal(put.status, 204);
    await pageA.waitForFunction(() => /wall-7: left/.test(document.querySelector('#nodes').textContent), null, { timeout: 2000 });
    assert.match(await pageA.textContent('#nodes [data-node=wall-7]'), /cannot reach the daemon/);
  });
});

test('calibration from an uploaded CSV: residuals per point, applied to the rig', async () => {
  await step('calibration', async () => {
    const doc = JSON.parse(readFileSync(join(root, 'calibration/examples/points.json'), 'utf8'));
    const csv = ['pixel_x,pixel_y,x,y,z', ...doc.points.map((p) => [...p.pixel, ...p.world].join(','))].join('\n');
    const file = join(work, 'points.csv');
    writeFileSync(file, csv);
    await selectChannel(pageA, 'left');
    await pageA.click('[data-tab=calibration]');
    await pageA.setInputFiles('#calib-file', file);
    await pageA.click('#calib-form button[type=submit]');
    await pageA.waitForSelector('#calib-summary', { timeout: 60000 });
    const rows = await pageA.locator('#calib-residuals tr').count();
    assert.equal(rows - 1, doc.points.length);
    await pageA.click('#calib-apply');
    await pageA.waitForFunction(() => document.querySelector('#rig-revision').textContent === 'rig revision 2');
    assert.equal((await api('/v1/rig')).revision, 2);
  });
});

test('the MPCDI package downloads', async () => {
  await step('mpcdi', async () => {
    await pageA.click('[data-tab=exports]');
    const [download] = await Promise.all([
      pageA.waitForEvent('download', { timeout: 120000 }),
      pageA.click('#mpcdi-download'),
    ]);
    const zip = readFileSync(await download.path());
    assert.equal(zip.subarray(0, 2).toString(), 'PK');
    assert.ok(zip.includes('mpcdi.xml'), 'the package holds mpcdi.xml');
    assert.match(await pageA.textContent('#export-log'), /rig\.mpcdi — \d+ KiB/);
  });
});

// After the export: the canvas this leaves (O 45° up) puts the equirect's pole in the centre
// projector's view, which no 2d grid follows (the MPCDI export is then a 422 saying so).
test('the content canvas from its pads: turned, O set, projected from a point', async () => {
  await step('content', async () => {
    // A shows left. Centre's canvas is held back: until it arrives the form still holds left's,
    // and saving it must not write left's canvas to centre.
    let release;
    const held = new Promise((r) => (release = r));
    await pageA.route('**/v1/channels/centre/content', async (route) => {
      await held;
      await route.continue();
    });
    await pageA.click('[data-tab=channel]');
    await selectChannel(pageA, 'centre');
    await pageA.click('[data-tab=content]');
    assert.equal(await pageA.textContent('#content-revision'), 'loading the content…');
    await pageA.click('#content-form button[type=submit]');
    await pageA.waitForFunction(() => /the content of centre is still loading/.test(document.querySelector('#notice').textContent));
    release();
    await pageA.unrouteAll({ behavior: 'wait' });
    await pageA.waitForFunction(() => document.querySelector('#content-revision').textContent === 'content revision 1');
    assert.equal((await api('/v1/channels/centre/content')).revision, 1, 'nothing was saved to centre while it loaded');
    const pad = await pageA.locator('#aim-pad').boundingBox();
    // Three quarters across is azimuth +90°, the middle height the horizon.
    await pageA.mouse.click(pad.x + pad.width * 0.75, pad.y + pad.height / 2);
    await pageA.selectOption('#aim-target', 'offaxis');
    await pageA.mouse.click(pad.x + pad.width * 0.5, pad.y + pad.height * 0.25);
    const centre = await pageA.locator('#centre-pad').boundingBox();
    // Half a metre to the right of the eye (the pad shows the 2 m cylinder within 0.45 of its side).
    await pageA.mouse.click(centre.x + centre.width * (0.5 + (0.45 * 0.5) / 2), centre.y + centre.height / 2);
    await pageA.click('#content-form button[type=submit]');
    await pageA.waitForFunction(() => document.querySelector('#content-revision').textContent === 'content revision 2');
    const { content } = await api('/v1/channels/centre/content');
    const near = (a, b, tol) => a.every((v, k) => Math.abs(v - b[k]) < tol);
    assert.ok(near(content.look_to, [1, 0, 0], 0.01), `look_to ${content.look_to}`);
    // Azimuth 0, elevation +45°, O's default length 0.25.
    assert.ok(near(content.offaxis, [0, 0.177, -0.177], 0.01), `O ${content.offaxis}`);
    assert.ok(near(content.project_from, [0.5, 0, 0], 0.03), `from ${content.project_from}`);
    await pageA.click('[data-tab=channel]');
  });
});

test("one canvas for the show: saved for every channel, and a channel of its own given back", async () => {
  await step('show canvas', async () => {
    await pageA.click('[data-tab=content]');
    await pageA.waitForFunction(() => /own canvas/.test(document.querySelector('#content-source').textContent));
    await pageA.click('[data-tab=channel]');
    await selectChannel(pageA, 'right');
    await pageA.click('[data-tab=content]');
    await pageA.waitForFunction(() => /show's canvas/.test(document.querySelector('#content-source').textContent));
    assert.ok(await pageA.isHidden('#content-inherit'));
    const rig = (await api('/v1/rig')).revision;
    await pageA.fill('#content-form input[name=width]', '2048');
    await pageA.fill('#content-form input[name=height]', '1024');
    await pageA.click('#content-show');
    await pageA.waitForFunction(() => /the show's canvas, rig revision/.test(document.querySelector('#notice').textContent));
    assert.equal((await api('/v1/rig')).revision, rig + 1);
    // Every channel without its own plays it; centre keeps its own.
    const left = await api('/v1/channels/left/content');
    assert.deepEqual([left.own, left.content.size], [false, [2048, 1024]]);
    assert.equal((await api('/v1/channels/centre/content')).own, true);
    // Right made its own, then given back to the show.
    await pageA.fill('#content-form input[name=width]', '1024');
    await pageA.fill('#content-form input[name=height]', '512');
    await pageA.click('#content-form button[type=submit]');
    await pageA.waitForFunction(() => /own canvas/.test(document.querySelector('#content-source').textContent));
    assert.deepEqual((await api('/v1/channels/right/content')).content.size, [1024, 512]);
    await pageA.click('#content-inherit');
    await pageA.waitForFunction(() => /show's canvas/.test(document.querySelector('#content-source').textContent));
    const right = await api('/v1/channels/right/content');
    assert.deepEqual([right.own, right.content.size], [false, [2048, 1024]]);
    await pageA.click('[data-tab=channel]');
  });
});

// A console whose feed never connects, on centre: the answers to its own writes are all it has.
async function feedless() {
  const context = await browser.newContext({ viewport: { width: 1280, height: 900 } });
  await context.route('**/v1/events', (route) => route.abort());
  const page = await context.newPage();
  pages.push(page);
  await page.goto(`${base}/`);
  await page.waitForSelector('#channels li >> nth=2');
  await page.waitForFunction(() => document.querySelector('#feed-state').textContent === 'offline');
  await selectChannel(page, 'centre');
  await page.waitForSelector('#preview[data-etag]');
  const close = async () => {
    pages.splice(pages.indexOf(page), 1);
    await context.close();
  };
  return { page, close };
}

// The answer to a console's own write and the feed's notice of it arrive in either order on a
// busy machine; with the feed down entirely, the answer alone must bring the preview up to date.
test('with the feed down, a console still shows its own edits in its preview', async () => {
  const { page, close } = await feedless();
  try {
    await step('feedless', async () => {
      const tiles = (await api('/v1/channels/centre/tiles')).revision;
      let etag = await page.getAttribute('#preview', 'data-etag');
      await drag(page, 16, 9, 0, -12);
      await tilesRevision(page, tiles + 1);
      await page.waitForFunction((e) => document.querySelector('#preview').dataset.etag !== e, etag, { timeout: 10000 });
      // The preview follows the content canvas through its projection centre.
      etag = await page.getAttribute('#preview', 'data-etag');
      await page.click('[data-tab=content]');
      await page.waitForFunction(() => /^content revision \d+$/.test(document.querySelector('#content-revision').textContent));
      await page.fill('#content-form input[name=project_from]', '0.25, 0, 0');
      await page.click('#content-form button[type=submit]');
      await page.waitForFunction((e) => document.querySelector('#preview').dataset.etag !== e, etag, { timeout: 10000 });
    });
  } finally {
    await close();
  }
});

// Without the feed, the answer to a nudge is what starts its preview; the next nudge waits for
// that answer's tiles, not for the render.
test('a nudge does not wait for the preview of the one before it', async () => {
  const { page, close } = await feedless();
  let release;
  const held = new Promise((r) => (release = r));
  try {
    await step('unwaited', async () => {
      const n = (await api('/v1/channels/centre/tiles')).revision;
      await page.route((url) => url.pathname === '/v1/channels/centre/render', async (route) => {
        await held;
        await route.continue().catch(() => {});
      });
      const [x, y] = await handle(page, 16, 9);
      await page.mouse.click(x, y);
      await page.keyboard.press('ArrowRight');
      await tilesRevision(page, n + 1);
      await page.keyboard.press('ArrowRight');
      await tilesRevision(page, n + 2);
      assert.equal((await api('/v1/channels/centre/tiles')).revision, n + 2);
    });
  } finally {
    release();
    await close();
  }
});

// Issue 48, bug 1: the form once kept the numbers it was opened with while its revision moved
// on with this console's own drags, so Apply wrote the old numbers back over a drag.
test('the feature form follows a drag of its feature; typed numbers never overwrite one silently', async () => {
  await step('form', async () => {
    await selectChannel(pageA, 'centre');
    const n = (await api('/v1/channels/centre/tiles')).revision;
    await tilesRevision(pageA, n);
    const [x, y] = await handle(pageA, 10, 12);
    await pageA.mouse.click(x, y);
    await pageA.waitForSelector('#feature-form:not([hidden])');
    await drag(pageA, 10, 12, 0, -20);
    await tilesRevision(pageA, n + 1);
    const dragged = await feature('centre', 10, 12);
    await pageA.waitForFunction(
      (t) => Number(document.querySelector('#feature-form input[name=theta]').value) === t,
      dragged.theta,
    );
    assert.equal(await pageA.textContent('#feature-base'), `at revision ${n + 1}`);
    // Applied as shown, the drag stays.
    await pageA.click('#feature-form button[type=submit]');
    await tilesRevision(pageA, n + 2);
    assert.equal((await feature('centre', 10, 12)).theta, dragged.theta);
    // Typed, then dragged: the form keeps what was typed, and applying it is a conflict.
    await pageA.fill('#feature-form input[name=phi]', '1.25');
    await drag(pageA, 10, 12, 0, 10);
    await tilesRevision(pageA, n + 3);
    assert.equal(await pageA.inputValue('#feature-form input[name=phi]'), '1.25');
    await pageA.click('#feature-form button[type=submit]');
    await pageA.waitForSelector('#conflict:not([hidden])');
    assert.match(await pageA.textContent('#conflict-text'), new RegExp(`revision ${n + 3} while you edited revision ${n + 2}`));
    await pageA.click('#conflict-reload');
    assert.equal((await api('/v1/channels/centre/tiles')).revision, n + 3, 'nothing written over the drag');
  });
});

// Issue 48, bugs 2 and 3: after a restart (which puts every channel back on its content) the
// console still said "grid" and its next card met a 412; an edit made while the daemon was down
// said "Failed to fetch", and nothing said it was lost.
test('across a daemon restart: what each channel shows, and an edit made while it was away said not saved', async () => {
  const dir = join(work, 'restarted');
  let d = daemon(['--demo', '--data', dir]);
  const home = await d.base;
  const context = await browser.newContext({ viewport: { width: 1280, height: 900 } });
  const page = await context.newPage();
  pages.push(page);
  let refused = 0;
  page.on('response', (r) => {
    if (r.status() === 412) refused++;
  });
  try {
    await step('restart', async () => {
      await page.goto(`${home}/`);
      await page.waitForSelector('#channels li >> nth=2');
      await page.waitForFunction(() => document.querySelector('#feed-state').textContent === 'live');
      await page.waitForSelector('#overlay circle');
      await page.click('[data-show=grid]');
      await page.waitForFunction(() => document.querySelector('#showing').textContent === 'grid');
      d.child.kill();
      await page.waitForFunction(() => document.querySelector('#feed-state').textContent === 'offline');
      await drag(page, 16, 9, 12, 0);
      await page.waitForFunction(() => /not saved/.test(document.querySelector('#notice').textContent));
      assert.doesNotMatch(await page.textContent('#notice'), /Failed to fetch/);
      d = daemon(['--demo', '--data', dir], home.replace('http://', ''));
      await d.base;
      await page.waitForFunction(() => document.querySelector('#feed-state').textContent === 'live', null, { timeout: 10000 });
      await page.waitForFunction(() => document.querySelector('#showing').textContent === 'content', null, { timeout: 5000 });
      await page.waitForFunction(() => /back; an edit made while it was away was not saved/.test(document.querySelector('#notice').textContent));
      await page.waitForFunction(() => /shows content/.test(document.querySelector('#channels li[data-channel="left"] .status').textContent));
      assert.equal((await (await fetch(`${home}/v1/channels/left/tiles`)).json()).follows_geometry, true, 'the lost edit was not made');
      await page.click('[data-show=crosshatch]');
      await page.waitForFunction(() => document.querySelector('#showing').textContent === 'crosshatch');
      assert.equal(refused, 0, 'no card met a stale revision');
    });
  } finally {
    d.child.kill();
    pages.splice(pages.indexOf(page), 1);
    await context.close();
  }
});

test('a tablet with the token: asked for it, then a touch drag edits a channel', async () => {
  const tokenFile = join(work, 'token');
  writeFileSync(tokenFile, 'tablet-secret-123\n');
  const guarded = daemon(['--demo', '--token-file', tokenFile]);
  const guardedBase = await guarded.base;
  const tablet = await browser.newContext({ viewport: { width: 820, height: 1180 }, hasTouch: true, isMobile: true });
  const page = await tablet.newPage();
  pages.push(page);
  try {
    await step('tablet', async () => {
      await page.goto(`${guardedBase}/`);
      await page.waitForSelector('#token-dialog:not([hidden])');
      await page.fill('#token', 'tablet-secret-123');
      await page.click('#token-form button');
      await page.waitForSelector('#channels li >> nth=2');
      await page.waitForFunction(() => document.querySelector('#feed-state').textContent === 'live');
      await page.waitForSelector('#overlay circle');
      const box = await page.locator('#overlay circle[data-column="16"][data-row="9"]').boundingBox();
      const [x, y] = [box.x + box.width / 2, box.y + box.height / 2];
      const cdp = await tablet.newCDPSession(page);
      const touch = (type, px, py) =>
        cdp.send('Input.dispatchTouchEvent', { type, touchPoints: type === 'touchEnd' ? [] : [{ x: px, y: py }] });
      await touch('touchStart', x, y);
      for (let k = 1; k <= 5; k++) await touch('touchMove', x + 2 * k, y);
      await touch('touchEnd');
      await tilesRevision(page, 2);
      // Two fingers apart: the preview zooms.
      await touch('touchStart', x, y);
      await cdp.send('Input.dispatchTouchEvent', { type: 'touchStart', touchPoints: [{ x, y, id: 0 }, { x: x + 40, y, id: 1 }] });
      for (let k = 1; k <= 5; k++) {
        await cdp.send('Input.dispatchTouchEvent', { type: 'touchMove', touchPoints: [{ x: x - 10 * k, y, id: 0 }, { x: x + 40 + 10 * k, y, id: 1 }] });
      }
      await touch('touchEnd');
      const width = await page.evaluate(() => document.querySelector('#zoomer').style.width);
      assert.ok(Number.parseFloat(width) > 150, `zoomed to ${width}`);
      const resp = await fetch(`${guardedBase}/v1/channels/left/tiles`, {
        headers: { Authorization: 'Bearer tablet-secret-123' },
      });
      assert.equal(resp.headers.get('etag'), '"2"');
    });
  } finally {
    guarded.child.kill();
  }
});
