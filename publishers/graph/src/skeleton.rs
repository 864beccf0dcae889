//! Graph from an occupancy map: Zhang–Suen thinning of the free space to a one-pixel skeleton,
//! short spurs pruned, then nodes at junctions (crossing number ≥ 3) and dead ends (one
//! neighbour) and links along the skeleton passages between them, with their traced lengths.

use super::{Graph, GraphError};

/// A free-space mask over a grid: `free[y * width + x]`, row `y` at world
/// `origin_y_m + (y + 0.5)·cell_size_m` (rows grow with world y).
#[derive(Debug, Clone, PartialEq)]
pub struct FreeMask {
    pub width: usize,
    pub height: usize,
    pub cell_size_m: f32,
    pub origin_m: [f32; 2],
    pub free: Vec<bool>,
}

/// Options of the extraction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkeletonOptions {
    /// Dead-end branches up to this long (m) that end in a junction are pruned (thinning leaves
    /// such spurs at corridor corners).
    pub min_branch_m: f32,
}

impl Default for SkeletonOptions {
    fn default() -> Self {
        Self { min_branch_m: 0.5 }
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SkeletonError {
    #[error("free mask: {len} cells for a {width}×{height} grid")]
    Size {
        len: usize,
        width: usize,
        height: usize,
    },
    #[error("free mask: cell_size_m {0} must be > 0")]
    CellSize(f32),
    #[error("skeleton graph: {0}")]
    Graph(#[from] GraphError),
}

// Neighbours P2..P9 clockwise from north (image rows: north = y − 1).
const RING: [(isize, isize); 8] = [
    (0, -1),
    (1, -1),
    (1, 0),
    (1, 1),
    (0, 1),
    (-1, 1),
    (-1, 0),
    (-1, -1),
];

struct Img {
    w: usize,
    h: usize,
    px: Vec<bool>,
}

impl Img {
    fn get(&self, x: isize, y: isize) -> bool {
        x >= 0
            && y >= 0
            && (x as usize) < self.w
            && (y as usize) < self.h
            && self.px[y as usize * self.w + x as usize]
    }

    fn ring(&self, i: usize) -> [bool; 8] {
        let (x, y) = ((i % self.w) as isize, (i / self.w) as isize);
        RING.map(|(dx, dy)| self.get(x + dx, y + dy))
    }

    fn neighbours(&self, i: usize) -> impl Iterator<Item = usize> + '_ {
        let (x, y) = ((i % self.w) as isize, (i / self.w) as isize);
        // 4-neighbours first, so traces follow the passage rather than cutting corners.
        [0, 2, 4, 6, 1, 3, 5, 7].into_iter().filter_map(move |k| {
            let (dx, dy) = RING[k];
            self.get(x + dx, y + dy)
                .then(|| (y + dy) as usize * self.w + (x + dx) as usize)
        })
    }
}

fn transitions(r: &[bool; 8]) -> usize {
    (0..8).filter(|&k| !r[k] && r[(k + 1) % 8]).count()
}

fn count(r: &[bool; 8]) -> usize {
    r.iter().filter(|&&b| b).count()
}

/// Zhang–Suen thinning of `free` (in place semantics, returns the skeleton).
pub fn thin(mask: &FreeMask) -> Result<Vec<bool>, SkeletonError> {
    check(mask)?;
    let mut img = Img {
        w: mask.width,
        h: mask.height,
        px: mask.free.clone(),
    };
    loop {
        let mut changed = false;
        for step in 0..2 {
            let del: Vec<usize> = (0..img.px.len())
                .filter(|&i| img.px[i])
                .filter(|&i| {
                    let r = img.ring(i);
                    let (p2, p4, p6, p8) = (r[0], r[2], r[4], r[6]);
                    let b = count(&r);
                    (2..=6).contains(&b)
                        && transitions(&r) == 1
                        && if step == 0 {
                            // P2·P4·P6 = 0 and P4·P6·P8 = 0
                            !(p4 && p6 && (p2 || p8))
                        } else {
                            // P2·P4·P8 = 0 and P2·P6·P8 = 0
                            !(p2 && p8 && (p4 || p6))
                        }
                })
                .collect();
            changed |= !del.is_empty();
            for i in del {
                img.px[i] = false;
            }
        }
        if !changed {
            return Ok(img.px);
        }
    }
}

fn check(mask: &FreeMask) -> Result<(), SkeletonError> {
    if mask.free.len() != mask.width * mask.height {
        return Err(SkeletonError::Size {
            len: mask.free.len(),
            width: mask.width,
            height: mask.height,
        });
    }
    if !(mask.cell_size_m.is_finite() && mask.cell_size_m > 0.0) {
        return Err(SkeletonError::CellSize(mask.cell_size_m));
    }
    Ok(())
}

fn is_junction(img: &Img, i: usize) -> bool {
    transitions(&img.ring(i)) >= 3
}

fn is_end(img: &Img, i: usize) -> bool {
    count(&img.ring(i)) == 1
}

/// Removes dead-end branches of at most `max_px` pixels that end in a junction.
fn prune(img: &mut Img, max_px: usize) {
    loop {
        let mut changed = false;
        let ends: Vec<usize> = (0..img.px.len())
            .filter(|&i| img.px[i] && is_end(img, i))
            .collect();
        for e in ends {
            if !img.px[e] || !is_end(img, e) {
                continue;
            }
            let mut path = vec![e];
            let mut prev = usize::MAX;
            let mut cur = e;
            let reached_junction = loop {
                let next: Vec<usize> = img
                    .neighbours(cur)
                    .filter(|&n| n != prev && !path.contains(&n))
                    .collect();
                if next.iter().any(|&n| is_junction(img, n)) || next.len() > 1 {
                    break true;
                }
                match next.first() {
                    Some(&n) if path.len() <= max_px => {
                        prev = cur;
                        cur = n;
                        path.push(n);
                    }
                    _ => break false,
                }
            };
            if reached_junction && path.len() <= max_px {
                for p in path {
                    img.px[p] = false;
                }
                changed = true;
            }
        }
        if !changed {
            return;
        }
    }
}

/// The skeleton graph of a free mask: node names `n0, n1, …` in row-major order of their
/// pixels; terminal = one link.
pub fn graph_from_mask(mask: &FreeMask, opts: SkeletonOptions) -> Result<Graph, SkeletonError> {
    let px = thin(mask)?;
    let mut img = Img {
        w: mask.width,
        h: mask.height,
        px,
    };
    prune(
        &mut img,
        (opts.min_branch_m / mask.cell_size_m).ceil() as usize,
    );
    let nodes = NodeClusters::of(&img);
    let mut g = Graph::new();
    add_cluster_nodes(&mut g, mask, &img, &nodes.members)?;
    trace_passages(&mut g, mask, &img, &nodes)?;
    g.mark_terminals();
    Ok(g)
}

/// The node pixels of a skeleton (junctions and dead ends), clustered by 8-connectivity.
struct NodeClusters {
    /// Whether each pixel is a node pixel.
    is_node: Vec<bool>,
    /// The cluster of each node pixel (`usize::MAX` for the others).
    cluster: Vec<usize>,
    /// The pixels of each cluster, in the order they were reached.
    members: Vec<Vec<usize>>,
}

impl NodeClusters {
    /// Finds the node pixels of `img` and clusters them, in row-major order of their first pixel.
    fn of(img: &Img) -> NodeClusters {
        // Node pixels, clustered by 8-connectivity.
        let is_node: Vec<bool> = (0..img.px.len())
            .map(|i| img.px[i] && (is_junction(img, i) || count(&img.ring(i)) <= 1))
            .collect();
        let mut cluster = vec![usize::MAX; img.px.len()];
        let mut members: Vec<Vec<usize>> = Vec::new();
        for i in 0..img.px.len() {
            if !is_node[i] || cluster[i] != usize::MAX {
                continue;
            }
            let c = members.len();
            let mut stack = vec![i];
            let mut m = Vec::new();
            cluster[i] = c;
            while let Some(p) = stack.pop() {
                m.push(p);
                for n in img.neighbours(p).collect::<Vec<_>>() {
                    if is_node[n] && cluster[n] == usize::MAX {
                        cluster[n] = c;
                        stack.push(n);
                    }
                }
            }
            members.push(m);
        }
        NodeClusters {
            is_node,
            cluster,
            members,
        }
    }
}

/// The world position (m) of the centre of pixel `i`.
fn world(mask: &FreeMask, img: &Img, i: usize) -> (f32, f32) {
    (
        mask.origin_m[0] + ((i % img.w) as f32 + 0.5) * mask.cell_size_m,
        mask.origin_m[1] + ((i / img.w) as f32 + 0.5) * mask.cell_size_m,
    )
}

/// Adds one node `n<c>` per cluster, at the member pixel nearest the cluster's centroid.
fn add_cluster_nodes(
    g: &mut Graph,
    mask: &FreeMask,
    img: &Img,
    members: &[Vec<usize>],
) -> Result<(), SkeletonError> {
    let world = |i: usize| world(mask, img, i);
    for (c, m) in members.iter().enumerate() {
        // The member pixel nearest the cluster's centroid.
        let (sx, sy) = m.iter().fold((0.0, 0.0), |(sx, sy), &p| {
            let (x, y) = world(p);
            (sx + x, sy + y)
        });
        let (cx, cy) = (sx / m.len() as f32, sy / m.len() as f32);
        let best = *m
            .iter()
            .min_by(|&&a, &&b| {
                let d = |p: usize| {
                    let (x, y) = world(p);
                    (x - cx).hypot(y - cy)
                };
                d(a).total_cmp(&d(b))
            })
            .unwrap();
        let (x, y) = world(best);
        g.add_node(&format!("n{c}"), x, y)?;
    }
    Ok(())
}

/// Traces the passages leaving each cluster and links the clusters they join.
fn trace_passages(
    g: &mut Graph,
    mask: &FreeMask,
    img: &Img,
    nodes: &NodeClusters,
) -> Result<(), SkeletonError> {
    let mut used = vec![false; img.px.len()];
    for (x, m) in nodes.members.iter().enumerate() {
        for &start in m {
            for first in img.neighbours(start).collect::<Vec<_>>() {
                if nodes.is_node[first] || used[first] {
                    continue;
                }
                let (end, path) = trace(img, nodes, &mut used, x, start, first);
                let Some(y) = end else { continue };
                link_passage(g, mask, img, x, y, &path)?;
            }
        }
    }
    Ok(())
}

/// Follows a passage from cluster `x` through `first`: the cluster it ends in, and its pixels.
fn trace(
    img: &Img,
    nodes: &NodeClusters,
    used: &mut [bool],
    x: usize,
    start: usize,
    first: usize,
) -> (Option<usize>, Vec<usize>) {
    let (is_node, cluster) = (&nodes.is_node, &nodes.cluster);
    let mut path = vec![first];
    used[first] = true;
    let mut prev = start;
    let mut cur = first;
    let end = loop {
        let ns: Vec<usize> = img.neighbours(cur).filter(|&n| n != prev).collect();
        if let Some(&n) = ns
            .iter()
            .find(|&&n| is_node[n] && (cluster[n] != x || path.len() > 2))
        {
            break Some(cluster[n]);
        }
        match ns.iter().find(|&&n| !is_node[n] && !used[n]) {
            Some(&n) => {
                used[n] = true;
                path.push(n);
                prev = cur;
                cur = n;
            }
            None => break None,
        }
    };
    (end, path)
}

/// Links nodes `x` and `y` along a traced passage, with extra nodes on loops and parallels.
fn link_passage(
    g: &mut Graph,
    mask: &FreeMask,
    img: &Img,
    x: usize,
    y: usize,
    path: &[usize],
) -> Result<(), SkeletonError> {
    // Split loops and parallel passages with extra nodes so links stay unique.
    let pieces = if x == y {
        3
    } else if g.edge_dirs(x, y).is_some() {
        2
    } else {
        1
    };
    let mut chain = vec![x];
    for k in 1..pieces {
        let p = path[path.len() * k / pieces];
        let (wx, wy) = world(mask, img, p);
        let name = format!("n{}", g.len());
        chain.push(g.add_node(&name, wx, wy)?);
    }
    chain.push(y);
    for pair in chain.windows(2) {
        g.add_edge(pair[0], pair[1], None, None)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Dir;

    fn mask(w: usize, h: usize, rects: &[(usize, usize, usize, usize)]) -> FreeMask {
        let mut free = vec![false; w * h];
        for &(x0, y0, x1, y1) in rects {
            for y in y0..y1 {
                for x in x0..x1 {
                    free[y * w + x] = true;
                }
            }
        }
        FreeMask {
            width: w,
            height: h,
            cell_size_m: 0.1,
            origin_m: [0.0, 0.0],
            free,
        }
    }

    #[test]
    fn t_corridor_gives_one_junction_and_three_dead_ends() {
        // A horizontal corridor 5 cells wide, and a vertical one up from its middle.
        let m = mask(60, 40, &[(3, 5, 57, 10), (27, 10, 32, 36)]);
        let g = graph_from_mask(&m, SkeletonOptions::default()).unwrap();
        let degrees: Vec<usize> = g.nodes().iter().map(|n| n.degree()).collect();
        assert_eq!(g.len(), 4, "{:?}", g.nodes());
        assert_eq!(
            degrees.iter().filter(|&&d| d == 3).count(),
            1,
            "{degrees:?}"
        );
        assert_eq!(
            degrees.iter().filter(|&&d| d == 1).count(),
            3,
            "{degrees:?}"
        );
        assert_eq!(g.nodes().iter().filter(|n| n.terminal).count(), 3);
        let j = g.nodes().iter().position(|n| n.degree() == 3).unwrap();
        let jn = &g.nodes()[j];
        assert!((jn.x_m - 2.95).abs() < 0.3, "junction at x {}", jn.x_m);
        // Links: left, right and up (+y, rows grow with world y).
        for d in [Dir::Left, Dir::Right, Dir::Up] {
            assert!(jn.links[d.index()].is_some(), "no {d:?} link: {jn:?}");
        }
        let up = g.link(j, Dir::Up).unwrap();
        assert!(up.length_m > 2.0 && up.length_m < 3.0, "{}", up.length_m);
    }

    #[test]
    fn straight_corridor_and_plus() {
        let g = graph_from_mask(&mask(40, 12, &[(2, 3, 38, 8)]), Default::default()).unwrap();
        assert_eq!(g.len(), 2, "{:?}", g.nodes());
        assert!(g.nodes().iter().all(|n| n.terminal));
        let g = graph_from_mask(
            &mask(50, 50, &[(3, 22, 47, 27), (22, 3, 27, 47)]),
            Default::default(),
        )
        .unwrap();
        let degrees: Vec<usize> = g.nodes().iter().map(|n| n.degree()).collect();
        assert_eq!(
            degrees.iter().filter(|&&d| d == 4).count(),
            1,
            "{degrees:?}"
        );
        assert_eq!(
            degrees.iter().filter(|&&d| d == 1).count(),
            4,
            "{degrees:?}"
        );
    }

    #[test]
    fn bad_mask_is_refused() {
        let mut m = mask(4, 4, &[]);
        m.free.pop();
        assert!(thin(&m).unwrap_err().to_string().contains("15 cells"));
    }
}
