//! A closed manifold triangle mesh as half-edges, with the three local operations of
//! isotropic remeshing: edge split, edge flip and half-edge collapse. The half-edges of face
//! f are stored at 3f, 3f + 1, 3f + 2 (a → b, b → c, c → a), so `next` and `prev` are
//! arithmetic; deleted faces and vertices are only marked.

use std::collections::HashMap;

use crate::geometry::mesh::{norm, sub};

/// Marks a deleted face or vertex.
pub const GONE: u32 = u32::MAX;

/// Half-edge mesh with one label per face.
#[derive(Debug, Clone)]
pub struct HalfEdges {
    /// Vertex positions.
    pub pos: Vec<[f64; 3]>,
    /// One outgoing half-edge per vertex (`GONE` when deleted).
    pub out: Vec<u32>,
    /// Target vertex of each half-edge.
    pub to: Vec<u32>,
    /// Opposite half-edge.
    pub twin: Vec<u32>,
    /// Face label (`GONE` when deleted).
    pub label: Vec<u32>,
}

/// The next half-edge in the same face.
pub fn next(h: u32) -> u32 {
    3 * (h / 3) + (h + 1) % 3
}

/// The previous half-edge in the same face.
pub fn prev(h: u32) -> u32 {
    3 * (h / 3) + (h + 2) % 3
}

impl HalfEdges {
    /// Builds the structure; `None` unless every edge has exactly two opposite half-edges.
    pub fn new(pos: Vec<[f64; 3]>, triangles: &[[u32; 3]], labels: &[u32]) -> Option<Self> {
        let mut to = Vec::with_capacity(3 * triangles.len());
        let mut out = vec![GONE; pos.len()];
        let mut by_pair: HashMap<(u32, u32), u32> = HashMap::with_capacity(3 * triangles.len());
        for (f, t) in triangles.iter().enumerate() {
            for k in 0..3 {
                let h = (3 * f + k) as u32;
                to.push(t[(k + 1) % 3]);
                out[t[k] as usize] = h;
                if by_pair.insert((t[k], t[(k + 1) % 3]), h).is_some() {
                    return None;
                }
            }
        }
        let mut twin = vec![GONE; to.len()];
        for (&(a, b), &h) in &by_pair {
            twin[h as usize] = *by_pair.get(&(b, a))?;
        }
        Some(Self {
            pos,
            out,
            to,
            twin,
            label: labels.to_vec(),
        })
    }

    /// Source vertex of a half-edge.
    pub fn from(&self, h: u32) -> u32 {
        self.to[prev(h) as usize]
    }

    /// Face of a half-edge.
    pub fn face(h: u32) -> usize {
        (h / 3) as usize
    }

    /// Whether the half-edge's face is still there.
    pub fn alive(&self, h: u32) -> bool {
        self.label[Self::face(h)] != GONE
    }

    /// Length of the edge of `h`.
    pub fn length(&self, h: u32) -> f64 {
        let (a, b) = (self.from(h), self.to[h as usize]);
        norm(sub(self.pos[a as usize], self.pos[b as usize]))
    }

    /// Whether the two faces of the edge carry different labels.
    pub fn is_border(&self, h: u32) -> bool {
        self.label[Self::face(h)] != self.label[Self::face(self.twin[h as usize])]
    }

    /// Outgoing half-edges of `v`, once around.
    pub fn ring(&self, v: u32) -> Vec<u32> {
        let start = self.out[v as usize];
        let mut out = Vec::with_capacity(8);
        let mut h = start;
        loop {
            out.push(h);
            h = self.twin[prev(h) as usize];
            if h == start || out.len() > 1000 {
                return out;
            }
        }
    }

    /// Neighbouring vertices of `v`.
    pub fn neighbours(&self, v: u32) -> Vec<u32> {
        self.ring(v)
            .into_iter()
            .map(|h| self.to[h as usize])
            .collect()
    }

    fn set_face(&mut self, f: usize, vertices: [u32; 3]) {
        for k in 0..3 {
            self.to[3 * f + k] = vertices[(k + 1) % 3];
            self.out[vertices[k] as usize] = (3 * f + k) as u32;
        }
    }

    fn link(&mut self, a: u32, b: u32) {
        self.twin[a as usize] = b;
        self.twin[b as usize] = a;
    }

    /// Splits the edge of `h` at `at`; returns the new vertex.
    pub fn split(&mut self, h: u32, at: [f64; 3]) -> u32 {
        let g = self.twin[h as usize];
        let (a, b) = (self.from(h), self.to[h as usize]);
        let (c, d) = (self.to[next(h) as usize], self.to[next(g) as usize]);
        let outer = [
            self.twin[next(h) as usize], // c→b side of b→c
            self.twin[prev(h) as usize], // a→c side of c→a
            self.twin[next(g) as usize], // d→a side of a→d
            self.twin[prev(g) as usize], // b→d side of d→b
        ];
        let m = self.pos.len() as u32;
        self.pos.push(at);
        self.out.push(GONE);
        let (f1, f2) = (Self::face(h), Self::face(g));
        let (f3, f4) = (self.label.len(), self.label.len() + 1);
        self.label.extend([self.label[f1], self.label[f2]]);
        self.to.extend([GONE; 6]);
        self.twin.extend([GONE; 6]);
        self.set_face(f1, [a, m, c]);
        self.set_face(f3, [m, b, c]);
        self.set_face(f2, [b, m, d]);
        self.set_face(f4, [m, a, d]);
        let he = |f: usize, k: usize| (3 * f + k) as u32;
        self.link(he(f1, 0), he(f4, 0));
        self.link(he(f1, 1), he(f3, 2));
        self.link(he(f1, 2), outer[1]);
        self.link(he(f3, 0), he(f2, 0));
        self.link(he(f3, 1), outer[0]);
        self.link(he(f2, 1), he(f4, 2));
        self.link(he(f2, 2), outer[3]);
        self.link(he(f4, 1), outer[2]);
        m
    }

    /// Flips the edge of `h` to join the two opposite vertices.
    pub fn flip(&mut self, h: u32) {
        let g = self.twin[h as usize];
        let (a, b) = (self.from(h), self.to[h as usize]);
        let (c, d) = (self.to[next(h) as usize], self.to[next(g) as usize]);
        let outer = [
            self.twin[next(h) as usize], // of b→c
            self.twin[prev(h) as usize], // of c→a
            self.twin[next(g) as usize], // of a→d
            self.twin[prev(g) as usize], // of d→b
        ];
        let (f1, f2) = (Self::face(h), Self::face(g));
        self.set_face(f1, [a, d, c]);
        self.set_face(f2, [d, b, c]);
        let he = |f: usize, k: usize| (3 * f + k) as u32;
        self.link(he(f1, 0), outer[2]);
        self.link(he(f1, 1), he(f2, 2));
        self.link(he(f1, 2), outer[1]);
        self.link(he(f2, 0), outer[3]);
        self.link(he(f2, 1), outer[0]);
    }

    /// Whether collapsing `h` keeps the mesh manifold: the two end points share exactly the
    /// two opposite vertices as neighbours, and neither opposite vertex drops below valence 3.
    pub fn can_collapse(&self, h: u32) -> bool {
        let g = self.twin[h as usize];
        let (a, b) = (self.from(h), self.to[h as usize]);
        let (c, d) = (self.to[next(h) as usize], self.to[next(g) as usize]);
        if c == d {
            return false;
        }
        let nb = self.neighbours(b);
        let shared = self
            .neighbours(a)
            .into_iter()
            .filter(|v| nb.contains(v))
            .count();
        shared == 2 && self.ring(c).len() > 3 && self.ring(d).len() > 3
    }

    /// Collapses `h` (a → b): `a` disappears into `b`, the edge's two faces with it.
    pub fn collapse(&mut self, h: u32) {
        let g = self.twin[h as usize];
        let (a, b) = (self.from(h), self.to[h as usize]);
        let (c, d) = (self.to[next(h) as usize], self.to[next(g) as usize]);
        let incoming: Vec<u32> = self
            .ring(a)
            .into_iter()
            .map(|e| self.twin[e as usize])
            .collect();
        let (t1, t2) = (self.twin[next(h) as usize], self.twin[prev(h) as usize]);
        let (u1, u2) = (self.twin[next(g) as usize], self.twin[prev(g) as usize]);
        for e in incoming {
            self.to[e as usize] = b;
        }
        self.link(t1, t2);
        self.link(u1, u2);
        for f in [Self::face(h), Self::face(g)] {
            self.label[f] = GONE;
        }
        self.out[a as usize] = GONE;
        self.out[b as usize] = t2;
        self.out[c as usize] = t1;
        self.out[d as usize] = u1;
    }

    /// The live triangles, their labels and the live vertices, renumbered.
    pub fn compact(&self) -> (Vec<[f64; 3]>, Vec<[u32; 3]>, Vec<u32>) {
        let mut map = vec![GONE; self.pos.len()];
        let mut pos = Vec::new();
        for (v, &o) in self.out.iter().enumerate() {
            if o != GONE {
                map[v] = pos.len() as u32;
                pos.push(self.pos[v]);
            }
        }
        let (mut tris, mut labels) = (Vec::new(), Vec::new());
        for (f, &l) in self.label.iter().enumerate() {
            if l != GONE {
                let h = (3 * f) as u32;
                tris.push(
                    [self.from(h), self.to[h as usize], self.to[next(h) as usize]]
                        .map(|v| map[v as usize]),
                );
                labels.push(l);
            }
        }
        (pos, tris, labels)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    impl HalfEdges {
        /// Every live half-edge's twin points back, runs the other way and is alive.
        pub(crate) fn consistent(&self) -> Result<(), String> {
            for h in 0..self.to.len() as u32 {
                if !self.alive(h) {
                    continue;
                }
                let g = self.twin[h as usize];
                if g == GONE || !self.alive(g) || self.twin[g as usize] != h {
                    return Err(format!("half-edge {h}: bad twin {g}"));
                }
                if self.to[g as usize] != self.from(h) || self.to[h as usize] != self.from(g) {
                    return Err(format!(
                        "half-edge {h}: twin runs {} → {}",
                        self.from(g),
                        self.to[g as usize]
                    ));
                }
            }
            for (v, &o) in self.out.iter().enumerate() {
                if o != GONE && (!self.alive(o) || self.from(o) != v as u32) {
                    return Err(format!("vertex {v}: outgoing {o} is not its own"));
                }
            }
            Ok(())
        }
    }

    fn sphere() -> HalfEdges {
        let m = crate::geometry::test_shapes::uv_sphere(1.0, [0.0; 3], 8, 10);
        let pos = m.positions.iter().map(|p| p.map(f64::from)).collect();
        HalfEdges::new(pos, &m.triangles, &vec![0; m.triangles.len()]).unwrap()
    }

    #[test]
    fn splits_flips_and_collapses_keep_the_mesh_closed_and_consistent() {
        let mut he = sphere();
        he.consistent().unwrap();
        let faces = he.label.len();
        let v = he.split(7, [0.0, 0.0, 1.2]);
        he.consistent().unwrap();
        assert_eq!((he.label.len(), he.ring(v).len()), (faces + 2, 4));
        he.flip(20);
        he.consistent().unwrap();
        let mut collapsed = 0;
        for h in 0..he.to.len() as u32 {
            if he.alive(h) && he.can_collapse(h) && collapsed < 5 {
                he.collapse(h);
                he.consistent().unwrap();
                collapsed += 1;
            }
        }
        let (pos, tris, _) = he.compact();
        let mut mesh =
            crate::geometry::TriMesh::new(pos.iter().map(|p| p.map(|c| c as f32)).collect(), tris);
        mesh.normals = None;
        assert!(mesh.edge_report().is_closed_and_oriented());
        assert_eq!(mesh.euler_characteristic(), 2);
        assert_eq!(mesh.triangle_count(), faces + 2 - 2 * collapsed);
    }
}
