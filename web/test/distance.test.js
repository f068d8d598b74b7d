// The viewer's distance map against brute force: the grid search must find exactly the
// nearest point for points on, inside and far outside the other set.

import assert from "node:assert/strict";
import { test } from "node:test";
import { colourAt, nearestDistances } from "../src/viewer/distance.js";

/** A deterministic pseudo-random sequence (xorshift32) in [0, 1). */
function random(seed) {
  let s = seed >>> 0 || 1;
  return () => {
    s ^= s << 13;
    s ^= s >>> 17;
    s ^= s << 5;
    return (s >>> 0) / 2 ** 32;
  };
}

function bruteForce(from, to) {
  const out = [];
  for (let i = 0; i < from.length; i += 3) {
    let best = Infinity;
    for (let j = 0; j < to.length; j += 3) {
      const d = (from[i] - to[j]) ** 2 + (from[i + 1] - to[j + 1]) ** 2 + (from[i + 2] - to[j + 2]) ** 2;
      best = Math.min(best, d);
    }
    out.push(Math.sqrt(best));
  }
  return out;
}

/** Points on a sphere of `radius` around `centre`, like a mesh's vertices. */
function sphere(n, radius, centre, next) {
  const points = new Float32Array(3 * n);
  for (let i = 0; i < n; i++) {
    const z = 2 * next() - 1;
    const phi = 2 * Math.PI * next();
    const r = Math.sqrt(1 - z * z);
    points.set([centre[0] + radius * r * Math.cos(phi), centre[1] + radius * r * Math.sin(phi), centre[2] + radius * z], 3 * i);
  }
  return points;
}

test("grid search equals brute force on surfaces that overlap, nest and lie apart", () => {
  const next = random(7);
  const to = sphere(800, 10, [0, 0, 0], next);
  for (const [radius, centre] of [[10, [0, 0, 0]], [11, [1, -2, 0.5]], [4, [0, 0, 0]], [3, [60, 5, -40]]]) {
    const from = sphere(300, radius, centre, next);
    const fast = nearestDistances(from, to);
    const exact = bruteForce(from, to);
    exact.forEach((d, i) => assert.ok(Math.abs(fast[i] - d) <= 1e-5 * Math.max(1, d), `${radius}: ${fast[i]} vs ${d}`));
  }
});

test("a point of the other set is at distance zero", () => {
  const to = new Float32Array([0, 0, 0, 5, 5, 5, -3, 2, 1]);
  assert.deepEqual([...nearestDistances(new Float32Array([5, 5, 5]), to)], [0]);
});

test("the colour map runs blue, white, red and clamps", () => {
  const [low, mid, high] = [colourAt(0), colourAt(0.5), colourAt(1)];
  assert.ok(low[2] > low[0], "blue at 0");
  assert.ok(Math.abs(mid[0] - mid[2]) < 1e-9, "grey at the middle");
  assert.ok(high[0] > high[2], "red at 1");
  assert.deepEqual(colourAt(-1), low);
  assert.deepEqual(colourAt(2), high);
});
