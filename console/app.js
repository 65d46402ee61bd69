// The console's entry: holds the token, the rig's revision and the selected channel, follows
// the change feed and routes each change to what it affects.

import { Api, ApiError, Unreachable } from './api.js';
import { ChannelView } from './channel.js';
import { CalibrationPanel, ContentPanel, ExportPanel, HistoryPanel, NodesPanel, PatternPanel } from './panels.js';
import { RigView } from './rig3d.js';
import { affects, channelColour } from './tiles.js';

const $ = (sel) => document.querySelector(sel);

class App {
  constructor() {
    // A token may arrive in the address's fragment (never sent to a server) so a link or a QR
    // code can open the console; it is kept for this tab only.
    const fromHash = new URLSearchParams(location.hash.slice(1)).get('token');
    if (fromHash) {
      sessionStorage.setItem('omniwarp-token', fromHash);
      history.replaceState(null, '', location.pathname);
    }
    this.api = new Api(sessionStorage.getItem('omniwarp-token') || '');
    const busy = 'the daemon is busy with other work; asking again…';
    this.api.onBusy = (path) => {
      if (path) this.notify(busy, 'warn');
      else if ($('#notice').textContent === busy) this.notify('');
    };
    this.channels = [];
    this.channel = null;
    this.rigRevision = null;
    this.rig = new RigView($('#rig3d'));
    this.view = new ChannelView(this);
    this.content = new ContentPanel(this);
    this.patterns = new PatternPanel(this);
    this.calibration = new CalibrationPanel(this);
    this.exports = new ExportPanel(this);
    this.historyPanel = new HistoryPanel(this);
    this.nodes = new NodesPanel(this);
    // Nodes report every second without a change on the feed; their list is read again now
    // and then so that one gone quiet shows as such.
    setInterval(() => this.nodes.load().catch(() => {}), 5000);
    this.stopFeed = null;
    $('#token-form').addEventListener('submit', (e) => {
      e.preventDefault();
      sessionStorage.setItem('omniwarp-token', $('#token').value.trim());
      this.api.token = $('#token').value.trim();
      $('#token-dialog').hidden = true;
      this.start();
    });
    $('#rig-undo').addEventListener('click', () => this.rigHistory('undo'));
    $('#rig-redo').addEventListener('click', () => this.rigHistory('redo'));
    for (const tab of document.querySelectorAll('[data-tab]')) {
      tab.addEventListener('click', () => this.tab(tab.dataset.tab));
    }
  }

  tab(name) {
    for (const t of document.querySelectorAll('[data-tab]')) t.classList.toggle('active', t.dataset.tab === name);
    for (const p of document.querySelectorAll('.panel')) p.hidden = p.id !== `panel-${name}`;
    if (name === 'overview') {
      this.rig.draw();
      this.loadPlan();
    }
  }

  // The plan of the rig as it is now: fetched when the overview is shown, again only when the
  // rig has changed since.
  async loadPlan() {
    const revision = this.rigRevision;
    if (this.planRevision === revision) return;
    this.planRevision = revision;
    try {
      const [{ body }, { blob }] = await Promise.all([
        this.api.get('/v1/rig/plan?step=1'),
        this.api.blob('/v1/rig/plan.png?step=1&width=900'),
      ]);
      if (revision !== this.rigRevision) return;
      const [none, one, two, more] = body.wall.lit_by.map((s) => (100 * s).toFixed(1));
      const density = body.wall.pixels_per_degree;
      const narrowest = Math.min(...body.overlaps.map((o) => o.width));
      $('#plan-summary').textContent =
        `Wall lit by no projector ${none} %, one ${one} %, two ${two} %, three or more ${more} %. ` +
        (density ? `Pixels per degree ${density[0].toFixed(1)} to ${density[2].toFixed(1)}, median ${density[1].toFixed(1)}. ` : '') +
        (body.overlaps.length ? `Narrowest overlap ${narrowest.toFixed(1)}°.` : 'No overlaps.');
      const img = $('#plan');
      const old = img.src;
      img.src = URL.createObjectURL(blob);
      img.dataset.revision = String(revision);
      if (old.startsWith('blob:')) URL.revokeObjectURL(old);
    } catch (e) {
      this.planRevision = undefined;
      $('#plan-summary').textContent = `The plan could not be loaded: ${this.describe(e)}`;
    }
  }

  describe(e) {
    if (e instanceof ApiError) return `${e.status} ${e.describe()}`;
    if (e instanceof Unreachable) return e.message;
    return String(e.message || e);
  }

  notify(message, kind = 'info') {
    const n = $('#notice');
    n.textContent = message;
    n.className = kind;
  }

  channelSize() {
    const c = this.channels.find((ch) => ch.id === this.channel);
    return c ? c.resolution : null;
  }

  // Over TLS the daemon's certificate fingerprint, to compare with what it printed at start
  // before the token is typed in. The version answers without the token.
  async showFingerprint() {
    try {
      const v = await (await fetch('/v1/version')).json();
      if (v.tls_sha256) {
        $('#tls-sha256').textContent = v.tls_sha256;
        $('#tls-fingerprint').hidden = false;
      }
    } catch {
      // Plain HTTP or the daemon is away: nothing to show.
    }
  }

  async start() {
    if (this.stopFeed) this.stopFeed();
    try {
      await this.loadRig();
    } catch (e) {
      if (e instanceof ApiError && e.status === 401) {
        this.showFingerprint();
        $('#token-dialog').hidden = false;
        this.notify('this daemon needs its access token', 'warn');
        return;
      }
      this.notify(this.describe(e), 'error');
    }
    let away = false;
    this.stopFeed = this.api.feed(
      (change) => this.onChange(change),
      (state) => {
        $('#feed-state').textContent = state;
        $('#feed-state').className = state;
        if (state === 'token') $('#token-dialog').hidden = false;
        if (state === 'live' && away) this.resync();
        away = state !== 'live';
      },
    );
  }

  // After the feed was away (a daemon restart, the network) or fell behind, changes may have
  // been missed — a restart also puts every channel back on its content — so everything shown
  // is read again, and the technician told of any edit that never reached the daemon.
  async resync() {
    const lost = this.api.lostWrites;
    this.api.lostWrites = 0;
    if (lost) {
      this.notify(
        `the daemon is back; ${lost === 1 ? 'an edit' : `${lost} edits`} made while it was away ${
          lost === 1 ? 'was' : 'were'
        } not saved: what is shown now is what it holds`,
        'warn',
      );
    } else if ($('#notice').textContent.includes('cannot be reached')) {
      this.notify('the daemon is back');
    }
    try {
      const { revision } = await this.api.get('/v1/channels');
      if (revision !== this.rigRevision) {
        await this.loadRig();
        return;
      }
      for (const c of this.channels) this.channelStatus(c.id);
      await Promise.all([
        this.view.loadTiles(),
        this.view.loadPreview(),
        this.content.load(this.channel),
        this.patterns.load(this.channel),
        this.historyPanel.load(),
        this.nodes.load(),
      ]);
    } catch (e) {
      this.notify(this.describe(e), 'error');
    }
  }

  async loadRig() {
    const { body, revision } = await this.api.get('/v1/channels');
    this.rigRevision = revision;
    this.channels = body.channels;
    $('#rig-revision').textContent = `rig revision ${revision}`;
    if (!this.channels.some((c) => c.id === this.channel)) this.channel = this.channels[0].id;
    this.drawChannels();
    const geometry = await this.api.get('/v1/rig/geometry');
    this.rig.selected = this.channel;
    this.rig.set(geometry.body);
    if (!$('#panel-overview').hidden) this.loadPlan();
    await Promise.all([this.select(this.channel), this.historyPanel.load(), this.nodes.load()]);
  }

  drawChannels() {
    const list = $('#channels');
    list.replaceChildren(
      ...this.channels.map((c, k) => {
        const li = document.createElement('li');
        li.dataset.channel = c.id;
        li.className = c.id === this.channel ? 'selected' : '';
        const swatch = document.createElement('span');
        swatch.className = 'swatch';
        swatch.style.background = channelColour(k);
        const name = document.createElement('button');
        name.textContent = c.id;
        name.addEventListener('click', () => this.select(c.id));
        const status = document.createElement('span');
        status.className = 'status';
        status.textContent = `${c.resolution[0]}×${c.resolution[1]} ${c.lens.replace('LENSMODEL_', '')}`;
        li.append(swatch, name, status);
        return li;
      }),
    );
    for (const c of this.channels) this.channelStatus(c.id);
  }

  // A channel's status line: its tile screen (edited or following the geometry) and what it
  // shows.
  async channelStatus(id) {
    try {
      const [tiles, show] = await Promise.all([
        this.api.get(`/v1/channels/${id}/tiles`),
        this.api.get(`/v1/channels/${id}/show`),
      ]);
      const li = document.querySelector(`#channels li[data-channel="${CSS.escape(id)}"] .status`);
      if (!li) return;
      const c = this.channels.find((ch) => ch.id === id);
      li.textContent = `${c.resolution[0]}×${c.resolution[1]} · tiles ${tiles.revision}${
        tiles.body.follows_geometry ? '' : ' edited'
      } · shows ${show.body.show}`;
    } catch {
      // The list still names the channel; the status fills in on the next change.
    }
  }

  async select(id) {
    this.channel = id;
    for (const li of document.querySelectorAll('#channels li')) li.classList.toggle('selected', li.dataset.channel === id);
    this.rig.selected = id;
    this.rig.draw();
    $('#channel-title').textContent = id;
    const c = this.channels.find((ch) => ch.id === id);
    await Promise.all([this.view.open(id, c.resolution), this.content.load(id), this.patterns.load(id)]);
  }

  async onChange(change) {
    $('#last-change').textContent = `${change.kind} ${change.channel || ''} ${change.revision || change.id || ''}`;
    try {
      if (change.kind === 'rig') {
        if (change.revision !== this.rigRevision) await this.loadRig();
        return;
      }
      if (change.kind === 'node') {
        await this.nodes.load();
        return;
      }
      if (change.kind === 'lagged') {
        await this.resync();
        return;
      }
      if (change.channel) this.channelStatus(change.channel);
      if (['tiles', 'content'].includes(change.kind)) this.historyPanel.load();
      if (!affects(change, this.channel)) return;
      if (change.kind === 'tiles') {
        await this.view.changed('tiles', change.revision);
      } else if (change.kind === 'content') {
        const jobs = [this.view.changed('content', change.revision)];
        if (change.revision !== this.content.revision) jobs.push(this.content.load(this.channel));
        await Promise.all(jobs);
      } else if (change.kind === 'show') {
        await this.patterns.load(this.channel);
      }
    } catch (e) {
      this.notify(this.describe(e), 'error');
    }
  }

  async rigHistory(action) {
    try {
      const r = await this.api.write('POST', `/v1/rig/${action}`, {}, this.rigRevision);
      this.notify(`${action}: rig revision ${r.revision}`);
    } catch (e) {
      this.notify(this.describe(e), 'error');
    }
  }

  // Someone else's write came first. Nothing is dropped silently: the technician chooses to
  // reload (and lose this edit, knowingly), reapply it on top of the newer revision, or merge
  // where the daemon can tell the two did not touch the same features.
  conflict({ what, mine, base, current, reload, reapply, merge, note = '' }) {
    const box = $('#conflict');
    box.hidden = false;
    $('#conflict-text').textContent = `${what} changed to revision ${current} while you edited revision ${base}. Your change: ${
      Array.isArray(mine) ? `${mine.length} edit${mine.length === 1 ? '' : 's'}` : 'the form'
    }. ${note}`;
    const run = (fn) => async () => {
      box.hidden = true;
      await fn();
    };
    $('#conflict-reload').onclick = run(reload);
    $('#conflict-reapply').onclick = run(reapply);
    $('#conflict-merge').hidden = !merge;
    $('#conflict-merge').onclick = merge ? run(merge) : null;
  }

  clearConflict() {
    $('#conflict').hidden = true;
  }
}

const app = new App();
window.omniwarp = app;
app.start();
