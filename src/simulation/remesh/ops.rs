//! The remeshing passes over a [`HalfEdges`] mesh, with the constraints that keep faces and
//! rims: every vertex knows whether it lies inside one face, on the border between two, or
//! where three or more meet (a corner, never moved or removed).

use std::collections::HashMap;

use super::halfedge::{GONE, HalfEdges, next};
use super::project::{TriangleTree, closest_on_curve};
use crate::geometry::mesh::{cross, dot, normalized, sub};
use crate::simulation::{LabelledMesh, SimulationError};

type P = [f64; 3];

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// Inside the face with this label.
    Inside(u32),
    /// On the border between the two labels (smaller first).
    Border(u32, u32),
    /// Where three or more faces meet, or on a border that branches.
    Corner,
}

/// The remeshing state: the mesh, what each vertex may do and the input to project onto.
pub(super) struct Remesher {
    he: HalfEdges,
    kind: Vec<Kind>,
    target: f64,
    faces: HashMap<u32, TriangleTree>,
    borders: HashMap<(u32, u32), Vec<(P, P)>>,
}

impl Remesher {
    pub(super) fn new(mesh: &LabelledMesh, target: f64) -> Result<Self, SimulationError> {
        let pos: Vec<P> = mesh
            .mesh
            .positions
            .iter()
            .map(|p| p.map(f64::from))
            .collect();
        let he =
            HalfEdges::new(pos.clone(), &mesh.mesh.triangles, &mesh.face_ids).ok_or_else(|| {
                SimulationError::Topology("only a closed manifold surface can be remeshed".into())
            })?;
        let mut corners: HashMap<u32, Vec<[P; 3]>> = HashMap::new();
        for (t, &l) in mesh.face_ids.iter().enumerate() {
            corners.entry(l).or_default().push(mesh.mesh.corners(t));
        }
        let faces = corners
            .into_iter()
            .map(|(l, c)| (l, TriangleTree::new(c)))
            .collect();
        let mut borders: HashMap<(u32, u32), Vec<(P, P)>> = HashMap::new();
        for h in 0..he.to.len() as u32 {
            let g = he.twin[h as usize];
            if h < g && he.is_border(h) {
                let key = pair(he.label[HalfEdges::face(h)], he.label[HalfEdges::face(g)]);
                let seg = (pos[he.from(h) as usize], pos[he.to[h as usize] as usize]);
                borders.entry(key).or_default().push(seg);
            }
        }
        let kind = (0..he.pos.len() as u32).map(|v| classify(&he, v)).collect();
        Ok(Self {
            he,
            kind,
            target,
            faces,
            borders,
        })
    }

    /// Runs the passes; returns positions, triangles and labels.
    pub(super) fn run(mut self, iterations: usize) -> (Vec<P>, Vec<[u32; 3]>, Vec<u32>) {
        for _ in 0..iterations {
            self.split_long();
            self.collapse_short();
            self.flip_to_valence();
            self.relax();
        }
        self.he.compact()
    }

    fn project(&self, kind: Kind, p: P) -> P {
        let found = match kind {
            Kind::Inside(l) => self.faces.get(&l).and_then(|t| t.closest(p)),
            Kind::Border(a, b) => self
                .borders
                .get(&(a, b))
                .and_then(|s| closest_on_curve(p, s)),
            Kind::Corner => None,
        };
        found.map_or(p, |(q, _)| q)
    }

    fn edge_kind(&self, h: u32) -> Kind {
        let (f, g) = (
            HalfEdges::face(h),
            HalfEdges::face(self.he.twin[h as usize]),
        );
        let (a, b) = (self.he.label[f], self.he.label[g]);
        if a == b {
            Kind::Inside(a)
        } else {
            pair(a, b).into()
        }
    }

    /// Splits the edges longer than 4/3·L at their (projected) midpoints, longest first,
    /// once per pass as in Botsch & Kobbelt: splitting again before the flips and the
    /// relaxation would bisect the same slivers over and over.
    fn split_long(&mut self) {
        let high = 4.0 / 3.0 * self.target;
        let mut long: Vec<(f64, u32)> = (0..self.he.to.len() as u32)
            .filter(|&h| self.he.alive(h) && h < self.he.twin[h as usize])
            .map(|h| (self.he.length(h), h))
            .filter(|&(l, _)| l > high)
            .collect();
        long.sort_by(|x, y| y.0.total_cmp(&x.0));
        let mut touched = vec![false; self.he.label.len()];
        for (_, h) in long {
            let g = self.he.twin[h as usize];
            let (f, k) = (HalfEdges::face(h), HalfEdges::face(g));
            // A face already split this pass has new edges: leave it to the next pass.
            let done = |x: usize| touched.get(x).copied().unwrap_or(true);
            if done(f) || done(k) {
                continue;
            }
            touched[f] = true;
            touched[k] = true;
            let (a, b) = (self.he.from(h), self.he.to[h as usize]);
            let (pa, pb) = (self.he.pos[a as usize], self.he.pos[b as usize]);
            let kind = self.edge_kind(h);
            let mid = self.project(kind, std::array::from_fn(|i| 0.5 * (pa[i] + pb[i])));
            self.he.split(h, mid);
            self.kind.push(kind);
        }
    }

    /// Whether `a` may disappear into `b` along `h` without moving a face's border.
    fn may_merge(&self, h: u32) -> bool {
        let (a, b) = (self.he.from(h), self.he.to[h as usize]);
        match self.kind[a as usize] {
            Kind::Corner => false,
            Kind::Inside(_) => true,
            Kind::Border(x, y) => {
                self.he.is_border(h) && matches!(self.kind[b as usize], Kind::Corner)
                    || self.he.is_border(h) && self.kind[b as usize] == Kind::Border(x, y)
            }
        }
    }

    /// Whether moving `a` onto `b` keeps every remaining face around `a` unflipped and its
    /// edges shorter than the split threshold.
    fn collapse_is_fair(&self, h: u32) -> bool {
        let (a, b) = (self.he.from(h), self.he.to[h as usize]);
        let high = 4.0 / 3.0 * self.target;
        let pb = self.he.pos[b as usize];
        for e in self.he.ring(a) {
            let (x, y) = (self.he.to[e as usize], self.he.to[next(e) as usize]);
            if x == b || y == b {
                continue;
            }
            let p = |v: u32| self.he.pos[v as usize];
            if crate::geometry::mesh::norm(sub(p(x), pb)) > high {
                return false;
            }
            let before = normalized(cross(sub(p(x), p(a)), sub(p(y), p(a))));
            let after = cross(sub(p(x), pb), sub(p(y), pb));
            if dot(before, normalized(after)) < 0.5 {
                return false;
            }
        }
        true
    }

    fn collapse_short(&mut self) {
        let low = 0.8 * self.target;
        for h in 0..self.he.to.len() as u32 {
            if !self.he.alive(h) || self.he.length(h) >= low {
                continue;
            }
            let g = self.he.twin[h as usize];
            let candidate = [h, g].into_iter().find(|&e| {
                self.may_merge(e) && self.he.can_collapse(e) && self.collapse_is_fair(e)
            });
            if let Some(e) = candidate {
                self.he.collapse(e);
            }
        }
    }

    fn valence(&self, v: u32) -> i64 {
        self.he.ring(v).len() as i64
    }

    fn flip_to_valence(&mut self) {
        for h in 0..self.he.to.len() as u32 {
            let g = self.he.twin[h as usize];
            if !self.he.alive(h) || h > g || self.he.is_border(h) {
                continue;
            }
            let (a, b) = (self.he.from(h), self.he.to[h as usize]);
            let (c, d) = (self.he.to[next(h) as usize], self.he.to[next(g) as usize]);
            let [va, vb, vc, vd] = [a, b, c, d].map(|v| self.valence(v));
            if va <= 3 || vb <= 3 || self.he.neighbours(c).contains(&d) {
                continue;
            }
            let dev = |x: i64| (x - 6).abs();
            let before = dev(va) + dev(vb) + dev(vc) + dev(vd);
            let after = dev(va - 1) + dev(vb - 1) + dev(vc + 1) + dev(vd + 1);
            if after < before && self.flip_is_fair(a, b, c, d) {
                self.he.flip(h);
            }
        }
    }

    /// The flipped pair (a, d, c), (d, b, c) must face like the pair it replaces.
    fn flip_is_fair(&self, a: u32, b: u32, c: u32, d: u32) -> bool {
        let p = |v: u32| self.he.pos[v as usize];
        let n = |x: u32, y: u32, z: u32| cross(sub(p(y), p(x)), sub(p(z), p(x)));
        let old = normalized(std::array::from_fn(|i| n(a, b, c)[i] + n(b, a, d)[i]));
        [n(a, d, c), n(d, b, c)]
            .iter()
            .all(|m| dot(normalized(*m), old) > 0.5)
    }

    /// Tangential relaxation towards the neighbours' centroid, then back onto the input.
    fn relax(&mut self) {
        let moved: Vec<Option<P>> = (0..self.he.pos.len() as u32)
            .map(|v| self.relaxed(v))
            .collect();
        for (v, p) in moved.into_iter().enumerate() {
            if let Some(p) = p {
                self.he.pos[v] = p;
            }
        }
    }

    fn relaxed(&self, v: u32) -> Option<P> {
        if self.he.out[v as usize] == GONE {
            return None;
        }
        let kind = self.kind[v as usize];
        let ring = self.he.ring(v);
        let p = self.he.pos[v as usize];
        let along: Vec<u32> = match kind {
            Kind::Corner => return None,
            Kind::Inside(_) => ring.iter().map(|&e| self.he.to[e as usize]).collect(),
            Kind::Border(..) => ring
                .iter()
                .filter(|&&e| self.he.is_border(e))
                .map(|&e| self.he.to[e as usize])
                .collect(),
        };
        let n = along.len().max(1) as f64;
        let centre: P = std::array::from_fn(|i| {
            along
                .iter()
                .map(|&u| self.he.pos[u as usize][i])
                .sum::<f64>()
                / n
        });
        let step = sub(centre, p);
        let target = if let Kind::Inside(_) = kind {
            let mut normal = [0.0; 3];
            for &e in &ring {
                let (x, y) = (
                    self.he.pos[self.he.to[e as usize] as usize],
                    self.he.pos[self.he.to[next(e) as usize] as usize],
                );
                let f = cross(sub(x, p), sub(y, p));
                normal = std::array::from_fn(|i| normal[i] + f[i]);
            }
            let normal = normalized(normal);
            let off = dot(step, normal);
            std::array::from_fn(|i| p[i] + step[i] - off * normal[i])
        } else {
            centre
        };
        Some(self.project(kind, target))
    }
}

fn pair(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

impl From<(u32, u32)> for Kind {
    fn from((a, b): (u32, u32)) -> Self {
        Kind::Border(a, b)
    }
}

fn classify(he: &HalfEdges, v: u32) -> Kind {
    if he.out[v as usize] == GONE {
        return Kind::Corner;
    }
    let ring = he.ring(v);
    let mut labels: Vec<u32> = ring.iter().map(|&e| he.label[HalfEdges::face(e)]).collect();
    labels.sort_unstable();
    labels.dedup();
    let borders = ring.iter().filter(|&&e| he.is_border(e)).count();
    match labels[..] {
        [l] => Kind::Inside(l),
        [a, b] if borders == 2 => Kind::Border(a, b),
        _ => Kind::Corner,
    }
}
