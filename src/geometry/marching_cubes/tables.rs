//! Lookup tables for face-consistent marching cubes, generated once from the cube's topology
//! instead of typed in, so every case follows the same three rules:
//!
//! 1. On each cell face the crossing points are joined by segments. A face with two crossings
//!    has one obvious segment; an *ambiguous* face (equal signs on the diagonals, four crossings)
//!    gets the pair chosen by a bit of the table index, which the caller sets from the
//!    asymptotic decider — a test on the face's four values alone, so both cells sharing the
//!    face choose the same pair.
//! 2. Each segment is directed so that the inside (negative) corners lie to its left when the
//!    face is seen from outside the cell; the segments then chain into closed loops, one
//!    polygon per loop, counter-clockwise seen from the outside of the surface.
//! 3. Each polygon is triangulated without a diagonal between two crossings of one face (the
//!    neighbouring cell could use the same pair), maximising the worst triangle shape;
//!    a polygon that admits no such triangulation is fanned around its centroid (slot 12).
//!
//! Corner `c` of a cell sits at `(c & 1, (c >> 1) & 1, (c >> 2) & 1)`; bit `c` of a case is set
//! when corner `c` is inside (value below the iso level). Edge `e` runs along axis `e / 4`.

use std::sync::LazyLock;

/// Slot of the polygon-centroid vertex in a triangle (slots 0–11 are cell edges).
pub(crate) const CENTRE_SLOT: u8 = 12;

/// Number of table entries: 8 corner bits plus 6 face-decision bits.
const ENTRIES: usize = 1 << 14;

/// Start corner of each edge; the end corner is `start | 1 << axis`.
pub(crate) const EDGE_START: [u8; 12] = edge_starts();

/// The four corners of each face (`2·axis + side`) in cyclic order.
pub(crate) const FACE_CORNERS: [[u8; 4]; 6] = face_corners();

/// The two axes other than `axis`, in increasing order.
const fn other_axes(axis: usize) -> (usize, usize) {
    match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    }
}

const fn edge_starts() -> [u8; 12] {
    let mut out = [0u8; 12];
    let mut e = 0;
    while e < 12 {
        let (u, v) = other_axes(e / 4);
        out[e] = (((e & 1) << u) | (((e >> 1) & 1) << v)) as u8;
        e += 1;
    }
    out
}

const fn face_corners() -> [[u8; 4]; 6] {
    let mut out = [[0u8; 4]; 6];
    let mut f = 0;
    while f < 6 {
        let (axis, side) = (f / 2, f % 2);
        let (u, v) = other_axes(axis);
        let base = side << axis;
        out[f] = [
            base as u8,
            (base | 1 << u) as u8,
            (base | 1 << u | 1 << v) as u8,
            (base | 1 << v) as u8,
        ];
        f += 1;
    }
    out
}

/// The edge joining two corners that differ in exactly one bit.
pub(crate) fn edge_between(a: u8, b: u8) -> u8 {
    let axis = (a ^ b).trailing_zeros() as usize;
    let start = a.min(b);
    let (u, v) = other_axes(axis);
    (axis * 4) as u8 + ((start >> u) & 1) + (((start >> v) & 1) << 1)
}

/// Position of a corner in the unit cube.
fn corner_pos(c: u8) -> [f64; 3] {
    [
        f64::from(c & 1),
        f64::from((c >> 1) & 1),
        f64::from((c >> 2) & 1),
    ]
}

/// Midpoint of an edge in the unit cube (where the table assumes the crossing lies).
fn edge_mid(e: u8) -> [f64; 3] {
    let a = corner_pos(EDGE_START[e as usize]);
    let mut p = a;
    p[e as usize / 4] = 0.5;
    p
}

/// The generated tables: triangles per (case, face decisions) and the centroid polygons.
pub(crate) struct CaseTable {
    /// `offsets[i]..offsets[i + 1]` indexes `triangles` for entry `i`.
    offsets: Vec<u32>,
    triangles: Vec<[u8; 3]>,
    /// Per entry, the edge slots whose mean is the centroid vertex (empty when unused).
    centres: Vec<Vec<u8>>,
    /// Per case, the faces (bit `f`) whose four corners alternate in sign.
    ambiguous: [u8; 256],
}

impl CaseTable {
    /// Triangles (edge slots, or [`CENTRE_SLOT`]) for a case and its face decisions.
    #[inline]
    pub(crate) fn triangles(&self, case: u8, decisions: u8) -> &[[u8; 3]] {
        let i = usize::from(case) | (usize::from(decisions) << 8);
        &self.triangles[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }
    /// Edge slots averaged into the centroid vertex of this entry.
    #[inline]
    pub(crate) fn centre_polygon(&self, case: u8, decisions: u8) -> &[u8] {
        &self.centres[usize::from(case) | (usize::from(decisions) << 8)]
    }
    /// Faces of `case` that need a decision (bit `f` for face `f`).
    #[inline]
    pub(crate) fn ambiguous_faces(&self, case: u8) -> u8 {
        self.ambiguous[usize::from(case)]
    }
}

/// The table, built on first use (well under a millisecond of work).
pub(crate) static TABLE: LazyLock<CaseTable> = LazyLock::new(build_table);

fn build_table() -> CaseTable {
    let mut offsets = Vec::with_capacity(ENTRIES + 1);
    let mut triangles = Vec::new();
    let mut centres = Vec::with_capacity(ENTRIES);
    offsets.push(0);
    for index in 0..ENTRIES {
        let case = (index & 0xff) as u8;
        let decisions = (index >> 8) as u8;
        let mut centre = Vec::new();
        for polygon in loops(case, decisions) {
            match triangulate(&polygon) {
                Some(tris) => triangles.extend(tris),
                None => {
                    assert!(centre.is_empty(), "two centroid polygons in case {case}");
                    let n = polygon.len();
                    triangles
                        .extend((0..n).map(|i| [polygon[i], polygon[(i + 1) % n], CENTRE_SLOT]));
                    centre = polygon;
                }
            }
        }
        centres.push(centre);
        offsets.push(u32::try_from(triangles.len()).expect("table fits in u32"));
    }
    let ambiguous = std::array::from_fn(|case| {
        (0..6).fold(0u8, |mask, f| {
            mask | (u8::from(is_ambiguous(case as u8, f)) << f)
        })
    });
    CaseTable {
        offsets,
        triangles,
        centres,
        ambiguous,
    }
}

fn inside(case: u8, corner: u8) -> bool {
    case >> corner & 1 == 1
}

fn is_ambiguous(case: u8, face: usize) -> bool {
    let [c0, c1, c2, c3] = FACE_CORNERS[face].map(|c| inside(case, c));
    c0 == c2 && c1 == c3 && c0 != c1
}

/// Directed face segments of a case, chained into closed loops of edge slots.
pub(crate) fn loops(case: u8, decisions: u8) -> Vec<Vec<u8>> {
    let mut next = [u8::MAX; 12];
    for face in 0..6 {
        for (from, to) in face_segments(case, face, decisions >> face & 1 == 1) {
            assert_eq!(
                next[from as usize],
                u8::MAX,
                "two segments leave edge {from}"
            );
            next[from as usize] = to;
        }
    }
    let mut seen = [false; 12];
    let mut out = Vec::new();
    for start in 0..12u8 {
        if next[start as usize] == u8::MAX || seen[start as usize] {
            continue;
        }
        let mut polygon = Vec::new();
        let mut e = start;
        while !seen[e as usize] {
            seen[e as usize] = true;
            polygon.push(e);
            e = next[e as usize];
        }
        assert_eq!(e, start, "segments of case {case} do not close");
        out.push(polygon);
    }
    out
}

/// Segments on one face, each directed with the inside corners on its left seen from outside.
fn face_segments(case: u8, face: usize, join_inside: bool) -> Vec<(u8, u8)> {
    let corners = FACE_CORNERS[face];
    let ins = corners.map(|c| inside(case, c));
    // Face edge i joins corners i and i + 1.
    let edge = |i: usize| edge_between(corners[i % 4], corners[(i + 1) % 4]);
    let crossings: Vec<usize> = (0..4).filter(|&i| ins[i] != ins[(i + 1) % 4]).collect();
    // Each segment cuts the face in two; `group` are the corners on one side.
    let cuts: Vec<(usize, usize, Vec<usize>)> = match crossings.as_slice() {
        [] => Vec::new(),
        &[i, j] => vec![(i, j, ((i + 1)..=j).collect())],
        _ => {
            // Alternating signs: cut off the two corners whose kind is separated.
            let cut_inside = !join_inside;
            (0..4)
                .filter(|&c| ins[c] == cut_inside)
                .map(|c| ((c + 3) % 4, c, vec![c]))
                .collect()
        }
    };
    let axis = face / 2;
    let mut normal = [0.0; 3];
    normal[axis] = if face.is_multiple_of(2) { -1.0 } else { 1.0 };
    cuts.into_iter()
        .map(|(i, j, group)| {
            let (p, q) = (edge_mid(edge(i)), edge_mid(edge(j)));
            let mid = std::array::from_fn(|k| 0.5 * (p[k] + q[k]));
            let centroid: [f64; 3] = std::array::from_fn(|k| {
                group
                    .iter()
                    .map(|&g| corner_pos(corners[g])[k])
                    .sum::<f64>()
                    / group.len() as f64
            });
            let left = cross(sub(q, p), normal);
            let towards_group = dot(left, sub(centroid, mid)) > 0.0;
            if towards_group == ins[group[0]] {
                (edge(i), edge(j))
            } else {
                (edge(j), edge(i))
            }
        })
        .collect()
}

/// Do two edges lie on a common face?
fn share_face(a: u8, b: u8) -> bool {
    FACE_CORNERS.iter().any(|f| {
        let on = |e: u8| {
            let (s, t) = (
                EDGE_START[e as usize],
                EDGE_START[e as usize] | 1 << (e / 4),
            );
            f.contains(&s) && f.contains(&t)
        };
        on(a) && on(b)
    })
}

/// Best triangulation of a polygon (max-min shape quality at edge midpoints) that avoids
/// diagonals between two edges of one face; `None` when every triangulation needs one.
fn triangulate(polygon: &[u8]) -> Option<Vec<[u8; 3]>> {
    let n = polygon.len();
    let chord_ok = |i: usize, j: usize| {
        j == i + 1 || (i == 0 && j == n - 1) || !share_face(polygon[i], polygon[j])
    };
    // best[i][j]: (worst quality, split) of the sub-polygon i..=j.
    let mut best = vec![vec![None::<(f64, usize)>; n]; n];
    for len in 2..n {
        for i in 0..n - len {
            let j = i + len;
            let mut choice: Option<(f64, usize)> = None;
            for k in i + 1..j {
                if !chord_ok(i, k) || !chord_ok(k, j) {
                    continue;
                }
                let sub_q = |a: usize, b: usize| {
                    if b == a + 1 {
                        Some(f64::INFINITY)
                    } else {
                        best[a][b].map(|x| x.0)
                    }
                };
                let (Some(left), Some(right)) = (sub_q(i, k), sub_q(k, j)) else {
                    continue;
                };
                let q = quality(polygon[i], polygon[k], polygon[j])
                    .min(left)
                    .min(right);
                if choice.is_none_or(|(bq, _)| q > bq) {
                    choice = Some((q, k));
                }
            }
            best[i][j] = choice;
        }
    }
    best[0][n - 1]?;
    let mut out = Vec::with_capacity(n - 2);
    let mut stack = vec![(0, n - 1)];
    while let Some((i, j)) = stack.pop() {
        if j <= i + 1 {
            continue;
        }
        let (_, k) = best[i][j].expect("sub-polygon of a valid triangulation");
        out.push([polygon[i], polygon[k], polygon[j]]);
        stack.push((i, k));
        stack.push((k, j));
    }
    Some(out)
}

/// Shape quality in (0, 1]: 1 for an equilateral triangle.
fn quality(a: u8, b: u8, c: u8) -> f64 {
    let (a, b, c) = (edge_mid(a), edge_mid(b), edge_mid(c));
    let area2 = norm(cross(sub(b, a), sub(c, a)));
    let sq = |x: [f64; 3]| dot(x, x);
    2.0 * 3f64.sqrt() * area2 / (sq(sub(b, a)) + sq(sub(c, b)) + sq(sub(a, c)))
}

use crate::geometry::mesh::{cross, dot, norm, sub};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_crossing_edge_is_in_exactly_one_loop() {
        for index in 0..ENTRIES {
            let case = (index & 0xff) as u8;
            let crossing: Vec<u8> = (0..12u8)
                .filter(|&e| {
                    let s = EDGE_START[e as usize];
                    inside(case, s) != inside(case, s | 1 << (e / 4))
                })
                .collect();
            let mut used: Vec<u8> = loops(case, (index >> 8) as u8).concat();
            used.sort_unstable();
            assert_eq!(used, crossing, "case {case:#010b}");
        }
    }

    #[test]
    fn triangles_meet_only_along_face_segments_or_private_diagonals() {
        let t = &*TABLE;
        for index in 0..ENTRIES {
            let (case, decisions) = ((index & 0xff) as u8, (index >> 8) as u8);
            let mut directed = std::collections::HashMap::new();
            for tri in t.triangles(case, decisions) {
                for k in 0..3 {
                    *directed.entry((tri[k], tri[(k + 1) % 3])).or_insert(0) += 1;
                }
            }
            for (&(a, b), &n) in &directed {
                let back = directed.get(&(b, a)).copied().unwrap_or(0);
                let on_face = a != CENTRE_SLOT && b != CENTRE_SLOT && share_face(a, b);
                if on_face {
                    // A segment on the cell's boundary: used once, by this cell alone.
                    assert_eq!(
                        (n, back),
                        (1, 0),
                        "case {case:#010b} dec {decisions:06b} edge {a}-{b}"
                    );
                } else {
                    assert_eq!(
                        (n, back),
                        (1, 1),
                        "case {case:#010b} dec {decisions:06b} edge {a}-{b}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_cut_off_inside_corner_faces_away_from_it() {
        // Corner 0 inside: the normal of its triangle points along +(1, 1, 1).
        let tris = TABLE.triangles(0b0000_0001, 0);
        assert_eq!(tris.len(), 1);
        let [a, b, c] = tris[0].map(edge_mid);
        let n = cross(sub(b, a), sub(c, a));
        assert!(n.iter().all(|&x| x > 0.0), "{n:?}");
        // The complement (all but corner 0 inside) is the same triangle reversed.
        let flipped = TABLE.triangles(0b1111_1110, 0);
        let [a, b, c] = flipped[0].map(edge_mid);
        assert!(cross(sub(b, a), sub(c, a)).iter().all(|&x| x < 0.0));
    }
}
