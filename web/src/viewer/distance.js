// Distances from the vertices of one mesh to the nearest vertex of another, with a uniform
// grid over the second so each query looks only at nearby cells, and the colour map that
// shows them.

/** For each vertex of `from` (flat xyz array), the distance to the nearest point of `to`. */
export function nearestDistances(from, to) {
  const count = to.length / 3;
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < to.length; i += 3) {
    for (let k = 0; k < 3; k++) {
      lo[k] = Math.min(lo[k], to[i + k]);
      hi[k] = Math.max(hi[k], to[i + k]);
    }
  }
  // About two points per occupied cell on a surface: cell side ~ sqrt(area / count).
  const extent = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-9);
  const cell = Math.max(extent / Math.cbrt(Math.max(count, 1)) / 2, extent * 1e-4);
  const dims = lo.map((l, k) => Math.max(1, Math.ceil((hi[k] - l) / cell) + 1));
  const key = (x, y, z) => (z * dims[1] + y) * dims[0] + x;
  const cells = new Map();
  for (let i = 0; i < count; i++) {
    const c = [0, 1, 2].map((k) => Math.floor((to[3 * i + k] - lo[k]) / cell));
    const id = key(c[0], c[1], c[2]);
    let list = cells.get(id);
    if (!list) cells.set(id, (list = []));
    list.push(i);
  }
  const out = new Float32Array(from.length / 3);
  for (let v = 0; v < out.length; v++) {
    const p = [from[3 * v], from[3 * v + 1], from[3 * v + 2]];
    const c = p.map((x, k) => Math.min(dims[k] - 1, Math.max(0, Math.floor((x - lo[k]) / cell))));
    // Distance from p to the grid box, so rings start where points can be.
    const outside = Math.hypot(...p.map((x, k) => Math.max(lo[k] - x, 0, x - hi[k])));
    let best = Infinity;
    for (let r = 0; ; r++) {
      for (let z = c[2] - r; z <= c[2] + r; z++) {
        for (let y = c[1] - r; y <= c[1] + r; y++) {
          for (let x = c[0] - r; x <= c[0] + r; x++) {
            const onShell = Math.max(Math.abs(x - c[0]), Math.abs(y - c[1]), Math.abs(z - c[2])) === r;
            if (!onShell || x < 0 || y < 0 || z < 0 || x >= dims[0] || y >= dims[1] || z >= dims[2]) continue;
            for (const i of cells.get(key(x, y, z)) ?? []) {
              const d = (to[3 * i] - p[0]) ** 2 + (to[3 * i + 1] - p[1]) ** 2 + (to[3 * i + 2] - p[2]) ** 2;
              if (d < best) best = d;
            }
          }
        }
      }
      // Every unvisited point is at least r·cell from p's cell (beyond the box: outside).
      const reach = Math.max(r * cell, outside);
      if (best <= reach * reach || r > Math.max(...dims)) break;
    }
    out[v] = Math.sqrt(best);
  }
  return out;
}

const STOPS = [
  [0.0, [0.23, 0.3, 0.75]],
  [0.25, [0.4, 0.6, 0.98]],
  [0.5, [0.87, 0.87, 0.87]],
  [0.75, [0.96, 0.6, 0.48]],
  [1.0, [0.7, 0.02, 0.15]],
];

/** A diverging blue–white–red colour for t in [0, 1]. */
export function colourAt(t) {
  const x = Math.min(1, Math.max(0, t));
  for (let i = 1; i < STOPS.length; i++) {
    const [t1, c1] = STOPS[i];
    const [t0, c0] = STOPS[i - 1];
    if (x <= t1) {
      const u = (x - t0) / (t1 - t0);
      return c0.map((c, k) => c + u * (c1[k] - c));
    }
  }
  return STOPS[STOPS.length - 1][1];
}

/** CSS gradient stops of the colour map, for the legend. */
export function legendGradient() {
  return STOPS.map(([t, c]) => `rgb(${c.map((x) => Math.round(255 * x)).join(",")}) ${100 * t}%`).join(", ");
}
