// One channel: its live preview with the tile grid drawn over it, dragging features (the
// content follows the finger), selecting regions, the tile operations, keyboard nudges, and
// what happens when someone else changed the tiles first.

import { ApiError } from './api.js';
import { grid, inRect, nearest, pinchRatio, pullEdits, span, usable } from './tiles.js';

const SVG = 'http://www.w3.org/2000/svg';

export class ChannelView {
  constructor(app) {
    this.app = app;
    this.id = null;
    this.size = [1, 1];
    this.tiles = null;
    this.revision = null; // the tile screen's revision shown
    this.follows = true;
    this.picks = [];
    this.form = null; // { column, row, base } while the feature form is open
    this.drag = null;
    this.previewSerial = 0;
    this.shown = { tiles: null, content: null }; // the revisions a preview was last asked for
    this.zoom = 1;
    this.touches = new Map();
    this.queue = Promise.resolve();
    this.$ = (sel) => document.querySelector(sel);
    this.stage = this.$('#stage');
    this.overlay = this.$('#overlay');
    this.preview = this.$('#preview');
    this.bind();
  }

  bind() {
    const o = this.overlay;
    o.addEventListener('pointerdown', (e) => this.down(e));
    o.addEventListener('pointermove', (e) => this.moveTo(e));
    o.addEventListener('pointerup', (e) => this.up(e));
    o.addEventListener('pointercancel', (e) => {
      this.touches.delete(e.pointerId);
      this.drag = null;
      this.draw();
    });
    this.stage.addEventListener('keydown', (e) => this.key(e));
    this.stage.addEventListener(
      'wheel',
      (e) => {
        if (!e.ctrlKey && !e.metaKey) return;
        e.preventDefault();
        this.setZoom(this.zoom * Math.exp(-e.deltaY * 0.002));
      },
      { passive: false },
    );
    this.$('#band-mode').addEventListener('click', (e) => e.currentTarget.classList.toggle('active'));
    this.$('#zoom-in').addEventListener('click', () => this.setZoom(this.zoom * 1.5));
    this.$('#zoom-out').addEventListener('click', () => this.setZoom(this.zoom / 1.5));
    this.$('#preview-content').addEventListener('change', () => this.loadPreview());
    this.$('#preview-scale').addEventListener('change', () => this.loadPreview());
    this.$('#feature-form').addEventListener('submit', (e) => {
      e.preventDefault();
      this.applyForm();
    });
    this.$('#feature-form').addEventListener('input', () => {
      if (this.form) this.form.dirty = true;
    });
    for (const b of document.querySelectorAll('[data-tile-op]')) {
      b.addEventListener('click', () => this.tileOp(b.dataset.tileOp));
    }
    this.$('#tiles-undo').addEventListener('click', () => this.history('undo'));
    this.$('#tiles-redo').addEventListener('click', () => this.history('redo'));
  }

  setZoom(z) {
    this.zoom = Math.min(8, Math.max(1, z));
    this.$('#zoomer').style.width = `${this.zoom * 100}%`;
  }

  async open(id, size) {
    this.id = id;
    this.size = size;
    // Nothing of the channel shown before may stay under this one's title until its own tiles
    // arrive: a press on a stale handle would edit this channel with the other's features and
    // revision, and a stale picture would pass for its preview.
    this.tiles = null;
    this.revision = null;
    this.picks = [];
    this.drag = null;
    this.closeForm();
    this.$('#tiles-revision').textContent = 'loading the tiles…';
    this.draw();
    this.previewSerial++;
    this.shown = { tiles: null, content: null };
    if (this.preview.src.startsWith('blob:')) URL.revokeObjectURL(this.preview.src);
    this.preview.removeAttribute('src');
    delete this.preview.dataset.etag;
    this.$('#zoomer').style.aspectRatio = `${size[0]} / ${size[1]}`;
    this.overlay.setAttribute('viewBox', `0 0 ${size[0]} ${size[1]}`);
    await Promise.all([this.loadTiles(), this.loadPreview()]);
  }

  async loadTiles() {
    const id = this.id;
    const { body, revision } = await this.app.api.get(`/v1/channels/${id}/tiles`);
    if (id !== this.id) return;
    this.tiles = body.tiles;
    this.revision = revision;
    this.follows = body.follows_geometry;
    this.$('#tiles-revision').textContent = `tiles revision ${revision}${
      this.follows ? ' (following the geometry)' : ''
    }`;
    this.draw();
    this.showForm();
  }

  // After a change to this channel's tiles or content canvas to revision n, the tiles and the
  // preview are asked for again once, whichever arrives first: the answer to this console's own
  // write or the feed's notice of it (their order is not fixed on a busy machine). Only the
  // tiles are waited for: the next queued nudge starts from them, and must not wait for a
  // render as well.
  async changed(kind, n) {
    if (this.shown[kind] !== n) {
      this.shown[kind] = n;
      this.loadPreview();
    }
    if (kind === 'tiles' && n !== this.revision) await this.loadTiles();
  }

  previewUrl() {
    const content = this.$('#preview-content').value;
    const scale = this.$('#preview-scale').value;
    return `/v1/channels/${this.id}/render?scale=${scale}&content=${content}`;
  }

  async loadPreview() {
    const serial = ++this.previewSerial;
    const id = this.id;
    const status = this.$('#preview-status');
    status.textContent = 'rendering…';
    try {
      const { blob, headers } = await this.app.api.blob(this.previewUrl());
      if (serial !== this.previewSerial || id !== this.id) return;
      const old = this.preview.src;
      this.preview.src = URL.createObjectURL(blob);
      if (old.startsWith('blob:')) URL.revokeObjectURL(old);
      this.preview.dataset.etag = headers.get('ETag') || '';
      this.preview.dataset.serial = String(serial);
      status.textContent = headers.get('X-Omniwarp-Preview') || 'ready';
    } catch (e) {
      if (serial === this.previewSerial) status.textContent = this.app.describe(e);
    }
  }

  // The grid: lines between neighbouring usable features, a handle per usable feature.
  draw() {
    const o = this.overlay;
    o.replaceChildren();
    if (!this.tiles) return;
    const [w, h] = this.size;
    const g = grid(this.tiles);
    const moved = (c, r) => {
      const f = g.at(c, r);
      let [x, y] = [f.x * w, f.y * h];
      if (this.drag && this.drag.moving && this.drag.picks.some((p) => p.column === c && p.row === r)) {
        x += this.drag.d[0];
        y += this.drag.d[1];
      }
      return [x, y];
    };
    const path = [];
    for (let r = 0; r < g.rows; r++) {
      for (let c = 0; c < g.columns; c++) {
        if (!usable(g.at(c, r))) continue;
        const [x, y] = moved(c, r);
        if (usable(g.at(c + 1, r))) {
          const [x2, y2] = moved(c + 1, r);
          path.push(`M${x} ${y}L${x2} ${y2}`);
        }
        if (usable(g.at(c, r + 1))) {
          const [x2, y2] = moved(c, r + 1);
          path.push(`M${x} ${y}L${x2} ${y2}`);
        }
      }
    }
    const lines = document.createElementNS(SVG, 'path');
    lines.setAttribute('d', path.join(''));
    lines.setAttribute('class', 'grid-lines');
    o.append(lines);
    const radius = Math.max(w, h) / 240;
    for (let r = 0; r < g.rows; r++) {
      for (let c = 0; c < g.columns; c++) {
        const f = g.at(c, r);
        if (!usable(f)) continue;
        const [x, y] = moved(c, r);
        const dot = document.createElementNS(SVG, 'circle');
        dot.setAttribute('cx', x);
        dot.setAttribute('cy', y);
        dot.setAttribute('r', radius);
        const picked = this.picks.some((p) => p.column === c && p.row === r);
        dot.setAttribute('class', `handle${picked ? ' picked' : ''}${f.outside ? ' outside' : ''}`);
        dot.dataset.column = c;
        dot.dataset.row = r;
        o.append(dot);
      }
    }
    if (this.drag && this.drag.band) {
      const [a, b] = [this.drag.start, this.drag.at];
      const rect = document.createElementNS(SVG, 'rect');
      rect.setAttribute('x', Math.min(a[0], b[0]));
      rect.setAttribute('y', Math.min(a[1], b[1]));
      rect.setAttribute('width', Math.abs(a[0] - b[0]));
      rect.setAttribute('height', Math.abs(a[1] - b[1]));
      rect.setAttribute('class', 'band');
      o.append(rect);
    }
  }

  // Client coordinates → projector pixels.
  pixel(e) {
    const box = this.overlay.getBoundingClientRect();
    return [
      ((e.clientX - box.left) / box.width) * this.size[0],
      ((e.clientY - box.top) / box.height) * this.size[1],
    ];
  }

  // Two fingers on the preview zoom it (the page's own pinch is off over the grid, so that
  // one finger drags features).
  pinch(e) {
    const spread = pinchRatio(this.touches, e.pointerId, e.clientX, e.clientY);
    if (spread === null) return false;
    this.setZoom(this.zoom * spread);
    this.touches.set(e.pointerId, [e.clientX, e.clientY]);
    return true;
  }

  down(e) {
    if (!this.tiles) return;
    this.touches.set(e.pointerId, [e.clientX, e.clientY]);
    if (this.touches.size === 2) {
      // The second finger turns a drag into a pinch: the first finger's drag is dropped.
      this.drag = null;
      this.draw();
      return;
    }
    this.stage.focus({ preventScroll: true });
    const at = this.pixel(e);
    const box = this.overlay.getBoundingClientRect();
    // A finger is less precise than a mouse: a larger reach on touch screens.
    const reach = ((e.pointerType === 'touch' ? 28 : 12) * this.size[0]) / box.width;
    const hit = nearest(this.tiles, at[0], at[1], this.size[0], this.size[1], reach);
    this.overlay.setPointerCapture(e.pointerId);
    // Shift (or the Region button, on a touch screen) draws a rectangle that adds the features
    // inside it to the picks; on a handle otherwise, a press picks and drags it.
    const band = e.shiftKey || this.$('#band-mode').classList.contains('active');
    if (hit && !band) {
      const already = this.picks.some((p) => p.column === hit.column && p.row === hit.row);
      if (e.ctrlKey || e.metaKey) {
        this.picks = already
          ? this.picks.filter((p) => p.column !== hit.column || p.row !== hit.row)
          : [...this.picks, hit];
      } else if (!already) {
        this.picks = [hit];
      }
      this.drag = { start: at, at, d: [0, 0], picks: [...this.picks], base: this.revision, moving: false };
      this.openForm(hit);
    } else {
      this.drag = { start: at, at, band: true, add: e.shiftKey || e.ctrlKey || e.metaKey };
    }
    this.draw();
  }

  moveTo(e) {
    if (this.pinch(e) || !this.drag) return;
    const at = this.pixel(e);
    this.drag.at = at;
    this.drag.d = [at[0] - this.drag.start[0], at[1] - this.drag.start[1]];
    if (!this.drag.band && Math.hypot(...this.drag.d) * (this.overlay.getBoundingClientRect().width / this.size[0]) > 3) {
      this.drag.moving = true;
    }
    this.draw();
  }

  async up(e) {
    this.touches.delete(e.pointerId);
    const drag = this.drag;
    this.drag = null;
    if (!drag) return;
    if (drag.band) {
      const inside = inRect(this.tiles, drag.start, drag.at, this.size[0], this.size[1]);
      const had = drag.add ? this.picks : [];
      const fresh = inside.filter((p) => !had.some((q) => q.column === p.column && q.row === p.row));
      this.picks = [...had, ...fresh];
      this.$('#band-mode').classList.remove('active');
      this.draw();
      this.app.notify(`${this.picks.length} features selected`);
      return;
    }
    this.draw();
    if (!drag.moving) return;
    await this.enqueue(this.id, () => this.pull(this.id, drag.picks, drag.d, drag.base));
  }

  // This console's writes go one after another, so a nudge sent while the last one is in flight
  // starts from the revision that one made instead of conflicting with it. A write queued for
  // one channel is not made once another is open: its edits are worked out from the tiles shown.
  enqueue(id, task) {
    const guarded = () => {
      if (id === this.id) return task();
      this.app.notify(`an edit of ${id} was not sent: ${this.id} was opened before its turn`, 'warn');
    };
    const run = this.queue.then(guarded, guarded);
    this.queue = run.catch(() => {});
    return run;
  }

  async pull(id, picks, d, base) {
    if (!this.loaded()) return;
    const edits = pullEdits(this.tiles, picks, d[0], d[1], this.size[0], this.size[1]);
    if (!edits.length) {
      this.app.notify('nothing to move: the features picked have no usable neighbours', 'warn');
      return;
    }
    await this.patch(id, edits, base);
  }

  key(e) {
    if (!this.picks.length || !this.tiles) return;
    const step = e.shiftKey ? 10 : e.altKey ? 0.25 : 1;
    const d = { ArrowLeft: [-step, 0], ArrowRight: [step, 0], ArrowUp: [0, -step], ArrowDown: [0, step] }[e.key];
    if (!d) return;
    e.preventDefault();
    const picks = [...this.picks];
    const id = this.id;
    this.enqueue(id, () => this.pull(id, picks, d, this.revision));
  }

  // Sends edits of channel `id` made against revision `base`; a conflict is shown, never
  // dropped, and choosing what to do about it still writes to that channel. `form` is the
  // feature form the edits came from, if they did.
  async patch(id, edits, base, { merge = false, form = null } = {}) {
    try {
      const r = await this.app.api.write('PATCH', `/v1/channels/${id}/tiles`, { edits, merge }, base);
      this.app.notify(`tiles revision ${r.revision} of ${id}`);
      this.app.clearConflict();
      if (id !== this.id) return true;
      // The form's own numbers, written: it follows the screen again.
      if (form && form === this.form) form.dirty = false;
      await this.changed('tiles', r.revision);
      this.showForm();
      return true;
    } catch (e) {
      if (e instanceof ApiError && e.status === 412) {
        this.app.conflict({
          what: `the tiles of ${id}`,
          note: merge ? 'The daemon could not merge: a revision since changed the same features.' : '',
          mine: edits,
          base,
          current: e.current,
          reload: async () => {
            if (id !== this.id) return;
            this.closeForm();
            await this.loadTiles();
          },
          reapply: () => this.patch(id, edits, e.current, { form }),
          merge: () => this.patch(id, edits, base, { merge: true, form }),
        });
      } else {
        this.app.notify(this.app.describe(e), 'error');
      }
      return false;
    }
  }

  // Whether this channel's tiles have arrived; says so when they have not.
  loaded() {
    if (this.tiles) return true;
    this.app.notify(`the tiles of ${this.id} are still loading`, 'warn');
    return false;
  }

  async tileOp(op) {
    if (!this.loaded()) return;
    const sel = this.picks[0];
    const around = span(this.picks);
    const number = (name) => Number(this.$(`#${name}`).value);
    const edits = {
      insert_row: sel && [{ op: 'insert_row', at: sel.row + 1 }],
      insert_column: sel && [{ op: 'insert_column', at: sel.column + 1 }],
      remove_row: sel && [{ op: 'remove_row', at: sel.row }],
      remove_column: sel && [{ op: 'remove_column', at: sel.column }],
      subdivide: [around && around.columns[0] !== around.columns[1] ? { op: 'subdivide', ...around } : { op: 'subdivide' }],
      smooth: [{ op: 'smooth', iterations: number('smooth-iterations') }],
      refine: [{ op: 'refine', tolerance: number('tile-tolerance') }],
      coarsen: [{ op: 'coarsen', tolerance: number('tile-tolerance') }],
      reset: [{ op: 'reset' }],
    }[op];
    if (op === 'geometry') {
      try {
        const r = await this.app.api.write('DELETE', `/v1/channels/${this.id}/tiles`, undefined, this.revision);
        this.app.notify(`tiles revision ${r.revision}: following the geometry again`);
        await this.changed('tiles', r.revision);
      } catch (e) {
        this.app.notify(this.app.describe(e), 'error');
      }
      return;
    }
    if (!edits) {
      this.app.notify('pick a feature first', 'warn');
      return;
    }
    this.picks = [];
    await this.patch(this.id, edits, this.revision);
  }

  async history(action) {
    if (!this.loaded()) return;
    try {
      const r = await this.app.api.write('POST', `/v1/channels/${this.id}/tiles/${action}`, {}, this.revision);
      this.app.notify(`${action}: tiles revision ${r.revision} (as revision ${r.body.from})`);
      await this.changed('tiles', r.revision);
    } catch (e) {
      if (e instanceof ApiError && e.status === 412) await this.loadTiles();
      this.app.notify(this.app.describe(e), 'error');
    }
  }

  // The feature form edits one feature's numbers. Its numbers and the revision they were read
  // at move together: untouched, the form follows every new revision (a drag of the feature
  // shows in it at once); once typed in, it keeps the revision it was typed against, so that
  // applying it after any change since — this console's own drags included — is a conflict,
  // never a silent overwrite.
  openForm(pick) {
    // Pressing the feature the form already shows (to drag it) keeps what was typed.
    if (this.form && this.form.column === pick.column && this.form.row === pick.row) return;
    this.form = { ...pick, base: this.revision, dirty: false };
    this.showForm();
  }

  closeForm() {
    this.form = null;
    this.$('#feature-form').hidden = true;
  }

  showForm() {
    const form = this.$('#feature-form');
    if (!this.form || !this.tiles) return;
    const f = grid(this.tiles).at(this.form.column, this.form.row);
    if (!f) return this.closeForm();
    form.hidden = false;
    this.$('#feature-name').textContent = `feature column ${this.form.column}, row ${this.form.row}`;
    if (!this.form.dirty) {
      this.form.base = this.revision;
      for (const k of ['phi', 'theta', 'f', 'scale']) form.elements[k].value = f[k];
    }
    this.$('#feature-base').textContent =
      this.form.base === this.revision
        ? `at revision ${this.form.base}`
        : `typed against revision ${this.form.base}; revision ${this.revision} is newer`;
  }

  async applyForm() {
    if (!this.form) return;
    const form = this.$('#feature-form');
    const edit = { op: 'set_feature', column: this.form.column, row: this.form.row };
    for (const k of ['phi', 'theta', 'f', 'scale']) {
      const v = Number(form.elements[k].value);
      if (!Number.isFinite(v)) {
        this.app.notify(`${k}: not a number`, 'error');
        return;
      }
      edit[k] = v;
    }
    await this.patch(this.id, [edit], this.form.base, { form: this.form });
  }
}
