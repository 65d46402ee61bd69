// The rig drawn in 3D on a 2D canvas: the wall as the daemon traces it (GET /v1/rig/geometry),
// the eye, and per channel its frustum and its footprint in the channel's colour. An orbit
// camera around the eye: drag to turn, wheel or pinch to move closer. A library would add
// shading we do not need; lines in perspective are all a technician reads here.

import { channelColour, pinchRatio } from './tiles.js';

export class RigView {
  constructor(canvas) {
    this.canvas = canvas;
    this.geometry = null;
    this.content = null; // { look_to, project_from } of the selected channel's canvas
    this.selected = null;
    this.yaw = 35;
    this.pitch = 25;
    this.distance = 6.5;
    this.pointers = new Map();
    canvas.addEventListener('pointerdown', (e) => {
      canvas.setPointerCapture(e.pointerId);
      this.pointers.set(e.pointerId, [e.clientX, e.clientY]);
    });
    canvas.addEventListener('pointermove', (e) => this.move(e));
    const up = (e) => this.pointers.delete(e.pointerId);
    canvas.addEventListener('pointerup', up);
    canvas.addEventListener('pointercancel', up);
    canvas.addEventListener(
      'wheel',
      (e) => {
        e.preventDefault();
        this.zoom(Math.exp(e.deltaY * 0.001));
      },
      { passive: false },
    );
    new ResizeObserver(() => this.draw()).observe(canvas);
  }

  zoom(factor) {
    this.distance = Math.min(80, Math.max(1, this.distance * factor));
    this.draw();
  }

  move(e) {
    const last = this.pointers.get(e.pointerId);
    if (!last) return;
    const now = [e.clientX, e.clientY];
    if (this.pointers.size === 1) {
      this.yaw -= (now[0] - last[0]) * 0.4;
      this.pitch = Math.max(-89, Math.min(89, this.pitch + (now[1] - last[1]) * 0.4));
    } else {
      const spread = pinchRatio(this.pointers, e.pointerId, now[0], now[1]);
      if (spread) this.zoom(1 / spread);
    }
    this.pointers.set(e.pointerId, now);
    this.draw();
  }

  set(geometry) {
    this.geometry = geometry;
    this.draw();
  }

  // World point → canvas pixel, or null behind the camera.
  projector() {
    const g = this.geometry;
    const target = g ? g.eye : [0, 0, 0];
    const [yaw, pitch] = [(this.yaw * Math.PI) / 180, (this.pitch * Math.PI) / 180];
    const back = [Math.cos(pitch) * Math.sin(yaw), Math.sin(pitch), Math.cos(pitch) * Math.cos(yaw)];
    const cam = target.map((t, k) => t + back[k] * this.distance);
    const f = back.map((v) => -v);
    // right = forward × world up (0, 1, 0).
    let right = [-f[2], 0, f[0]];
    const rl = Math.hypot(...right) || 1;
    right = right.map((v) => v / rl);
    const up = [
      right[1] * f[2] - right[2] * f[1],
      right[2] * f[0] - right[0] * f[2],
      right[0] * f[1] - right[1] * f[0],
    ];
    const { width, height } = this.canvas;
    const focal = 0.9 * Math.min(width, height);
    return (p) => {
      const d = [p[0] - cam[0], p[1] - cam[1], p[2] - cam[2]];
      const z = d[0] * f[0] + d[1] * f[1] + d[2] * f[2];
      if (z < 0.05) return null;
      const x = d[0] * right[0] + d[1] * right[1] + d[2] * right[2];
      const y = d[0] * up[0] + d[1] * up[1] + d[2] * up[2];
      return [width / 2 + (focal * x) / z, height / 2 - (focal * y) / z];
    };
  }

  draw() {
    const c = this.canvas;
    const ratio = window.devicePixelRatio || 1;
    const [w, h] = [Math.round(c.clientWidth * ratio), Math.round(c.clientHeight * ratio)];
    if (w === 0 || h === 0) return;
    if (c.width !== w || c.height !== h) [c.width, c.height] = [w, h];
    const ctx = c.getContext('2d');
    ctx.fillStyle = '#111418';
    ctx.fillRect(0, 0, w, h);
    const g = this.geometry;
    if (!g) return;
    const project = this.projector();
    const line = (points, style, width) => {
      ctx.strokeStyle = style;
      ctx.lineWidth = width * ratio;
      ctx.beginPath();
      let pen = false;
      for (const p of points) {
        const q = project(p);
        if (!q) {
          pen = false;
          continue;
        }
        if (pen) ctx.lineTo(q[0], q[1]);
        else ctx.moveTo(q[0], q[1]);
        pen = true;
      }
      ctx.stroke();
    };
    for (const l of g.wall) line(l, 'rgba(170, 180, 190, 0.35)', 1);
    const labels = [];
    g.channels.forEach((ch, k) => {
      const colour = channelColour(k);
      const strong = this.selected === null || this.selected === ch.id;
      ctx.globalAlpha = strong ? 1 : 0.35;
      for (const corner of ch.frustum) if (corner) line([ch.position, corner], colour, 1);
      for (const l of ch.footprint) line(l, colour, strong ? 3 : 2);
      ctx.setLineDash([4 * ratio, 4 * ratio]);
      for (const l of ch.spill) line(l, colour, 1);
      ctx.setLineDash([]);
      const q = project(ch.position);
      if (q) labels.push({ q, text: ch.id, colour, alpha: ctx.globalAlpha });
      ctx.globalAlpha = 1;
    });
    this.labels = this.placeLabels(ctx, labels, ratio);
    const eye = project(g.eye);
    if (eye) {
      ctx.fillStyle = '#fff';
      ctx.beginPath();
      ctx.arc(eye[0], eye[1], 4 * ratio, 0, 2 * Math.PI);
      ctx.fill();
    }
    // The selected channel's content: where its centre looks from the eye, and the point a
    // projected panorama is cast from.
    const content = this.content;
    if (content && content.look_to) {
      const t = content.look_to;
      const n = Math.hypot(...t) || 1;
      line([g.eye, g.eye.map((e, k) => e + (1.5 * t[k]) / n)], '#ffd24a', 2);
    }
    if (content && content.project_from) {
      const q = project(content.project_from);
      if (q) {
        ctx.strokeStyle = '#ffd24a';
        ctx.lineWidth = 2 * ratio;
        ctx.strokeRect(q[0] - 5 * ratio, q[1] - 5 * ratio, 10 * ratio, 10 * ratio);
      }
    }
  }

  // Projectors often hang side by side, so their names would print over each other: each label
  // goes beside its projector, moved down past the labels already placed, with a leader line
  // when it had to move. The boxes, in canvas pixels, are kept (tests read them).
  placeLabels(ctx, labels, ratio) {
    ctx.font = `${12 * ratio}px system-ui, sans-serif`;
    const height = 16 * ratio;
    const placed = [];
    for (const l of labels.sort((a, b) => a.q[1] - b.q[1] || a.q[0] - b.q[0])) {
      const box = { x: l.q[0] + 6 * ratio, y: l.q[1] - 6 * ratio - 12 * ratio, w: ctx.measureText(l.text).width, h: height };
      const hits = () => placed.some((p) => box.x < p.x + p.w && p.x < box.x + box.w && box.y < p.y + p.h && p.y < box.y + box.h);
      const start = box.y;
      while (hits()) box.y += height;
      ctx.globalAlpha = l.alpha;
      ctx.fillStyle = l.colour;
      ctx.strokeStyle = l.colour;
      if (box.y !== start) {
        ctx.lineWidth = ratio;
        ctx.beginPath();
        ctx.moveTo(l.q[0], l.q[1]);
        ctx.lineTo(box.x, box.y + 12 * ratio);
        ctx.stroke();
      }
      ctx.fillText(l.text, box.x, box.y + 12 * ratio);
      ctx.globalAlpha = 1;
      placed.push({ ...box, text: l.text });
    }
    return placed;
  }
}
