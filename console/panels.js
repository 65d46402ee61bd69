// The panels beside a channel's preview: its content canvas (fields and an aiming pad), the
// test cards it can be sent, calibration from uploaded correspondences, exports, the history
// and the render nodes. Each reads and writes through /v1 only.

import { ApiError } from './api.js';
import { angles, direction, parseCorrespondences, pinchRatio } from './tiles.js';

const $ = (sel) => document.querySelector(sel);

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  e.append(...children);
  return e;
}

const vec = (text) => text.split(/[ ,]+/).filter(Boolean).map(Number);
const fmt = (v) => (Array.isArray(v) ? v.map((x) => +x.toFixed(6)).join(', ') : '');

// The content canvas: projection, field of view, orientation, off-axis vector, zoom, size and
// the point a panorama is projected from, as fields and on two pads. The aiming pad maps
// azimuth across and elevation up: dragging it turns the content (look_to), or, with "off-axis O"
// chosen, turns O keeping its length; the wheel or a pinch zooms (or, for O, changes its length,
// below 1). The centre pad is the wall seen from above with the eye: a press puts the point a
// panorama is projected from there (at the height in the field, else the eye's).
const O_DEFAULT = 0.25;
const O_MAX = 0.95;

export class ContentPanel {
  constructor(app) {
    this.app = app;
    this.revision = null;
    this.canvas = null;
    this.form = $('#content-form');
    this.form.addEventListener('submit', (e) => {
      e.preventDefault();
      this.save();
    });
    $('#content-show').addEventListener('click', () => this.saveShow());
    $('#content-inherit').addEventListener('click', () => this.inherit());
    $('#content-undo').addEventListener('click', () => this.history('undo'));
    $('#content-redo').addEventListener('click', () => this.history('redo'));
    $('#centre-clear').addEventListener('click', () => {
      this.form.elements.project_from.value = '';
      this.drawCentre();
    });
    this.form.addEventListener('input', () => this.drawPads());
    const pad = $('#aim-pad');
    this.pad = pad;
    this.pointers = new Map();
    pad.addEventListener('pointerdown', (e) => {
      pad.setPointerCapture(e.pointerId);
      this.pointers.set(e.pointerId, [e.clientX, e.clientY]);
      if (this.pointers.size === 1) this.aim(e);
    });
    pad.addEventListener('pointermove', (e) => {
      const last = this.pointers.get(e.pointerId);
      if (!last) return;
      const spread = pinchRatio(this.pointers, e.pointerId, e.clientX, e.clientY);
      if (spread) this.scale(spread);
      else if (this.pointers.size === 1) this.aim(e);
      this.pointers.set(e.pointerId, [e.clientX, e.clientY]);
    });
    const up = (e) => this.pointers.delete(e.pointerId);
    pad.addEventListener('pointerup', up);
    pad.addEventListener('pointercancel', up);
    pad.addEventListener(
      'wheel',
      (e) => {
        e.preventDefault();
        this.scale(Math.exp(-e.deltaY * 0.001));
      },
      { passive: false },
    );
    const centre = $('#centre-pad');
    centre.addEventListener('pointerdown', (e) => {
      centre.setPointerCapture(e.pointerId);
      this.place(e);
    });
    centre.addEventListener('pointermove', (e) => {
      if (centre.hasPointerCapture(e.pointerId)) this.place(e);
    });
  }

  target() {
    return $('#aim-target').value;
  }

  // The zoom, or the length of O, by a factor.
  scale(factor) {
    const f = this.form.elements;
    if (this.target() === 'offaxis') {
      const o = vec(f.offaxis.value);
      const n = Math.hypot(...o);
      if (o.length !== 3 || !(n > 0)) return;
      const length = Math.min(O_MAX, n * factor);
      f.offaxis.value = fmt(o.map((v) => (v * length) / n));
    } else {
      f.zoom.value = +Math.min(1000, Math.max(0.001, Number(f.zoom.value || 1) * factor)).toFixed(4);
    }
    this.drawPad();
  }

  aim(e) {
    const box = this.pad.getBoundingClientRect();
    const az = ((e.clientX - box.left) / box.width) * 360 - 180;
    const el = 90 - ((e.clientY - box.top) / box.height) * 180;
    const d = direction(az, el);
    const f = this.form.elements;
    if (this.target() === 'offaxis') {
      const n = Math.hypot(...vec(f.offaxis.value)) || O_DEFAULT;
      f.offaxis.value = fmt(d.map((v) => v * Math.min(n, O_MAX)));
    } else {
      f.look_to.value = fmt(d);
    }
    this.drawPad();
  }

  drawPads() {
    this.drawPad();
    this.drawCentre();
  }

  drawPad() {
    const c = this.pad;
    const ctx = c.getContext('2d');
    const [w, h] = [c.width, c.height];
    ctx.fillStyle = '#1b2027';
    ctx.fillRect(0, 0, w, h);
    ctx.strokeStyle = '#39424d';
    for (let k = 1; k < 8; k++) {
      ctx.beginPath();
      ctx.moveTo((k * w) / 8, 0);
      ctx.lineTo((k * w) / 8, h);
      ctx.stroke();
    }
    for (let k = 1; k < 4; k++) {
      ctx.beginPath();
      ctx.moveTo(0, (k * h) / 4);
      ctx.lineTo(w, (k * h) / 4);
      ctx.stroke();
    }
    const at = (v) => {
      const a = angles(v);
      return a && [((a[0] + 180) / 360) * w, ((90 - a[1]) / 180) * h];
    };
    const f = this.form.elements;
    const o = vec(f.offaxis.value);
    const op = o.length === 3 && at(o);
    if (op) {
      // O: a ring as large as its length.
      ctx.strokeStyle = '#4ad3ff';
      ctx.lineWidth = 2;
      ctx.beginPath();
      ctx.arc(op[0], op[1], 4 + 30 * Math.hypot(...o), 0, 2 * Math.PI);
      ctx.stroke();
    }
    const d = vec(f.look_to.value);
    const p = d.length === 3 && at(d);
    if (p) {
      ctx.fillStyle = '#ffd24a';
      ctx.beginPath();
      ctx.arc(p[0], p[1], 6, 0, 2 * Math.PI);
      ctx.fill();
    }
  }

  // The centre pad's frame: the wall's extent from above, x across, z down (ahead is up).
  centreFrame() {
    const c = $('#centre-pad');
    const g = this.app.rig.geometry;
    const points = g ? g.wall.flat() : [];
    const eye = g ? g.eye : [0, 0, 0];
    let reach = 1;
    for (const p of points) reach = Math.max(reach, Math.abs(p[0] - eye[0]), Math.abs(p[2] - eye[2]));
    const s = (0.45 * Math.min(c.width, c.height)) / reach;
    return {
      eye,
      to: (p) => [c.width / 2 + (p[0] - eye[0]) * s, c.height / 2 + (p[2] - eye[2]) * s],
      from: (x, y) => [eye[0] + (x - c.width / 2) / s, eye[2] + (y - c.height / 2) / s],
    };
  }

  place(e) {
    const c = $('#centre-pad');
    const box = c.getBoundingClientRect();
    const { eye, from } = this.centreFrame();
    const [x, z] = from(((e.clientX - box.left) / box.width) * c.width, ((e.clientY - box.top) / box.height) * c.height);
    const old = vec(this.form.elements.project_from.value);
    const y = old.length === 3 ? old[1] : eye[1];
    this.form.elements.project_from.value = fmt([x, y, z]);
    this.drawCentre();
  }

  drawCentre() {
    const c = $('#centre-pad');
    const ctx = c.getContext('2d');
    ctx.fillStyle = '#1b2027';
    ctx.fillRect(0, 0, c.width, c.height);
    const g = this.app.rig.geometry;
    if (!g) return;
    const { eye, to } = this.centreFrame();
    ctx.strokeStyle = 'rgba(170, 180, 190, 0.5)';
    for (const line of g.wall) {
      ctx.beginPath();
      line.forEach((p, k) => (k ? ctx.lineTo(...to(p)) : ctx.moveTo(...to(p))));
      ctx.stroke();
    }
    const [ex, ey] = to(eye);
    ctx.fillStyle = '#fff';
    ctx.beginPath();
    ctx.arc(ex, ey, 4, 0, 2 * Math.PI);
    ctx.fill();
    const from = vec(this.form.elements.project_from.value);
    if (from.length === 3) {
      const [x, y] = to(from);
      ctx.strokeStyle = '#ffd24a';
      ctx.lineWidth = 2;
      ctx.strokeRect(x - 6, y - 6, 12, 12);
      ctx.lineWidth = 1;
    }
  }

  async load(id) {
    this.id = id;
    // Until this channel's canvas arrives the form still holds the last one's: saved now, it
    // would be written to this channel.
    this.revision = null;
    $('#content-revision').textContent = 'loading the content…';
    const { body, revision } = await this.app.api.get(`/v1/channels/${id}/content`);
    if (id !== this.id) return;
    this.revision = revision;
    this.canvas = body.content;
    this.own = body.own;
    $('#content-source').textContent = body.own ? "(this channel's own canvas)" : "(the show's canvas)";
    $('#content-inherit').hidden = !body.own;
    const c = body.content;
    const f = this.form.elements;
    f.projection.value = c.projection;
    for (const k of ['hfov', 'vfov', 'fov']) f[k].value = c.params && c.params[k] !== undefined ? c.params[k] : '';
    f.look_to.value = fmt(c.look_to || [0, 0, -1]);
    f.look_up.value = fmt(c.look_up || [0, 1, 0]);
    f.offaxis.value = fmt(c.offaxis || [0, 0, 0]);
    f.zoom.value = c.zoom === undefined ? 1 : c.zoom;
    f.width.value = c.size[0];
    f.height.value = c.size[1];
    f.project_from.value = fmt(c.project_from || []);
    $('#content-revision').textContent = `content revision ${revision}`;
    this.app.rig.content = { look_to: c.look_to || [0, 0, -1], project_from: c.project_from };
    this.app.rig.draw();
    this.drawPads();
  }

  body() {
    const f = this.form.elements;
    const params = {};
    for (const k of ['hfov', 'vfov', 'fov']) if (f[k].value !== '') params[k] = Number(f[k].value);
    const canvas = {
      projection: f.projection.value,
      params,
      look_to: vec(f.look_to.value),
      look_up: vec(f.look_up.value),
      offaxis: vec(f.offaxis.value),
      zoom: Number(f.zoom.value),
      size: [Number(f.width.value), Number(f.height.value)],
    };
    const from = vec(f.project_from.value);
    if (from.length) canvas.project_from = from;
    return canvas;
  }

  // Whether this channel's canvas has arrived; says so when it has not.
  loaded() {
    if (this.revision !== null) return true;
    this.app.notify(`the content of ${this.id} is still loading`, 'warn');
    return false;
  }

  // A conflict's reapply sends the same canvas to the same channel, whatever is open by then.
  async save(base = this.revision, id = this.id, body = this.body()) {
    if (base === null && !this.loaded()) return;
    try {
      const r = await this.app.api.write('PUT', `/v1/channels/${id}/content`, body, base);
      this.app.notify(`content revision ${r.revision} of ${id}`);
      this.app.clearConflict();
      if (id === this.id) await Promise.all([this.load(id), this.app.view.changed('content', r.revision)]);
    } catch (e) {
      if (e instanceof ApiError && e.status === 412) {
        this.app.conflict({
          what: `the content of ${id}`,
          mine: body,
          base,
          current: e.current,
          reload: async () => {
            if (id === this.id) await this.load(id);
          },
          reapply: () => this.save(e.current, id, body),
        });
      } else {
        this.app.notify(this.app.describe(e), 'error');
      }
    }
  }

  // The show's canvas is the rig's `canvas`: a rig edit, which recomputes no warp.
  async saveShow(body = this.body()) {
    if (!this.loaded()) return;
    try {
      const { body: rig, revision } = await this.app.api.get('/v1/rig');
      const doc = rig.rig;
      doc.canvas = body;
      const r = await this.app.api.write('PUT', '/v1/rig', doc, revision);
      this.app.notify(`the show's canvas, rig revision ${r.revision}`);
      await this.load(this.id);
    } catch (e) {
      this.app.notify(this.app.describe(e), 'error');
    }
  }

  async inherit(id = this.id) {
    if (!this.loaded()) return;
    try {
      const r = await this.app.api.write('DELETE', `/v1/channels/${id}/content`, undefined, this.revision);
      this.app.notify(`${id} plays the show's canvas (content revision ${r.revision})`);
      if (id === this.id) await Promise.all([this.load(id), this.app.view.changed('content', r.revision)]);
    } catch (e) {
      this.app.notify(this.app.describe(e), 'error');
    }
  }

  async history(action) {
    if (!this.loaded()) return;
    const id = this.id;
    try {
      const r = await this.app.api.write('POST', `/v1/channels/${id}/content/${action}`, {}, this.revision);
      this.app.notify(`${action}: content revision ${r.revision} of ${id}`);
      if (id === this.id) await Promise.all([this.load(id), this.app.view.changed('content', r.revision)]);
    } catch (e) {
      this.app.notify(this.app.describe(e), 'error');
    }
  }
}

// Test cards: what the channel puts out (GET …/output.png) follows what is sent here.
export class PatternPanel {
  constructor(app) {
    this.app = app;
    this.revision = null;
    for (const b of document.querySelectorAll('[data-show]')) {
      b.addEventListener('click', () => this.send(b.dataset.show));
    }
  }

  async load(id) {
    this.id = id;
    const { body, revision } = await this.app.api.get(`/v1/channels/${id}/show`);
    if (id !== this.id) return;
    this.revision = revision;
    $('#showing').textContent = body.show;
    for (const b of document.querySelectorAll('[data-show]')) {
      b.classList.toggle('active', b.dataset.show === body.show);
    }
    const img = $('#output');
    const serial = (this.serial = (this.serial || 0) + 1);
    const { blob } = await this.app.api.blob(`/v1/channels/${id}/output.png?scale=4`);
    if (serial !== this.serial) return;
    const old = img.src;
    img.src = URL.createObjectURL(blob);
    img.dataset.show = body.show;
    if (old.startsWith('blob:')) URL.revokeObjectURL(old);
  }

  async send(show) {
    const id = this.id;
    try {
      await this.app.api.write('PUT', `/v1/channels/${id}/show`, { show }, this.revision);
    } catch (e) {
      if (!(e instanceof ApiError && e.status === 412)) {
        this.app.notify(this.app.describe(e), 'error');
        return;
      }
      // Last choice wins for a test card: nothing is lost by sending it again.
      await this.app.api.write('PUT', `/v1/channels/${id}/show`, { show }, e.current);
    }
    this.app.notify(`${id} shows ${show}`);
    if (id === this.id) await this.load(id);
  }
}

// Calibration: a correspondences file in, a proposal out (residual per point, warnings), and
// the proposal applied to the rig.
export class CalibrationPanel {
  constructor(app) {
    this.app = app;
    this.proposal = null;
    $('#calib-form').addEventListener('submit', (e) => {
      e.preventDefault();
      this.solve();
    });
    $('#calib-apply').addEventListener('click', () => this.apply());
  }

  async solve() {
    const file = $('#calib-file').files[0];
    if (!file) {
      this.app.notify('choose a CSV or JSON file of correspondences', 'warn');
      return;
    }
    const out = $('#calib-result');
    let doc;
    try {
      doc = parseCorrespondences(await file.text(), file.name, this.app.channelSize());
    } catch (e) {
      out.replaceChildren(el('p', { class: 'error' }, e.message));
      return;
    }
    const model = $('#calib-model').value;
    if (model !== 'auto' && !doc.model) doc.model = model;
    out.replaceChildren(el('p', {}, `solving from ${doc.points.length} points…`));
    try {
      const { body } = await this.app.api.write('POST', `/v1/channels/${this.app.channel}/calibration`, doc);
      this.show(body, doc);
    } catch (e) {
      out.replaceChildren(el('p', { class: 'error' }, this.app.describe(e)));
    }
  }

  show(p, doc) {
    this.proposal = p;
    const out = $('#calib-result');
    const considered = el('table', {}, el('tr', {}, el('th', {}, 'model'), el('th', {}, 'rms px'), el('th', {}, 'held out'), el('th', {}, 'verdict')));
    for (const c of p.considered) {
      considered.append(
        el('tr', {}, el('td', {}, c.model), el('td', {}, (+c.rms).toFixed(4)), el('td', {}, c.held_out_rms === null ? '—' : (+c.held_out_rms).toFixed(4)), el('td', {}, c.verdict || '')),
      );
    }
    const worst = Math.max(...p.residuals, 1e-9);
    const residuals = el('table', { class: 'residuals', id: 'calib-residuals' }, el('tr', {}, el('th', {}, '#'), el('th', {}, 'pixel'), el('th', {}, 'residual px'), el('th', {}, '')));
    p.residuals.forEach((r, k) => {
      const bar = el('span', { class: 'bar' });
      bar.style.width = `${(100 * r) / worst}%`;
      const row = el('tr', { class: p.outliers.includes(k) ? 'outlier' : '' }, el('td', {}, String(k)), el('td', {}, fmt(doc.points[k].pixel)), el('td', {}, r.toFixed(4)), el('td', {}, bar));
      residuals.append(row);
    });
    const warnings = el('ul', { class: 'warnings' }, ...p.warnings.map((w) => el('li', {}, w)));
    out.replaceChildren(
      el('p', { id: 'calib-summary' }, `proposal ${p.id}: ${p.proposed.lens.model}, rms ${p.rms.toFixed(4)} px over ${p.residuals.length} points, ${p.outliers.length} outliers (measured against rig revision ${p.rig_revision})`),
      warnings,
      considered,
      residuals,
    );
    $('#calib-apply').hidden = false;
  }

  async apply() {
    if (!this.proposal) return;
    try {
      const r = await this.app.api.write('POST', `/v1/proposals/${this.proposal.id}/apply`, undefined, this.app.rigRevision);
      this.app.notify(`proposal ${this.proposal.id} applied: rig revision ${r.revision}`);
      $('#calib-apply').hidden = true;
    } catch (e) {
      this.app.notify(this.app.describe(e), 'error');
    }
  }
}

// Exports: each file of the channel and the rig's MPCDI package, with the grid and error the
// daemon reports, saved through a download link.
export class ExportPanel {
  constructor(app) {
    this.app = app;
    for (const b of document.querySelectorAll('[data-export]')) {
      b.addEventListener('click', () => this.channelFile(b.dataset.export));
    }
    $('#mpcdi-form').addEventListener('submit', (e) => {
      e.preventDefault();
      this.mpcdi();
    });
  }

  // `unit`: what the daemon's largest error is measured in for this file.
  async fetchFile(url, name, unit) {
    const log = $('#export-log');
    const line = el('li', {}, `${name}: working…`);
    log.prepend(line);
    try {
      const { blob, headers } = await this.app.api.blob(url);
      const grid = headers.get('X-Omniwarp-Grid');
      const error = headers.get('X-Omniwarp-Max-Error');
      const href = URL.createObjectURL(blob);
      const a = el('a', { href, download: name }, name);
      line.replaceChildren(a, ` — ${(blob.size / 1024).toFixed(0)} KiB${grid ? `, grid ${grid}` : ''}${error ? `, largest error ${error} ${unit}` : ''}`);
      a.click();
    } catch (e) {
      line.replaceChildren(`${name}: ${this.app.describe(e)}`);
      line.className = 'error';
    }
  }

  channelFile(file) {
    const q = new URLSearchParams();
    const tol = $('#export-tolerance').value;
    if (tol !== '') q.set('tolerance', tol);
    if (file === 'mesh.data') q.set('reader', $('#export-reader').value);
    const id = this.app.channel;
    this.fetchFile(`/v1/channels/${id}/exports/${file}?${q}`, `${id}-${file}`, file === 'warp-a3.pfm' ? 'mm' : 'content px');
  }

  mpcdi() {
    const f = $('#mpcdi-form').elements;
    const q = new URLSearchParams({ profile: f.profile.value, reader: f.reader.value, alpha_bits: f.alpha_bits.value });
    if (f.version.value) q.set('version', f.version.value);
    if (f.tolerance.value !== '') q.set('tolerance', f.tolerance.value);
    this.fetchFile(`/v1/export.mpcdi?${q}`, 'rig.mpcdi', f.profile.value === 'a3' ? 'mm' : 'content px');
  }
}

// The history of every acknowledged write, newest first. An entry of the rig, a content canvas
// or a tile screen can be made current again (a revert: a new revision, nothing rewritten).
export class HistoryPanel {
  constructor(app) {
    this.app = app;
  }

  async load() {
    const { body } = await this.app.api.get('/v1/history?limit=40');
    const list = $('#history');
    // Newest first: a resource's first entry is its current revision, which there is nothing
    // to revert to.
    const seen = new Set();
    list.replaceChildren(
      ...body.history.map((h) => {
        const li = el('li', {}, `${new Date(h.at_ms).toLocaleTimeString()} ${h.who}: ${h.action} ${h.resource} → ${h.revision} `);
        const current = !seen.has(h.resource);
        seen.add(h.resource);
        if (current) {
          li.append(el('span', { class: 'current' }, 'current'));
        } else if (/^(rig|channels\/[^/]+\/(content|tiles))$/.test(h.resource)) {
          const back = el('button', { class: 'revert', title: `make revision ${h.revision} of ${h.resource} current again` }, 'revert');
          back.dataset.resource = h.resource;
          back.dataset.revision = h.revision;
          back.addEventListener('click', () => this.confirm(back, h.resource, h.revision));
          li.append(back);
        }
        return li;
      }),
    );
  }

  // A revert changes what the projectors show: the first press asks, a second within a few
  // seconds does it.
  confirm(button, resource, revision) {
    if (button.dataset.armed) {
      delete button.dataset.armed;
      button.textContent = 'revert';
      this.revert(resource, revision);
      return;
    }
    button.dataset.armed = 'yes';
    button.textContent = `make ${revision} current? press again`;
    setTimeout(() => {
      if (!button.dataset.armed) return;
      delete button.dataset.armed;
      button.textContent = 'revert';
    }, 5000);
  }

  async revert(resource, revision) {
    const path = `/v1/${resource}`;
    try {
      const { revision: current } = await this.app.api.get(path);
      const r = await this.app.api.write('POST', `${path}/revert`, { revision }, current);
      this.app.notify(`${resource}: revision ${revision} made current as revision ${r.revision}`);
    } catch (e) {
      this.app.notify(this.app.describe(e), 'error');
    }
  }
}

// The render nodes following the daemon (`omniwarp play`, docs/player.md), as each last
// reported: the channels its outputs show, whether it is muted, its last error; one not heard
// from for a few seconds (it reports every second) is marked silent.
export class NodesPanel {
  constructor(app) {
    this.app = app;
  }

  async load() {
    const { body } = await this.app.api.get('/v1/nodes');
    const list = $('#nodes');
    if (!body.nodes.length) {
      list.replaceChildren(el('li', {}, 'none has reported'));
      return;
    }
    list.replaceChildren(
      ...body.nodes.map((n) => {
        const outputs = n.outputs.map((o) => o.channel).join(', ');
        const muted = n.black ? ' · muted to black' : '';
        const silent = n.age_seconds > 3 ? ` · silent for ${Math.round(n.age_seconds)} s` : '';
        const li = el('li', { 'data-node': n.id }, `${n.id}: ${outputs}${muted}${silent}`);
        if (n.error) li.append(el('div', { class: 'node-error' }, n.error));
        return li;
      }),
    );
  }
}
