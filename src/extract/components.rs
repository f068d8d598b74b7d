//! Connected components of a mesh and removal of small ones (floaters: the specks a neural
//! field leaves away from the shape).

use crate::geometry::TriMesh;

/// Component of every triangle, numbered 0.. in order of first appearance (triangles are
/// connected when they share a vertex).
pub fn triangle_components(mesh: &TriMesh) -> (Vec<u32>, usize) {
    let mut parent: Vec<u32> = (0..mesh.positions.len() as u32).collect();
    fn find(parent: &mut [u32], mut v: u32) -> u32 {
        while parent[v as usize] != v {
            let up = parent[parent[v as usize] as usize];
            parent[v as usize] = up;
            v = up;
        }
        v
    }
    for t in &mesh.triangles {
        let a = find(&mut parent, t[0]);
        for &other in &t[1..] {
            let b = find(&mut parent, other);
            let a = find(&mut parent, a);
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    let mut label = vec![u32::MAX; parent.len()];
    let mut count = 0;
    let components = mesh
        .triangles
        .iter()
        .map(|t| {
            let root = find(&mut parent, t[0]) as usize;
            if label[root] == u32::MAX {
                label[root] = count;
                count += 1;
            }
            label[root]
        })
        .collect();
    (components, count as usize)
}

/// Drops every component with fewer triangles than `min_fraction` × the largest component's
/// (0 keeps everything) and the vertices only they used. Whole components go, so a closed
/// mesh stays closed. Returns the cleaned mesh and the number of components removed.
pub fn remove_small_components(mesh: TriMesh, min_fraction: f64) -> (TriMesh, usize) {
    if min_fraction <= 0.0 {
        return (mesh, 0);
    }
    let (component, count) = triangle_components(&mesh);
    let mut sizes = vec![0usize; count];
    for &c in &component {
        sizes[c as usize] += 1;
    }
    let largest = sizes.iter().copied().max().unwrap_or(0);
    let keep: Vec<bool> = sizes
        .iter()
        .map(|&s| s as f64 >= min_fraction * largest as f64)
        .collect();
    let removed = keep.iter().filter(|&&k| !k).count();
    if removed == 0 {
        return (mesh, 0);
    }
    let mut new_index = vec![u32::MAX; mesh.positions.len()];
    let mut out = TriMesh::default();
    let mut normals = Vec::new();
    for (t, &c) in mesh.triangles.iter().zip(&component) {
        if !keep[c as usize] {
            continue;
        }
        out.triangles.push(t.map(|v| {
            if new_index[v as usize] == u32::MAX {
                new_index[v as usize] = out.positions.len() as u32;
                out.positions.push(mesh.positions[v as usize]);
                if let Some(n) = &mesh.normals {
                    normals.push(n[v as usize]);
                }
            }
            new_index[v as usize]
        }));
    }
    if mesh.normals.is_some() {
        out.normals = Some(normals);
    }
    (out, removed)
}
