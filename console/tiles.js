// The console's own logic, free of the page so that `node --test` checks it: reading a tile
// screen, turning a drag into tile edits, picking features, reading correspondence files, and
// deciding which changes on the feed touch a channel.
//
// A tile screen's features sit at fixed places in the projector image (x, y from 0 to 1, edge to
// edge) and each says which content direction (phi, theta, degrees) shows there. Dragging a
// feature by d pixels therefore means "show here what was shown d pixels back": the content
// follows the finger. The new direction is the old one minus the local rate of change of the
// directions times d, the rate measured from the neighbouring features.

export function grid(tiles) {
  const columns = tiles.layout.columns;
  const features = tiles.layout.features;
  const rows = Math.floor(features.length / columns);
  return {
    columns,
    rows,
    at(c, r) {
      if (c < 0 || r < 0 || c >= columns || r >= rows) return null;
      return features[r * columns + c];
    },
  };
}

export function usable(f) {
  return !!f && f.valid !== false;
}

// Degrees wrapped into (-180, 180].
export function wrap(d) {
  let v = ((d + 180) % 360 + 360) % 360 - 180;
  if (v === -180) v = 180;
  return v;
}

// d(phi, theta)/d(pixel x, pixel y) at feature (c, r), from its usable neighbours: central
// differences where both exist, one-sided where one does. Null where a direction has none.
export function rate(tiles, c, r, width, height) {
  const g = grid(tiles);
  const here = g.at(c, r);
  if (!usable(here)) return null;
  const along = (dc, dr) => {
    const fwd = g.at(c + dc, r + dr);
    const back = g.at(c - dc, r - dr);
    const a = usable(fwd) ? fwd : here;
    const b = usable(back) ? back : here;
    if (a === b) return null;
    const dpx = (a.x - b.x) * width + (a.y - b.y) * height;
    if (dpx === 0) return null;
    return [wrap(a.phi - b.phi) / dpx, (a.theta - b.theta) / dpx];
  };
  const dx = along(1, 0);
  const dy = along(0, 1);
  if (!dx || !dy) return null;
  // Columns: [d/dx, d/dy]; rows: [phi, theta].
  return [
    [dx[0], dy[0]],
    [dx[1], dy[1]],
  ];
}

const round6 = (v) => Math.round(v * 1e6) / 1e6;

// set_feature edits that pull the content at each picked feature by (dx, dy) projector pixels.
// Rates come from the screen before the move, so a region moves as one piece.
export function pullEdits(tiles, picks, dx, dy, width, height) {
  const g = grid(tiles);
  const edits = [];
  for (const { column, row } of picks) {
    const f = g.at(column, row);
    const j = rate(tiles, column, row, width, height);
    if (!usable(f) || !j) continue;
    const phi = wrap(f.phi - (j[0][0] * dx + j[0][1] * dy));
    const theta = Math.max(-90, Math.min(90, f.theta - (j[1][0] * dx + j[1][1] * dy)));
    edits.push({ op: 'set_feature', column, row, phi: round6(phi), theta: round6(theta) });
  }
  return edits;
}

// The usable feature nearest to pixel (px, py) within `radius` pixels, or null.
export function nearest(tiles, px, py, width, height, radius) {
  const g = grid(tiles);
  let best = null;
  let bestD = radius * radius;
  for (let r = 0; r < g.rows; r++) {
    for (let c = 0; c < g.columns; c++) {
      const f = g.at(c, r);
      if (!usable(f)) continue;
      const d = (f.x * width - px) ** 2 + (f.y * height - py) ** 2;
      if (d <= bestD) {
        bestD = d;
        best = { column: c, row: r };
      }
    }
  }
  return best;
}

// The usable features inside the pixel rectangle spanned by two corners.
export function inRect(tiles, [x0, y0], [x1, y1], width, height) {
  const g = grid(tiles);
  const [lx, hx] = [Math.min(x0, x1), Math.max(x0, x1)];
  const [ly, hy] = [Math.min(y0, y1), Math.max(y0, y1)];
  const picks = [];
  for (let r = 0; r < g.rows; r++) {
    for (let c = 0; c < g.columns; c++) {
      const f = g.at(c, r);
      if (!usable(f)) continue;
      const [x, y] = [f.x * width, f.y * height];
      if (x >= lx && x <= hx && y >= ly && y <= hy) picks.push({ column: c, row: r });
    }
  }
  return picks;
}

// The columns and rows a set of picks spans, as the tile ops take them ([first, last]).
export function span(picks) {
  if (!picks.length) return null;
  const cs = picks.map((p) => p.column);
  const rs = picks.map((p) => p.row);
  return { columns: [Math.min(...cs), Math.max(...cs)], rows: [Math.min(...rs), Math.max(...rs)] };
}

// A correspondences document from a file: JSON as `omniwarp calibrate` reads it, or CSV/TSV
// with five numbers a line (pixel x, pixel y, world x, y, z; a header line and # comments
// skipped). Throws an Error naming the line at fault.
export function parseCorrespondences(text, name, resolution) {
  const trimmed = text.trim();
  if (name.toLowerCase().endsWith('.json') || trimmed.startsWith('{')) {
    let doc;
    try {
      doc = JSON.parse(trimmed);
    } catch (e) {
      throw new Error(`${name}: not JSON (${e.message})`);
    }
    if (!doc || !Array.isArray(doc.points)) throw new Error(`${name}: no "points" list`);
    return doc;
  }
  const points = [];
  const lines = text.split(/\r?\n/);
  lines.forEach((line, k) => {
    const l = line.trim();
    if (!l || l.startsWith('#')) return;
    const cells = l.split(/[,;\t ]+/).filter((c) => c !== '');
    const nums = cells.map(Number);
    if (nums.some((v) => !Number.isFinite(v))) {
      if (points.length === 0 && k === lines.findIndex((x) => x.trim() && !x.trim().startsWith('#'))) {
        return; // the header
      }
      throw new Error(`${name}, line ${k + 1}: expected five numbers, got "${l}"`);
    }
    if (nums.length !== 5) {
      throw new Error(`${name}, line ${k + 1}: expected five numbers, got ${nums.length}`);
    }
    points.push({ pixel: nums.slice(0, 2), world: nums.slice(2) });
  });
  if (!points.length) throw new Error(`${name}: no points`);
  const doc = { points };
  if (resolution) doc.resolution = resolution;
  return doc;
}

// Unit direction at azimuth `az` (0 ahead, −z; positive to the right, +x) and elevation `el`,
// degrees, as the daemon's frames have it; and back. `angles` of a zero vector is null.
export function direction(az, el) {
  const [a, e] = [(az * Math.PI) / 180, (el * Math.PI) / 180];
  return [Math.cos(e) * Math.sin(a), Math.sin(e), -Math.cos(e) * Math.cos(a)];
}

export function angles(v) {
  const n = Math.hypot(...v);
  if (!(n > 0)) return null;
  return [(Math.atan2(v[0], -v[2]) * 180) / Math.PI, (Math.asin(Math.max(-1, Math.min(1, v[1] / n))) * 180) / Math.PI];
}

// How much a two-finger pinch spread when pointer `id` moved to (x, y): the ratio of the
// fingers' distance after to before, or null unless exactly two pointers are down. `pointers`
// maps pointer ids to their last [x, y].
export function pinchRatio(pointers, id, x, y) {
  const last = pointers.get(id);
  if (!last || pointers.size !== 2) return null;
  const other = [...pointers].find(([k]) => k !== id)[1];
  const before = Math.hypot(last[0] - other[0], last[1] - other[1]);
  const after = Math.hypot(x - other[0], y - other[1]);
  return before > 0 && after > 0 ? after / before : null;
}

// Whether a change on the feed alters what `channel` shows or how it is edited.
export function affects(change, channel) {
  if (!change) return false;
  if (change.kind === 'rig') return true;
  return ['tiles', 'content', 'show'].includes(change.kind) && change.channel === channel;
}

// A colour per channel, far apart for neighbouring indices (the same hues as the daemon's ids
// test card).
export function channelColour(index) {
  const hue = ((index * 0.61803398875) % 1) * 6;
  const x = 1 - Math.abs((hue % 2) - 1);
  const table = [
    [1, x, 0],
    [x, 1, 0],
    [0, 1, x],
    [0, x, 1],
    [x, 0, 1],
    [1, 0, x],
  ];
  const [r, g, b] = table[Math.min(5, Math.floor(hue))];
  const c = (v) => Math.floor(40 + 160 * v);
  return `rgb(${c(r)}, ${c(g)}, ${c(b)})`;
}
