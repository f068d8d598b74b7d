//! A vessel surface prepared for repeated queries: plane sections around a centre point,
//! ray hits along the centreline direction, and the mesh's open ends.

use std::collections::HashMap;

use super::MeasureError;
use super::sections::{
    Contour, PlaneFrame, contours, convex_hull, feret_diameters, polygon_area_centroid,
    polygon_contains,
};
use crate::geometry::TriMesh;
use crate::geometry::mesh::{cross, dot, norm, sub};

/// Largest |cos| between a cutting plane's normal and a crossed triangle's normal for the
/// loop to count as a wall section: the wall may slope up to about 70° from the axis, and a
/// plane tilted less than 18° against an end cap is caught.
pub const FACING_LIMIT: f64 = 0.85;

/// An open end of the surface (a boundary loop), summarised for end-point search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OpenEnd {
    /// Length-weighted centroid of the boundary loop.
    pub centroid: [f64; 3],
    /// Mean distance of the loop's vertices from the centroid.
    pub radius: f64,
    /// Unit normal of the loop's best-fit plane (Newell's method), either orientation.
    pub normal: [f64; 3],
}

/// The closed section loop chosen around a centre point, in its plane's coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct SectionLoop {
    /// The cutting plane (origin = the queried centre).
    pub frame: PlaneFrame,
    /// Loop points in plane coordinates.
    pub points: Vec<[f64; 2]>,
    /// Enclosed area, mm².
    pub area: f64,
    /// Area centroid in 3-D.
    pub centroid: [f64; 3],
    /// Largest |cos| between the plane normal and the normal of a crossed triangle: near 1
    /// when the loop runs over a surface facing along the centreline (an end cap, the rim of
    /// a branch ostium) rather than along the vessel wall.
    pub facing: f64,
}

impl SectionLoop {
    /// Maximal and minimal Feret diameters of the loop.
    pub fn feret(&self) -> (f64, f64) {
        feret_diameters(&convex_hull(&self.points))
    }

    /// Whether the loop is the main lumen alone rather than a lumen merged with a branch
    /// ostium (maximal Feret diameter at most [`super::SINGLE_LUMEN_MAX_ASPECT`] × the
    /// minimal one).
    pub fn is_single_lumen(&self) -> bool {
        let (max, min) = self.feret();
        max <= super::SINGLE_LUMEN_MAX_ASPECT * min
    }

    /// Largest distance from the in-plane point `q` to the loop.
    pub fn max_distance_from(&self, q: [f64; 2]) -> f64 {
        self.points
            .iter()
            .map(|p| (p[0] - q[0]).hypot(p[1] - q[1]))
            .fold(0.0, f64::max)
    }
}

/// Positions in f64 and per-triangle bounding spheres for fast plane rejection.
#[derive(Debug, Clone)]
pub struct Surface {
    /// Vertex positions.
    pub positions: Vec<[f64; 3]>,
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
    centres: Vec<[f64; 3]>,
    radii: Vec<f64>,
    normals: Vec<[f64; 3]>,
    /// Boundary loops of an open surface.
    pub open_ends: Vec<OpenEnd>,
}

impl Surface {
    /// Validates and prepares `mesh`.
    pub fn new(mesh: &TriMesh) -> Result<Self, MeasureError> {
        mesh.validate()?;
        let positions: Vec<[f64; 3]> = mesh.positions.iter().map(|p| p.map(f64::from)).collect();
        let (mut centres, mut radii) = (Vec::new(), Vec::new());
        for t in &mesh.triangles {
            let c: [f64; 3] = std::array::from_fn(|i| {
                t.iter().map(|&v| positions[v as usize][i]).sum::<f64>() / 3.0
            });
            let r = t
                .iter()
                .map(|&v| norm(sub(positions[v as usize], c)))
                .fold(0.0, f64::max);
            centres.push(c);
            radii.push(r);
        }
        let normals = mesh
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| positions[v as usize]);
                crate::geometry::mesh::normalized(cross(sub(b, a), sub(c, a)))
            })
            .collect();
        let open_ends = boundary_loops(&mesh.triangles, &positions);
        Ok(Self {
            positions,
            triangles: mesh.triangles.clone(),
            centres,
            radii,
            normals,
            open_ends,
        })
    }

    /// All connected curves where the plane cuts the surface.
    pub fn slice(&self, frame: &PlaneFrame) -> Vec<Contour> {
        let crossing = (0..self.triangles.len())
            .filter(|&t| frame.height(self.centres[t]).abs() <= self.radii[t])
            .map(|t| (t, self.triangles[t]));
        contours(crossing, &self.positions, |v| {
            frame.height(self.positions[v as usize])
        })
    }

    /// The closed section loop of the plane through `centre` with normal `normal` that
    /// surrounds `centre` (the innermost one if several do). When none does, the nearest
    /// closed loop is accepted if `centre` lies within its equivalent radius of it; otherwise
    /// there is no section (the centre is outside the lumen).
    pub fn section_at(&self, centre: [f64; 3], normal: [f64; 3]) -> Option<SectionLoop> {
        let frame = PlaneFrame::new(centre, normal);
        let mut best: Option<(bool, f64, SectionLoop)> = None;
        for contour in self.slice(&frame) {
            if !contour.closed || contour.points.len() < 3 {
                continue;
            }
            let points: Vec<[f64; 2]> = contour.points.iter().map(|&p| frame.project(p)).collect();
            let (area, c2) = polygon_area_centroid(&points);
            let area = area.abs();
            let inside = polygon_contains(&points, [0.0, 0.0]);
            let gap = if inside {
                area
            } else {
                let nearest = points
                    .iter()
                    .map(|p| p[0].hypot(p[1]))
                    .fold(f64::INFINITY, f64::min);
                if nearest > (area / std::f64::consts::PI).sqrt() {
                    continue;
                }
                nearest
            };
            let better = match &best {
                None => true,
                Some((b_inside, b_gap, _)) => {
                    (inside && !b_inside) || (inside == *b_inside && gap < *b_gap)
                }
            };
            if better {
                let centroid = frame.lift(c2);
                let facing = contour
                    .faces
                    .iter()
                    .map(|&f| dot(self.normals[f], frame.normal).abs())
                    .fold(0.0, f64::max);
                best = Some((
                    inside,
                    gap,
                    SectionLoop {
                        frame,
                        points,
                        area,
                        centroid,
                        facing,
                    },
                ));
            }
        }
        best.map(|(_, _, s)| s)
    }

    /// Distance along the ray from `origin` in unit direction `dir` to the first triangle hit.
    pub fn ray_hit(&self, origin: [f64; 3], dir: [f64; 3]) -> Option<f64> {
        let mut best: Option<f64> = None;
        for t in &self.triangles {
            let [a, b, c] = t.map(|v| self.positions[v as usize]);
            let (e1, e2) = (sub(b, a), sub(c, a));
            let p = cross(dir, e2);
            let det = dot(e1, p);
            if det.abs() < 1e-14 {
                continue;
            }
            let s = sub(origin, a);
            let u = dot(s, p) / det;
            if !(0.0..=1.0).contains(&u) {
                continue;
            }
            let q = cross(s, e1);
            let v = dot(dir, q) / det;
            if v < 0.0 || u + v > 1.0 {
                continue;
            }
            let dist = dot(e2, q) / det;
            if dist > 1e-9 && best.is_none_or(|b| dist < b) {
                best = Some(dist);
            }
        }
        best
    }

    /// [`Surface::section_at`], rejecting loops that run over a surface facing along the
    /// centreline (|cos| above [`FACING_LIMIT`]: the loop cuts an end cap or the rim of a side
    /// branch) and loops whose centroid lies farther from `centre` than their equivalent
    /// radius (the plane runs along the vessel rather than across it).
    pub fn wall_section_at(&self, centre: [f64; 3], normal: [f64; 3]) -> Option<SectionLoop> {
        self.section_at(centre, normal).filter(|s| {
            let radius = (s.area / std::f64::consts::PI).sqrt();
            s.facing <= FACING_LIMIT && norm(sub(s.centroid, centre)) <= radius
        })
    }

    /// Distance within `max` along the unit direction `dir` from `from` at which a path
    /// leaves the vessel: the first surface hit (a cap or the wall), or the crossing of an
    /// open end's plane inside that end's loop, whichever comes first.
    pub fn first_exit(&self, from: [f64; 3], dir: [f64; 3], max: f64) -> Option<f64> {
        let hit = self.ray_hit(from, dir).filter(|&d| d <= max);
        let open = self.open_ends.iter().filter_map(|end| {
            let facing = dot(dir, end.normal);
            if facing.abs() < 1e-6 {
                return None;
            }
            let d = dot(sub(end.centroid, from), end.normal) / facing;
            let at: [f64; 3] = std::array::from_fn(|i| from[i] + d * dir[i]);
            ((0.0..=max).contains(&d) && norm(sub(at, end.centroid)) < 1.5 * end.radius)
                .then_some(d)
        });
        hit.into_iter().chain(open).min_by(f64::total_cmp)
    }
}

/// Boundary loops (edges used by one triangle), chained vertex to vertex.
fn boundary_loops(triangles: &[[u32; 3]], positions: &[[f64; 3]]) -> Vec<OpenEnd> {
    let mut uses: HashMap<(u32, u32), u32> = HashMap::new();
    for t in triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            *uses.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let mut next: HashMap<u32, Vec<u32>> = HashMap::new();
    for (&(a, b), &n) in &uses {
        if n == 1 {
            next.entry(a).or_default().push(b);
            next.entry(b).or_default().push(a);
        }
    }
    let mut starts: Vec<u32> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut seen = std::collections::HashSet::new();
    let mut ends = Vec::new();
    for start in starts {
        if !seen.insert(start) {
            continue;
        }
        let mut chain = vec![start];
        let (mut prev, mut cur) = (u32::MAX, start);
        while let Some(&n) = next[&cur]
            .iter()
            .find(|&&n| n != prev && !seen.contains(&n))
        {
            seen.insert(n);
            chain.push(n);
            (prev, cur) = (cur, n);
        }
        if chain.len() < 3 {
            continue;
        }
        let contour = Contour {
            points: chain.iter().map(|&v| positions[v as usize]).collect(),
            closed: true,
            faces: Vec::new(),
        };
        let centroid = contour.centroid();
        let radius = contour
            .points
            .iter()
            .map(|&p| norm(sub(p, centroid)))
            .sum::<f64>()
            / contour.points.len() as f64;
        let n = contour.points.len();
        let newell = (0..n).fold([0.0; 3], |acc, i| {
            let c = cross(
                sub(contour.points[i], centroid),
                sub(contour.points[(i + 1) % n], centroid),
            );
            std::array::from_fn(|k| acc[k] + c[k])
        });
        ends.push(OpenEnd {
            centroid,
            radius,
            normal: crate::geometry::mesh::normalized(newell),
        });
    }
    ends
}
