//! Triangle-mesh screens from OBJ files, with a bounding-volume hierarchy (median split on the
//! longest axis, up to four triangles a leaf) so that a 4K warp costs O(log n) per pixel.

use super::{EPS, Hit, classify};
use crate::error::{Error, Result};
use glam::DVec3;
use std::path::Path;

/// A triangle mesh screen in world coordinates (metres), with its bounding-volume hierarchy.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    tris: Vec<[DVec3; 3]>,
    /// Each triangle's index in the order it was given (the tree reorders them).
    ids: Vec<u32>,
    nodes: Vec<Node>,
    digest: u64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Node {
    lo: DVec3,
    hi: DVec3,
    /// Leaf: first triangle and count; inner: index of the left child (the right follows its
    /// subtree) and 0.
    first: usize,
    count: usize,
    right: usize,
}

const LEAF: usize = 4;

impl Mesh {
    /// A mesh of the given triangles (vertices in metres), its tree built; refused when empty or
    /// when a vertex is not finite.
    pub fn new(tris: Vec<[DVec3; 3]>) -> Result<Self> {
        Mesh::check(&tris)?;
        let digest = {
            use std::hash::{Hash, Hasher};
            let mut h = std::collections::hash_map::DefaultHasher::new();
            for v in tris.iter().flatten() {
                v.to_array().map(f64::to_bits).hash(&mut h);
            }
            h.finish()
        };
        let mut m = Mesh {
            ids: (0..tris.len() as u32).collect(),
            tris,
            nodes: Vec::new(),
            digest,
        };
        let n = m.tris.len();
        m.build(0, n);
        Ok(m)
    }

    /// What [`Mesh::new`] refuses, without building anything: no triangles, or a vertex that is
    /// not finite.
    pub fn check(tris: &[[DVec3; 3]]) -> Result<()> {
        if tris.is_empty() {
            return Err(Error::invalid("mesh", "has no triangles"));
        }
        if tris.iter().flatten().any(|v| !v.is_finite()) {
            return Err(Error::invalid("mesh", "has a non-finite vertex"));
        }
        Ok(())
    }

    /// An OBJ file as a mesh (see [`read_obj_triangles`]).
    pub fn read_obj(path: &Path) -> Result<Self> {
        Mesh::read_obj_within(path, u64::MAX)
    }

    /// [`Mesh::read_obj`], refused before the triangles are built when reading and indexing
    /// them would take more than `budget` bytes (see
    /// [`crate::limits::MESH_BYTES_PER_TRIANGLE`]): a small OBJ of many faces sharing a few
    /// vertices takes far more memory than its file.
    pub fn read_obj_within(path: &Path, budget: u64) -> Result<Self> {
        let text = read_obj_text(path)?;
        let triangles = count_obj_triangles(&text);
        let need = memory_of(triangles);
        if need > budget {
            return Err(Error::file(
                path,
                format!(
                    "its {triangles} triangles need {} MiB to read and index, above the {} MiB \
                     the memory budget leaves after the channels' warps",
                    need >> 20,
                    budget >> 20
                ),
            ));
        }
        let tris = parse_obj_triangles(&text).map_err(|e| Error::file(path, e.reason()))?;
        Mesh::new(tris).map_err(|e| Error::file(path, e))
    }

    /// A hash of the triangles as given: two meshes of one name but different shapes differ
    /// in it, so what is computed from a mesh can be keyed by it.
    pub fn digest(&self) -> u64 {
        self.digest
    }

    /// The memory this mesh is counted as in a memory budget.
    pub fn memory_bytes(&self) -> u64 {
        memory_of(self.tris.len())
    }

    /// The triangles in the tree's order.
    pub fn triangles(&self) -> &[[DVec3; 3]] {
        &self.tris
    }

    fn bounds(tris: &[[DVec3; 3]]) -> (DVec3, DVec3) {
        let mut lo = DVec3::splat(f64::MAX);
        let mut hi = DVec3::splat(f64::MIN);
        for v in tris.iter().flatten() {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
        (lo, hi)
    }

    fn build(&mut self, first: usize, count: usize) -> usize {
        let (lo, hi) = Self::bounds(&self.tris[first..first + count]);
        let at = self.nodes.len();
        self.nodes.push(Node {
            lo,
            hi,
            first,
            count,
            right: 0,
        });
        if count > LEAF {
            let axis = (hi - lo).max_position();
            let centroid = |t: &[DVec3; 3]| (t[0][axis] + t[1][axis] + t[2][axis]) / 3.0;
            let mut order: Vec<usize> = (first..first + count).collect();
            order.sort_by(|&a, &b| centroid(&self.tris[a]).total_cmp(&centroid(&self.tris[b])));
            let tris: Vec<_> = order.iter().map(|&k| self.tris[k]).collect();
            let ids: Vec<_> = order.iter().map(|&k| self.ids[k]).collect();
            self.tris[first..first + count].copy_from_slice(&tris);
            self.ids[first..first + count].copy_from_slice(&ids);
            let half = count / 2;
            self.build(first, half);
            let right = self.build(first + half, count - half);
            self.nodes[at].count = 0;
            self.nodes[at].right = right;
        }
        at
    }

    /// Entry distance of the ray into node n's box, if it enters before `limit`.
    fn enter(&self, n: usize, origin: DVec3, inv: DVec3, limit: f64) -> Option<f64> {
        let node = &self.nodes[n];
        let t0 = (node.lo - origin) * inv;
        let t1 = (node.hi - origin) * inv;
        let near = t0.min(t1).max_element();
        let far = t0.max(t1).min_element();
        (far >= near.max(EPS) && near <= limit).then_some(near)
    }

    /// What the unit ray from `origin` in direction `dir` meets at the nearest triangle: a lit
    /// point, a grazing one, or a miss.
    pub fn intersect(&self, origin: DVec3, dir: DVec3) -> Hit {
        match self.first_hit(origin, dir) {
            Some((t, _, n)) => classify(origin, dir, t, n),
            None => Hit::Miss,
        }
    }

    /// The nearest triangle the ray meets: distance, the triangle's index as given to
    /// [`Mesh::new`], and its unit normal (either side).
    pub fn first_hit(&self, origin: DVec3, dir: DVec3) -> Option<(f64, u32, DVec3)> {
        let inv = dir.recip();
        let mut best: Option<(f64, usize)> = None;
        // A fixed stack: a median-split tree of up to 4 billion triangles is under 64 deep.
        let mut stack = [0usize; 64];
        let mut top = 0;
        if self.enter(0, origin, inv, f64::MAX).is_some() {
            top = 1;
        }
        while top > 0 {
            top -= 1;
            let n = stack[top];
            let limit = best.map_or(f64::MAX, |b| b.0);
            if self.enter(n, origin, inv, limit).is_none() {
                continue;
            }
            let node = self.nodes[n];
            if node.count > 0 {
                for k in node.first..node.first + node.count {
                    match moller_trumbore(origin, dir, &self.tris[k]) {
                        Some(d) if d > EPS && d < best.map_or(f64::MAX, |b| b.0) => {
                            best = Some((d, k));
                        }
                        _ => {}
                    }
                }
                continue;
            }
            // The nearer child goes on top, so the first hit found prunes the farther one.
            let (l, r) = (n + 1, node.right);
            let (dl, dr) = (
                self.enter(l, origin, inv, limit),
                self.enter(r, origin, inv, limit),
            );
            let mut push = |c: usize| {
                stack[top] = c;
                top += 1;
            };
            match (dl, dr) {
                (Some(a), Some(b)) if a <= b => {
                    push(r);
                    push(l);
                }
                (Some(_), Some(_)) => {
                    push(l);
                    push(r);
                }
                (Some(_), None) => push(l),
                (None, Some(_)) => push(r),
                (None, None) => {}
            }
        }
        best.map(|(d, k)| {
            let t = &self.tris[k];
            (d, self.ids[k], (t[1] - t[0]).cross(t[2] - t[0]).normalize())
        })
    }
}

/// Distance along the ray to triangle t, either side.
fn moller_trumbore(o: DVec3, d: DVec3, t: &[DVec3; 3]) -> Option<f64> {
    let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-14 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - t[0];
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some(e2.dot(q) * inv)
}

/// The triangles of an OBJ file in file order: `v` and `f` lines (polygons fanned into
/// triangles; `f 1/2/3 …` and negative indices accepted; everything else ignored).
///
/// Only a regular file of at most [`crate::limits::MESH_BYTES`] is read: a device or a FIFO
/// named as a mesh would never end.
pub fn read_obj_triangles(path: &Path) -> Result<Vec<[DVec3; 3]>> {
    parse_obj_triangles(&read_obj_text(path)?).map_err(|e| Error::file(path, e.reason()))
}

fn memory_of(triangles: usize) -> u64 {
    (triangles as u64).saturating_mul(crate::limits::MESH_BYTES_PER_TRIANGLE)
}

/// An OBJ file's text: only from a regular file of at most [`crate::limits::MESH_BYTES`].
fn read_obj_text(path: &Path) -> Result<String> {
    use std::io::Read;
    let file = std::fs::File::open(path).map_err(|e| Error::file(path, e))?;
    let meta = file.metadata().map_err(|e| Error::file(path, e))?;
    if !meta.is_file() {
        return Err(Error::file(path, "not a regular file"));
    }
    let limit = crate::limits::MESH_BYTES;
    if meta.len() > limit {
        return Err(Error::file(
            path,
            format!("{} bytes is above the mesh limit of {limit}", meta.len()),
        ));
    }
    let mut bytes = Vec::new();
    file.take(limit + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::file(path, e))?;
    if bytes.len() as u64 > limit {
        return Err(Error::file(
            path,
            format!("above the mesh limit of {limit} bytes"),
        ));
    }
    String::from_utf8(bytes).map_err(|_| Error::file(path, "not UTF-8 text"))
}

/// How many triangles the faces of OBJ text fan into (a face of n vertices makes n − 2),
/// counted without building anything; malformed lines are left to the parser.
pub fn count_obj_triangles(text: &str) -> usize {
    text.lines()
        .filter_map(|line| {
            let mut parts = line.split_whitespace();
            (parts.next() == Some("f")).then(|| parts.count().saturating_sub(2))
        })
        .sum()
}

/// The triangles of OBJ text (see [`read_obj_triangles`]); at most
/// [`crate::limits::MESH_TRIANGLES`].
pub fn parse_obj_triangles(text: &str) -> Result<Vec<[DVec3; 3]>> {
    let mut verts = Vec::new();
    // Grown by doubling, the list would take up to twice its size.
    let mut tris = Vec::with_capacity(count_obj_triangles(text).min(crate::limits::MESH_TRIANGLES));
    for (no, line) in text.lines().enumerate() {
        let mut parts = line.split_whitespace();
        let bad = |why: &str| Error::invalid("obj", format!("line {}: {why}", no + 1));
        match parts.next() {
            Some("v") => {
                let c: Vec<f64> = parts
                    .take(3)
                    .map(|s| s.parse().map_err(|_| bad("a vertex needs three numbers")))
                    .collect::<Result<_>>()?;
                if c.len() != 3 {
                    return Err(bad("a vertex needs three numbers"));
                }
                verts.push(DVec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                let idx: Vec<usize> = parts
                    .map(|s| {
                        let i: i64 = s
                            .split('/')
                            .next()
                            .unwrap_or("")
                            .parse()
                            .map_err(|_| bad("a face index is not a number"))?;
                        let i = if i < 0 { verts.len() as i64 + i } else { i - 1 };
                        usize::try_from(i)
                            .ok()
                            .filter(|&i| i < verts.len())
                            .ok_or_else(|| bad("a face refers to a vertex not yet defined"))
                    })
                    .collect::<Result<_>>()?;
                if idx.len() < 3 {
                    return Err(bad("a face needs three vertices"));
                }
                if tris.len() + idx.len() - 2 > crate::limits::MESH_TRIANGLES {
                    return Err(bad(&format!(
                        "more than {} triangles",
                        crate::limits::MESH_TRIANGLES
                    )));
                }
                for k in 1..idx.len() - 1 {
                    tris.push([verts[idx[0]], verts[idx[k]], verts[idx[k + 1]]]);
                }
            }
            _ => {}
        }
    }
    Ok(tris)
}
