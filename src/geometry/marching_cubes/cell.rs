//! The per-cell step of marching cubes, shared by the dense grid path and the sparse
//! extraction so both produce bit-identical vertices: classification of a cell, the face
//! decisions, and the arithmetic that places a vertex on an edge.

use super::tables::{EDGE_START, FACE_CORNERS, TABLE};

/// Which corners are inside: bit `c` set when `values[c] < iso` (a value equal to the iso
/// level counts as outside, so a cell never sees a zero-length crossing as two crossings).
#[inline]
pub(crate) fn case_of(values: &[f32; 8], iso: f32) -> u8 {
    values
        .iter()
        .enumerate()
        .fold(0u8, |case, (c, &v)| case | (u8::from(v < iso) << c))
}

/// Face decisions for the ambiguous faces of `case` (asymptotic decider): bit `f` is set when
/// the bilinear saddle of face `f` lies inside, i.e. the two inside corners are joined
/// across the face. The test compares the products of the two diagonals' values, which is
/// symmetric in the face's corners, so both cells sharing the face decide alike.
#[inline]
pub(crate) fn decisions(values: &[f32; 8], case: u8, iso: f32) -> u8 {
    let mut ambiguous = TABLE.ambiguous_faces(case);
    let mut out = 0u8;
    while ambiguous != 0 {
        let f = ambiguous.trailing_zeros() as usize;
        ambiguous &= ambiguous - 1;
        let [c0, c1, c2, c3] = FACE_CORNERS[f].map(|c| values[c as usize] - iso);
        let (p02, p13) = (c0 * c2, c1 * c3);
        // On an ambiguous face one diagonal is inside (both negative), the other outside.
        let inside_joined = if c0 < 0.0 { p02 > p13 } else { p13 > p02 };
        out |= u8::from(inside_joined) << f;
    }
    out
}

/// The triangles of a classified cell, as edge slots (0–11) or the centroid slot.
#[inline]
pub(crate) fn triangles(case: u8, decisions: u8) -> &'static [[u8; 3]] {
    TABLE.triangles(case, decisions)
}

/// Edge slots whose mean positions the centroid vertex of this cell (empty if none).
#[inline]
pub(crate) fn centre_polygon(case: u8, decisions: u8) -> &'static [u8] {
    TABLE.centre_polygon(case, decisions)
}

/// Offset of an edge slot's lower corner within the cell, and the edge's axis.
#[inline]
pub(crate) fn slot_edge(slot: u8) -> ([usize; 3], usize) {
    let s = EDGE_START[slot as usize];
    (
        [
            usize::from(s & 1),
            usize::from((s >> 1) & 1),
            usize::from((s >> 2) & 1),
        ],
        slot as usize / 4,
    )
}

/// The two cell corners an edge slot joins (lower first).
#[inline]
pub(crate) fn slot_corners(slot: u8) -> (usize, usize) {
    let s = EDGE_START[slot as usize];
    (usize::from(s), usize::from(s | 1 << (slot / 4)))
}

/// Linear position of the crossing between `v0` (lower end) and `v1`, as a fraction.
#[inline]
pub(crate) fn crossing_fraction(v0: f32, v1: f32, iso: f32) -> f32 {
    (iso - v0) / (v1 - v0)
}

/// The vertex on the edge from sample `lower` along `axis`, with values `v0` at the lower
/// and `v1` at the upper end; `coords` are the grid's sample coordinates on one axis.
#[inline]
pub(crate) fn edge_position(
    coords: &[f32],
    lower: [usize; 3],
    axis: usize,
    v0: f32,
    v1: f32,
    iso: f32,
) -> [f32; 3] {
    let t = crossing_fraction(v0, v1, iso);
    let mut p = lower.map(|i| coords[i]);
    let (c0, c1) = (coords[lower[axis]], coords[lower[axis] + 1]);
    p[axis] = c0 + t * (c1 - c0);
    p
}

/// Position of a cell's centroid vertex: the mean of its polygon's edge vertices.
pub(crate) fn centre_position(
    coords: &[f32],
    cell: [usize; 3],
    values: &[f32; 8],
    iso: f32,
    polygon: &[u8],
) -> [f32; 3] {
    let mut sum = [0.0f32; 3];
    for &slot in polygon {
        let (offset, axis) = slot_edge(slot);
        let (a, b) = slot_corners(slot);
        let lower = std::array::from_fn(|k| cell[k] + offset[k]);
        let p = edge_position(coords, lower, axis, values[a], values[b], iso);
        for k in 0..3 {
            sum[k] += p[k];
        }
    }
    sum.map(|s| s / polygon.len() as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decider_is_invariant_under_relabelling_of_the_face() {
        // Face 0 (x = 0) holds corners 0, 2, 6, 4; the face's values in two orders.
        let mut values = [1.0f32; 8];
        for (c, v) in [(0, -0.3), (2, 0.2), (6, -0.4), (4, 0.5)] {
            values[c] = v;
        }
        let case = case_of(&values, 0.0);
        assert_eq!(TABLE.ambiguous_faces(case) & 1, 1);
        // Saddle value (ad − bc)/(a + d − b − c) = (0.12 − 0.10)/(−1.4) < 0: inside joined.
        assert_eq!(decisions(&values, case, 0.0) & 1, 1);
        values[2] = 0.4; // now (0.12 − 0.20)/(−1.6) > 0: separated
        assert_eq!(decisions(&values, case, 0.0) & 1, 0);
    }

    #[test]
    fn edge_vertices_interpolate_linearly_and_hit_corners_exactly() {
        let coords = [0.0f32, 0.5, 1.0];
        let p = edge_position(&coords, [1, 0, 1], 0, -1.0, 3.0, 0.0);
        assert_eq!(p, [0.625, 0.0, 0.5]);
        // A value equal to the iso level puts the vertex on that corner.
        assert_eq!(
            edge_position(&coords, [0, 1, 0], 2, -2.0, 0.0, 0.0),
            [0.0, 0.5, 0.5]
        );
    }
}
