//! Exact nearest neighbours in 3-D on a small k-d tree of our own.
//!
//! Every query is exact and deterministic: results are sorted by distance, ties by point index.
//! The tree is built here rather than taken from kiddo 4 because both of kiddo's trees panic
//! (integer overflow in construction) when more points than a bucket holds share one
//! coordinate — routine in real clouds with duplicated points. Splitting at the median by
//! count keeps this tree balanced whatever the duplicates.
//!
//! The file is long because the tree's build, its one search and the four ways a search keeps
//! what it finds (nearest, any, best k, every one within) are one job, kept in one place.

use std::sync::OnceLock;

use nalgebra::Point3;
use rayon::prelude::*;

use crate::{GeomError, Result};

/// Most points in a leaf.
const LEAF_SIZE: usize = 12;

/// A node of the tree with the tight box of its points: a search skips every node whose box
/// lies beyond its bound. A scan's points lie on surfaces, so a box is far smaller than the
/// cell a split leaves it, and a query off the surface (a point moved by a wrong pose) is
/// turned away by the boxes where the cells' empty space would let it in.
#[derive(Clone, Debug)]
struct Node {
    /// Least coordinate of the node's points on each axis.
    lo: [f64; 3],
    /// Greatest coordinate of the node's points on each axis.
    hi: [f64; 3],
    kind: Kind,
}

/// What a node holds: a leaf owns a range of the reordered points; a split has every point
/// of `left` with `coord[axis] <= value` and every point of `right` with `coord[axis] >= value`.
#[derive(Clone, Debug)]
enum Kind {
    Leaf {
        start: u32,
        end: u32,
    },
    /// A range of points that all lie at one place (duplicates: a LiDAR sweep's missing
    /// returns stored as 0,0,0), of any size, sorted by index: a query offers their indices in
    /// order and stops at the first one turned away, so k copies cost O(k) at most, not a visit
    /// of every cell tied with the best distance.
    Same {
        start: u32,
        end: u32,
    },
    Split {
        axis: u8,
        value: f64,
        left: u32,
        right: u32,
    },
}

/// An exact nearest-neighbour index over a fixed set of points, built once.
///
/// Coordinates must be finite (a NaN point is never reported); [`knn_graph`] checks this for
/// its callers. Distances returned are Euclidean (not squared).
#[derive(Clone, Debug)]
pub struct KnnIndex {
    /// Tree nodes, root first; empty for an empty point set.
    nodes: Vec<Node>,
    /// The points' coordinates in tree order, one array per axis, so that a leaf's squared
    /// distances are computed side by side. // (3, N)
    xyz: [Vec<f64>; 3],
    /// Each point's index in the caller's slice, in tree order. // (N,)
    ids: Vec<u32>,
    /// Each point's place in tree order, by its index in the caller's slice. // (N,)
    places: Vec<u32>,
}

/// What [`KnnIndex::new`] calls with the points of every index it builds, once set.
static ON_BUILD: OnceLock<fn(&[Point3<f64>])> = OnceLock::new();

/// Has `hook` called with the points of every [`KnnIndex`] this process builds from now on: how
/// a test holds a registration to one tree per cloud it searches. The first hook set stays;
/// false when one was set already.
pub fn watch_index_builds(hook: fn(&[Point3<f64>])) -> bool {
    ON_BUILD.set(hook).is_ok()
}

impl KnnIndex {
    /// An index over `points`; reported indices are positions in this slice.
    pub fn new(points: &[Point3<f64>]) -> Self {
        if let Some(hook) = ON_BUILD.get() {
            hook(points);
        }
        let mut tree_points = tree_points(points);
        let mut nodes = Vec::with_capacity(most_nodes(points.len()));
        if !tree_points.is_empty() {
            build(&mut nodes, &mut tree_points, 0, SIDE_BY_SIDE_POINTS);
        }
        let mut xyz = [(); 3].map(|_| Vec::with_capacity(tree_points.len()));
        for (p, _) in &tree_points {
            for (axis, coords) in xyz.iter_mut().enumerate() {
                coords.push(p[axis]);
            }
        }
        let ids: Vec<u32> = tree_points.iter().map(|&(_, i)| i).collect();
        let mut places = vec![0; ids.len()];
        for (place, &i) in ids.iter().enumerate() {
            places[i as usize] = place as u32;
        }
        Self {
            nodes,
            xyz,
            ids,
            places,
        }
    }

    /// Number of indexed points.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// True when the index holds no point.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// The nearest point to `query`: (index, distance); the lowest index among equally near
    /// points. An empty index answers `(usize::MAX, f64::INFINITY)`.
    pub fn nearest(&self, query: &Point3<f64>) -> (usize, f64) {
        let (i, d2) = self.nearest_from(query, (usize::MAX, f64::INFINITY));
        (i, d2.sqrt())
    }

    /// The nearest point strictly closer than `radius`, if any: the search prunes every cell
    /// farther than `radius`, so it is much cheaper than [`Self::nearest`] for small radii
    /// (ICP's correspondence search).
    pub fn nearest_within(&self, query: &Point3<f64>, radius: f64) -> Option<(usize, f64)> {
        let r2 = radius * radius;
        let (i, d2) = self.nearest_from(query, (usize::MAX, r2));
        (i != usize::MAX && d2 < r2).then(|| (i, d2.sqrt()))
    }

    /// [`Self::nearest_within`] of a query near an earlier one whose nearest was point `guess`
    /// (an iteration of ICP, each point moved a little since the last): the search starts from
    /// `guess`'s distance instead of `radius`, which prunes most cells at once. The same answer
    /// as [`Self::nearest_within`], whatever `guess` is.
    pub fn nearest_within_from(
        &self,
        query: &Point3<f64>,
        radius: f64,
        guess: usize,
    ) -> Option<(usize, f64)> {
        let r2 = radius * radius;
        // The distance as a leaf computes it, so that ties resolve as in a search without it.
        let start = self
            .places
            .get(guess)
            .map(|&place| {
                let at = [0, 1, 2].map(|axis| self.xyz[axis][place as usize]);
                (guess, squared_distance(&at, &[query.x, query.y, query.z]))
            })
            .filter(|&(_, d2)| d2 < r2)
            .unwrap_or((usize::MAX, r2));
        let (i, d2) = self.nearest_from(query, start);
        (i != usize::MAX && d2 < r2).then(|| (i, d2.sqrt()))
    }

    /// (index, squared distance) of the first point by (squared distance, index) that comes no
    /// later than `start` (a point of the index with its squared distance, or `(usize::MAX,
    /// bound)`); `start` itself when none does.
    fn nearest_from(&self, query: &Point3<f64>, start: (usize, f64)) -> (usize, f64) {
        let mut best = Nearest(start);
        self.search_all(query, &mut best);
        best.0
    }

    /// Whether some point is strictly closer than `radius` to `query`: the same answer as
    /// `nearest_within(query, radius).is_some()`, but the search ends at the first such point
    /// instead of looking on for the nearest (counting overlaps: under a right transform the
    /// query's own leaf nearly always holds one).
    pub fn any_within(&self, query: &Point3<f64>, radius: f64) -> bool {
        let mut any = Any {
            r2: radius * radius,
            found: false,
        };
        self.search_all(query, &mut any);
        any.found
    }

    /// The `k` nearest points to `query` (fewer when the index has fewer), sorted by distance,
    /// ties by index — also across the k-th distance: of points tied there, the lowest indices.
    pub fn k_nearest(&self, query: &Point3<f64>, k: usize) -> Vec<(usize, f64)> {
        let mut out = Vec::with_capacity(k.min(self.len()));
        self.k_nearest_squared_into(query, k, &mut out);
        out.iter_mut().for_each(|n| n.1 = n.1.sqrt());
        out
    }

    /// [`Self::k_nearest`] into a reused buffer, with *squared* distances: for inner loops.
    pub fn k_nearest_squared_into(
        &self,
        query: &Point3<f64>,
        k: usize,
        out: &mut Vec<(usize, f64)>,
    ) {
        self.best_within(query, k, f64::INFINITY, out);
    }

    /// [`Self::hybrid`] into a reused buffer, with *squared* distances: for inner loops.
    pub fn hybrid_squared_into(
        &self,
        query: &Point3<f64>,
        radius: f64,
        max_nn: usize,
        out: &mut Vec<(usize, f64)>,
    ) {
        if !(radius > 0.0) {
            out.clear();
            return;
        }
        self.best_within(query, max_nn, radius * radius, out);
    }

    /// The `k` first points by (squared distance, index) among those with squared distance
    /// below `r2`, sorted, into `out`.
    fn best_within(&self, query: &Point3<f64>, k: usize, r2: f64, out: &mut Vec<(usize, f64)>) {
        out.clear();
        if k == 0 || self.nodes.is_empty() {
            return;
        }
        // No more than the points: the buffer's `2k` then neither overflows nor over-allocates.
        let mut best = Best::new(k.min(self.len()), r2, out);
        self.search_all(query, &mut best);
        best.finish();
    }

    /// Every point strictly closer than `radius` to `query`, sorted by distance, ties by index.
    pub fn within_radius(&self, query: &Point3<f64>, radius: f64) -> Vec<(usize, f64)> {
        let mut out = Vec::new();
        self.for_each_within(query, radius, |i, d2| out.push((i, d2)));
        sort_by_distance_then_index(&mut out);
        out.iter_mut().for_each(|n| n.1 = n.1.sqrt());
        out
    }

    /// Calls `visit(index, squared distance)` for every point strictly closer than `radius` to
    /// `query`, in the order the search meets them (fixed by the query and radius alone),
    /// without gathering them: for sums over a neighbourhood.
    pub fn for_each_within(&self, query: &Point3<f64>, radius: f64, visit: impl FnMut(usize, f64)) {
        if radius > 0.0 {
            self.search_all(
                query,
                &mut Within {
                    r2: radius * radius,
                    visit,
                },
            );
        }
    }

    /// Open3D's hybrid search (`KDTreeSearchParamHybrid`): the at most `max_nn` nearest points
    /// strictly closer than `radius`, sorted by distance, ties by index.
    pub fn hybrid(&self, query: &Point3<f64>, radius: f64, max_nn: usize) -> Vec<(usize, f64)> {
        let mut out = Vec::with_capacity(max_nn.min(self.len()));
        self.hybrid_squared_into(query, radius, max_nn, &mut out);
        out.iter_mut().for_each(|n| n.1 = n.1.sqrt());
        out
    }

    /// Offers every point of the tree that could beat `found`'s bound to `found` (none of an
    /// empty tree): [`Self::search`] from the root.
    fn search_all<F: Found>(&self, query: &Point3<f64>, found: &mut F) {
        let q = [query.x, query.y, query.z];
        if let Some(root) = self.nodes.first() {
            if found.may_improve(box_squared_distance(root, &q)) {
                self.search(0, &q, found);
            }
        }
    }

    /// Offers every point of the subtree at `node` that could beat `found`'s bound to `found`,
    /// the child on the query's side of the split first (whatever the boxes: a visit's order
    /// is then the query's alone, and so are sums over [`Self::for_each_within`]).
    fn search<F: Found>(&self, node: usize, q: &[f64; 3], found: &mut F) {
        match self.nodes[node].kind {
            Kind::Leaf { start, end } => {
                #[cfg(test)]
                LEAVES.with(|n| n.set(n.get() + 1));
                let (start, end) = (start as usize, end as usize);
                let mut d2 = [0.0; LEAF_SIZE];
                leaf_squared_distances(
                    [
                        &self.xyz[0][start..end],
                        &self.xyz[1][start..end],
                        &self.xyz[2][start..end],
                    ],
                    q,
                    &mut d2,
                );
                // Only candidates the search could take are offered (the answer is the same:
                // every other one would be turned away).
                for (&i, &d2) in self.ids[start..end].iter().zip(&d2) {
                    if d2 <= found.limit() {
                        found.offer((i as usize, d2));
                        #[cfg(test)]
                        OFFERS.with(|n| n.set(n.get() + 1));
                    }
                }
            }
            Kind::Same { start, end } => {
                let (start, end) = (start as usize, end as usize);
                let p = [self.xyz[0][start], self.xyz[1][start], self.xyz[2][start]];
                let d2 = squared_distance(&p, q);
                for &i in &self.ids[start..end] {
                    #[cfg(test)]
                    OFFERS.with(|n| n.set(n.get() + 1));
                    if !found.offer((i as usize, d2)) {
                        break;
                    }
                }
            }
            Kind::Split {
                axis,
                value,
                left,
                right,
            } => {
                let (near, far) = if q[axis as usize] < value {
                    (left, right)
                } else {
                    (right, left)
                };
                for child in [near as usize, far as usize] {
                    if found.may_improve(box_squared_distance(&self.nodes[child], q)) {
                        self.search(child, q, found);
                    }
                }
            }
        }
    }
}

/// [`KnnIndex::nearest_within`] answered from `around` alone, where that is proof enough:
/// `around` holds every point strictly within `reach` of `points[centre]` (as
/// [`KnnIndex::for_each_within`] meets them), `points` being the indexed points. Every point
/// within `reach − |query − centre|` of `query` is then among them, so a nearest found within
/// that is the index's, to the bit, ties included; and so is "none within `radius`" when
/// `radius` is within it too: `Some(answer)`. `None` when `around` cannot tell (the query has
/// moved too far from the centre): search the index then. A few distances instead of a walk
/// down the tree, for queries that move a little from one search to the next (ICP's).
pub fn nearest_among(
    points: &[Point3<f64>],
    around: &[u32],
    centre: usize,
    reach: f64,
    query: &Point3<f64>,
    radius: f64,
) -> Option<Option<(usize, f64)>> {
    let q = [query.x, query.y, query.z];
    let coords = |i: usize| [points[i].x, points[i].y, points[i].z];
    let step = squared_distance(&coords(centre), &q).sqrt();
    // A hair inside the proof, so that rounding cannot let a point at its edge slip out.
    let proof = (reach - step) * (1.0 - 1e-9);
    if !(proof > 0.0) {
        return None;
    }
    let mut best = (usize::MAX, f64::INFINITY);
    for &j in around {
        // The distance as a leaf computes it, so that answers and ties are the search's.
        let candidate = (j as usize, squared_distance(&coords(j as usize), &q));
        if is_before(candidate, best) {
            best = candidate;
        }
    }
    let (r2, proof2) = (radius * radius, proof * proof);
    if best.1 < r2 && best.1 < proof2 {
        Some(Some((best.0, best.1.sqrt())))
    } else if r2 <= proof2 {
        // Every point strictly within `radius` is among `around`, and none is.
        Some(None)
    } else {
        None
    }
}

/// The hybrid neighbourhoods of many query points, stored flat: query q's neighbours, sorted by
/// distance then index, with *squared* distances.
#[derive(Clone, Debug, Default)]
pub struct Neighbourhoods {
    /// Query q owns `items[offsets[q]..offsets[q + 1]]`. // (Q + 1,)
    offsets: Vec<usize>,
    /// (index, squared distance) of every neighbour of every query. // (ΣK,)
    items: Vec<(usize, f64)>,
}

impl Neighbourhoods {
    /// [`KnnIndex::hybrid`] for each of `queries`: blocks of queries side by side, joined in
    /// order.
    pub fn hybrid(index: &KnnIndex, queries: &[Point3<f64>], radius: f64, max_nn: usize) -> Self {
        // Small enough that a cloud of a few hundred points makes pieces for every thread.
        const BLOCK: usize = 64;
        let k = max_nn.min(index.len());
        // Per block: where each query's neighbours end, and the neighbours.
        type Block = (Vec<usize>, Vec<(usize, f64)>);
        let blocks: Vec<Block> = queries
            .par_chunks(BLOCK)
            .map(|block| {
                let mut ends = Vec::with_capacity(block.len()); // (B,)
                let mut items = Vec::with_capacity(block.len() * k); // (ΣK over the block,)
                let mut found = Vec::with_capacity(k);
                for q in block {
                    index.hybrid_squared_into(q, radius, max_nn, &mut found);
                    items.extend_from_slice(&found);
                    ends.push(items.len());
                }
                (ends, items)
            })
            .collect();
        let mut offsets = Vec::with_capacity(queries.len() + 1);
        let mut items = Vec::with_capacity(blocks.iter().map(|b| b.1.len()).sum());
        offsets.push(0);
        for (ends, block_items) in blocks {
            let base = items.len();
            offsets.extend(ends.iter().map(|end| base + end));
            items.extend(block_items);
        }
        Self { offsets, items }
    }

    /// Number of queries.
    pub fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// True when there is no query.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Query `q`'s neighbours: (index, squared distance), sorted.
    pub fn get(&self, q: usize) -> &[(usize, f64)] {
        &self.items[self.offsets[q]..self.offsets[q + 1]]
    }

    /// Query `q`'s neighbours restricted to a smaller hybrid search: the first at most `max_nn`
    /// strictly within `radius`. Exact when `radius` and `max_nn` do not exceed those searched.
    pub fn get_within(&self, q: usize, radius: f64, max_nn: usize) -> &[(usize, f64)] {
        let all = self.get(q);
        let r2 = radius * radius;
        &all[..all.partition_point(|&(_, d2)| d2 < r2).min(max_nn)]
    }
}

/// What a tree search collects: it is offered (index, squared distance) candidates and says
/// whether a cell at a squared distance could still hold a better one.
trait Found {
    /// Takes `candidate` if it is among the best so far; false when it is turned away, and so
    /// would be every candidate at the same distance with a larger index.
    fn offer(&mut self, candidate: (usize, f64)) -> bool;
    fn may_improve(&self, cell_d2: f64) -> bool;
    /// A squared distance above which every candidate would be turned away.
    fn limit(&self) -> f64;
}

/// The single first point by (distance, index).
struct Nearest((usize, f64));

impl Found for Nearest {
    #[inline]
    fn offer(&mut self, candidate: (usize, f64)) -> bool {
        let better = is_before(candidate, self.0);
        if better {
            self.0 = candidate;
        }
        better
    }
    #[inline]
    fn may_improve(&self, cell_d2: f64) -> bool {
        // `<=`: a point as far as the current best may still win on its index.
        cell_d2 <= self.0 .1
    }
    #[inline]
    fn limit(&self) -> f64 {
        self.0 .1
    }
}

/// Whether any point has squared distance below `r2`; once one has, every later candidate
/// and cell is turned away, which ends the search.
struct Any {
    r2: f64,
    found: bool,
}

impl Found for Any {
    #[inline]
    fn offer(&mut self, candidate: (usize, f64)) -> bool {
        let first = !self.found && candidate.1 < self.r2;
        self.found |= first;
        first
    }
    #[inline]
    fn may_improve(&self, cell_d2: f64) -> bool {
        // `<=`, as `Nearest` prunes with its bound `r2`: the same cells are searched until one
        // point is found.
        !self.found && cell_d2 <= self.r2
    }
    #[inline]
    fn limit(&self) -> f64 {
        if self.found {
            f64::NEG_INFINITY
        } else {
            self.r2
        }
    }
}

/// The `k` first points with squared distance below `r2`, gathered unordered in `buf`: when it
/// holds `2k`, a selection cuts it back to the `k` first (cheaper than keeping a heap), and
/// `bound`, the last of those, then turns away every candidate after it.
struct Best<'a> {
    k: usize,
    r2: f64,
    bound: (usize, f64),
    buf: &'a mut Vec<(usize, f64)>,
}

impl<'a> Best<'a> {
    fn new(k: usize, r2: f64, buf: &'a mut Vec<(usize, f64)>) -> Self {
        buf.clear();
        buf.reserve(2 * k);
        Self {
            k,
            r2,
            bound: (usize::MAX, f64::INFINITY),
            buf,
        }
    }

    /// Keeps the `k` first of `buf`, unordered.
    fn cut(&mut self) {
        if self.buf.len() > self.k {
            self.buf
                .select_nth_unstable_by_key(self.k - 1, distance_then_index);
            self.buf.truncate(self.k);
        }
    }

    /// The `k` first, sorted.
    fn finish(mut self) {
        self.cut();
        self.buf.sort_unstable_by_key(distance_then_index);
    }
}

impl Found for Best<'_> {
    #[inline]
    fn offer(&mut self, candidate: (usize, f64)) -> bool {
        if !(candidate.1 < self.r2 && is_before(candidate, self.bound)) {
            return false;
        }
        self.buf.push(candidate);
        if self.buf.len() == 2 * self.k {
            self.cut();
            self.bound = self.buf[self.k - 1];
        }
        true
    }
    #[inline]
    fn may_improve(&self, cell_d2: f64) -> bool {
        // `<=`: a point as far as the bound may still come before it on its index.
        cell_d2 < self.r2 && cell_d2 <= self.bound.1
    }
    #[inline]
    fn limit(&self) -> f64 {
        self.r2.min(self.bound.1)
    }
}

/// Every point with squared distance below `r2`, handed to `visit` as it is met.
struct Within<V> {
    r2: f64,
    visit: V,
}

impl<V: FnMut(usize, f64)> Found for Within<V> {
    #[inline]
    fn offer(&mut self, candidate: (usize, f64)) -> bool {
        let near = candidate.1 < self.r2;
        if near {
            (self.visit)(candidate.0, candidate.1);
        }
        near
    }
    #[inline]
    fn may_improve(&self, cell_d2: f64) -> bool {
        cell_d2 < self.r2
    }
    #[inline]
    fn limit(&self) -> f64 {
        self.r2
    }
}

/// `points` as the tree stores them, each with its index in the slice, before the build orders
/// them. // (N,)
fn tree_points(points: &[Point3<f64>]) -> Vec<([f64; 3], u32)> {
    points
        .iter()
        .enumerate()
        .map(|(i, p)| ([p.x, p.y, p.z], i as u32))
        .collect()
}

/// The most nodes a tree over `n` points has: a node of more than [`LEAF_SIZE`] points splits
/// in halves, so every leaf holds at least half of `LEAF_SIZE` (rounded up), and a binary
/// tree has fewer than twice as many nodes as leaves. The nodes' list is made this long at
/// once: growing it copied every node again and again.
fn most_nodes(n: usize) -> usize {
    2 * n / LEAF_SIZE.div_ceil(2) + 1
}

/// Builds the subtree over `points` (which start at position `offset` of the whole array)
/// and returns its node index; the subtrees of a node over `side_by_side_from` points or more
/// are built side by side.
fn build(
    nodes: &mut Vec<Node>,
    points: &mut [([f64; 3], u32)],
    offset: usize,
    side_by_side_from: usize,
) -> u32 {
    let id = nodes.len() as u32;
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    // Comparisons rather than `min` and `max`, which also look for NaN (a tree's coordinates
    // are finite): the same box, found sooner.
    for (p, _) in points.iter() {
        for a in 0..3 {
            lo[a] = if p[a] < lo[a] { p[a] } else { lo[a] };
            hi[a] = if p[a] > hi[a] { p[a] } else { hi[a] };
        }
    }
    let (start, end) = (offset as u32, (offset + points.len()) as u32);
    let node = |kind| Node { lo, hi, kind };
    if points.len() <= LEAF_SIZE {
        nodes.push(node(Kind::Leaf { start, end }));
        return id;
    }
    // Split the widest axis at the median by count.
    let axis = (0..3)
        .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
        .unwrap_or(0);
    if hi[axis] - lo[axis] == 0.0 {
        points.sort_unstable_by_key(|&(_, i)| i);
        nodes.push(node(Kind::Same { start, end }));
        return id;
    }
    let mid = points.len() / 2;
    points.select_nth_unstable_by(mid, |a, b| a.0[axis].total_cmp(&b.0[axis]));
    let value = points[mid].0[axis];
    nodes.push(node(Kind::Leaf { start, end })); // a placeholder, made the split below
    let side_by_side = points.len() >= side_by_side_from;
    let (left_points, right_points) = points.split_at_mut(mid);
    let (left, right) = if side_by_side {
        // The two subtrees side by side, each into a list of its own, then appended in the
        // order the one-by-one build gives: the same tree, node for node.
        let subtree = |points: &mut [([f64; 3], u32)], offset: usize| {
            let mut nodes = Vec::with_capacity(most_nodes(points.len()));
            build(&mut nodes, points, offset, side_by_side_from);
            nodes
        };
        let (left_nodes, right_nodes) = rayon::join(
            || subtree(left_points, offset),
            || subtree(right_points, offset + mid),
        );
        let left = append_shifted(nodes, left_nodes);
        (left, append_shifted(nodes, right_nodes))
    } else {
        let left = build(nodes, left_points, offset, side_by_side_from);
        (
            left,
            build(nodes, right_points, offset + mid, side_by_side_from),
        )
    };
    nodes[id as usize].kind = Kind::Split {
        axis: axis as u8,
        value,
        left,
        right,
    };
    id
}

/// Points from which [`KnnIndex::new`] builds a node's two subtrees side by side.
const SIDE_BY_SIDE_POINTS: usize = 8192;

/// Appends the subtree `subtree` (built into a list of its own, its root first) to `nodes` and
/// returns its root's index there.
fn append_shifted(nodes: &mut Vec<Node>, subtree: Vec<Node>) -> u32 {
    let base = nodes.len() as u32;
    nodes.extend(subtree.into_iter().map(|mut node| {
        if let Kind::Split { left, right, .. } = &mut node.kind {
            *left += base;
            *right += base;
        }
        node
    }));
    base
}

/// The squared distance from `q` to `node`'s box, summed x, y, z as [`squared_distance`] sums:
/// never more than that of any of the node's points, to the last bit (each gap is at most the
/// point's, and rounding keeps the order), so a search that skips the box skips no point it
/// would have taken.
#[inline]
fn box_squared_distance(node: &Node, q: &[f64; 3]) -> f64 {
    let gap = |a: usize| (node.lo[a] - q[a]).max(q[a] - node.hi[a]).max(0.0);
    let d = [gap(0), gap(1), gap(2)];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

#[cfg(test)]
thread_local! {
    /// The candidates this thread's searches offered: what a search costs, for the tests.
    static OFFERS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
    /// The leaves this thread's searches visited.
    static LEAVES: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// `|p − q|²`, summed x, y, z in that order (every query reports bit-identical distances).
#[inline]
fn squared_distance(p: &[f64; 3], q: &[f64; 3]) -> f64 {
    let d = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

/// `out[k]` = [`squared_distance`] from `q` to point k of a leaf given as its x, y and z (each
/// of one length, at most [`LEAF_SIZE`]): the same sums, laid out so the compiler computes
/// several points at once.
#[inline]
fn leaf_squared_distances(xyz: [&[f64]; 3], q: &[f64; 3], out: &mut [f64; LEAF_SIZE]) {
    let n = xyz[0].len();
    let (x, y, z) = (&xyz[0][..n], &xyz[1][..n], &xyz[2][..n]);
    for (k, d2) in out[..n].iter_mut().enumerate() {
        let d = [x[k] - q[0], y[k] - q[1], z[k] - q[2]];
        *d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    }
}

/// Whether `a` comes before `b` in the order of results ([`distance_then_index`]).
#[inline]
fn is_before(a: (usize, f64), b: (usize, f64)) -> bool {
    distance_then_index(&a) < distance_then_index(&b)
}

/// The order of results as a key: by distance, ties by index. Every distance and bound compared
/// is a square or a sum of squares (never negative), whose bits order as its value.
#[inline]
fn distance_then_index(&(i, d2): &(usize, f64)) -> (u64, usize) {
    (d2.to_bits(), i)
}

/// Sorts (index, squared distance) pairs by distance, ties by index.
fn sort_by_distance_then_index(items: &mut [(usize, f64)]) {
    items.sort_unstable_by_key(distance_then_index);
}

/// The (N, K) kNN graph of a cloud, flat row-major: row i lists the K nearest points of point i,
/// itself first (spec §2.1: a point counts as its own nearest neighbour, even when other points
/// coincide with it), then the others by distance, ties by index.
pub fn knn_graph(points: &[Point3<f64>], k: usize) -> Result<Vec<usize>> {
    let n = points.len();
    if k > n {
        return Err(GeomError::TooFewPoints {
            op: "knn_graph",
            needed: k,
            got: n,
        });
    }
    if points
        .iter()
        .any(|p| !p.coords.iter().all(|v| v.is_finite()))
    {
        return Err(GeomError::NonFinite { op: "knn_graph" });
    }
    let index = KnnIndex::new(points);
    let mut graph = Vec::with_capacity(n * k); // (N, K)
    let mut row = Vec::with_capacity(k); // (K,)
    for (i, p) in points.iter().enumerate() {
        if k == 0 {
            break;
        }
        index.k_nearest_squared_into(p, k, &mut row);
        graph.push(i);
        graph.extend(row.iter().map(|&(j, _)| j).filter(|&j| j != i).take(k - 1));
    }
    Ok(graph)
}

#[cfg(test)]
mod tests;
