//! A small 3-D k-d tree built for the Chamfer distance's access pattern: every point of one
//! set asks for its nearest neighbour in another. Queries are answered a leaf at a time —
//! the [`LEAF`] spatially close points of one leaf of the query set traverse the other tree
//! together, pruned by box-to-box distances, and each visited leaf is scanned with
//! branch-free loops the compiler vectorises. On surface samples this is several times
//! faster than one tree descent per point.

/// Points per leaf (and per query block).
pub const LEAF: usize = 32;

const NO_CHILD: u32 = u32::MAX;

#[derive(Debug, Clone, Copy)]
struct Node {
    min: [f32; 3],
    max: [f32; 3],
    /// Children, or `NO_CHILD` for a leaf.
    children: [u32; 2],
    /// Range of `points` under this node.
    start: u32,
    end: u32,
}

/// Points reordered so every node covers a contiguous range, with node bounding boxes.
#[derive(Debug, Clone, Default)]
pub struct PointTree {
    points: Vec<[f32; 3]>,
    xs: Vec<f32>,
    ys: Vec<f32>,
    zs: Vec<f32>,
    nodes: Vec<Node>,
    leaves: Vec<u32>,
}

impl PointTree {
    /// Builds the tree (median splits along the widest box axis).
    pub fn new(points: &[[f32; 3]]) -> Self {
        let mut tree = Self {
            points: points.to_vec(),
            ..Self::default()
        };
        if !points.is_empty() {
            tree.build(0, points.len());
        }
        tree.xs = tree.points.iter().map(|p| p[0]).collect();
        tree.ys = tree.points.iter().map(|p| p[1]).collect();
        tree.zs = tree.points.iter().map(|p| p[2]).collect();
        tree
    }

    fn build(&mut self, start: usize, end: usize) -> u32 {
        let slice = &mut self.points[start..end];
        let (mut min, mut max) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for p in slice.iter() {
            for k in 0..3 {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
            }
        }
        let id = self.nodes.len() as u32;
        self.nodes.push(Node {
            min,
            max,
            children: [NO_CHILD; 2],
            start: start as u32,
            end: end as u32,
        });
        if end - start <= LEAF {
            self.leaves.push(id);
            return id;
        }
        let axis = (0..3)
            .max_by(|&a, &b| (max[a] - min[a]).total_cmp(&(max[b] - min[b])))
            .unwrap_or(0);
        let mid = (end - start) / 2;
        slice.select_nth_unstable_by(mid, |a, b| a[axis].total_cmp(&b[axis]));
        let left = self.build(start, start + mid);
        let right = self.build(start + mid, end);
        self.nodes[id as usize].children = [left, right];
        id
    }

    /// The points in tree order.
    pub fn points(&self) -> &[[f32; 3]] {
        &self.points
    }

    /// Number of leaves; leaf `l` covers [`Self::leaf_points`]`(l)`.
    pub fn leaf_count(&self) -> usize {
        self.leaves.len()
    }

    /// The points of leaf `l` (at most [`LEAF`], spatially compact).
    pub fn leaf_points(&self, l: usize) -> &[[f32; 3]] {
        let n = &self.nodes[self.leaves[l] as usize];
        &self.points[n.start as usize..n.end as usize]
    }

    /// Squared distance (f64, from the f32 coordinates) from `q` to its nearest point.
    pub fn nearest_squared(&self, q: &[f32; 3]) -> f64 {
        let mut block = [0.0; 1];
        self.nearest_block(std::slice::from_ref(q), &mut block);
        block[0]
    }

    /// For each of up to [`LEAF`] `queries`, the squared distance to its nearest point,
    /// written to `out` (∞ when the tree is empty). Neighbours are selected in f32 and
    /// their distances recomputed exactly in f64.
    pub fn nearest_block(&self, queries: &[[f32; 3]], out: &mut [f64]) {
        let n = queries.len();
        assert!(
            n <= LEAF && out.len() >= n,
            "nearest_block takes at most {LEAF} queries"
        );
        if self.nodes.is_empty() {
            out[..n].fill(f64::INFINITY);
            return;
        }
        // Unused lanes repeat the first query so they never loosen the pruning bound.
        let lane = |k: usize| {
            std::array::from_fn::<f32, LEAF, _>(|i| queries[if i < n { i } else { 0 }][k])
        };
        let (qx, qy, qz) = (lane(0), lane(1), lane(2));
        let (mut qmin, mut qmax) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for q in queries {
            for k in 0..3 {
                qmin[k] = qmin[k].min(q[k]);
                qmax[k] = qmax[k].max(q[k]);
            }
        }
        let mut best = [f32::INFINITY; LEAF];
        let mut best_idx = [0u32; LEAF];
        let mut worst = f32::INFINITY;
        let mut stack: Vec<(u32, f32)> = Vec::with_capacity(64);
        stack.push((0, 0.0));
        while let Some((id, lower)) = stack.pop() {
            if lower > worst {
                continue;
            }
            let node = &self.nodes[id as usize];
            if node.children[0] == NO_CHILD {
                for j in node.start as usize..node.end as usize {
                    let (px, py, pz) = (self.xs[j], self.ys[j], self.zs[j]);
                    for i in 0..LEAF {
                        let d = (qx[i] - px) * (qx[i] - px)
                            + (qy[i] - py) * (qy[i] - py)
                            + (qz[i] - pz) * (qz[i] - pz);
                        let closer = d < best[i];
                        best[i] = if closer { d } else { best[i] };
                        best_idx[i] = if closer { j as u32 } else { best_idx[i] };
                    }
                }
                // A little slack covers f32 rounding in the box bound.
                worst = best.iter().fold(0.0f32, |a, &b| a.max(b)) * (1.0 + 1e-5);
                continue;
            }
            let [a, b] = node
                .children
                .map(|c| (c, box_distance(&self.nodes[c as usize], qmin, qmax)));
            let (near, far) = if a.1 <= b.1 { (a, b) } else { (b, a) };
            stack.push(far);
            stack.push(near);
        }
        for i in 0..n {
            let p = self.points[best_idx[i] as usize];
            out[i] = (0..3)
                .map(|k| (f64::from(queries[i][k]) - f64::from(p[k])).powi(2))
                .sum();
        }
    }
}

/// Squared distance between a node's box and the query box (0 when they overlap).
fn box_distance(node: &Node, qmin: [f32; 3], qmax: [f32; 3]) -> f32 {
    (0..3)
        .map(|k| {
            let gap = (node.min[k] - qmax[k]).max(qmin[k] - node.max[k]).max(0.0);
            gap * gap
        })
        .sum()
}
