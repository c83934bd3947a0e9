//! Block-sparse LU (LDU) factorisation on a graph, in a caller-given elimination order.
//!
//! The Newton matrix of a multibody system is block sparse: graph nodes are bodies, joints
//! and contacts, each owning a small dense diagonal block, and an edge couples two nodes
//! through the off-diagonal blocks `(i, j)` and `(j, i)`. The matrix is unsymmetric but its
//! sparsity pattern is symmetric. [`BlockPattern`] runs the elimination game once (when the
//! model is compiled) to find the fill-in and precompute every offset the numeric phase
//! needs; [`BlockMatrix`] then factors and solves every Newton iteration without allocating.
//!
//! The factorisation is right-looking block Gaussian elimination in the given order, with
//! partial pivoting only inside diagonal blocks, so the cost is linear for trees eliminated
//! leaves first and fill-in only appears along cycles. With `k` running over the order and
//! `i`, `j` over the neighbours of `k` eliminated after it, step `k` computes
//!
//! ```text
//! D_k  = A_kk                      (dense LU with pivoting, in place)
//! U_kj = D_k⁻¹ A_kj                (overwrites A_kj)
//! A_ij = A_ij - A_ik U_kj          (Schur complement; A_ik = L_ik D_k is kept)
//! ```
//!
//! so that `A = L̃ Ũ` with `L̃` block lower triangular (diagonal `D_k`, below it `A_ik`) and
//! `Ũ` unit block upper triangular (above the diagonal `U_kj`), in elimination order.

use std::collections::BTreeSet;
use std::ops::Range;

use super::dense::{
    copy_small, gemm_sub, gemv_add, gemv_sub, gemv_t_sub, lu_factor, lu_solve,
    lu_solve_left_matrix, lu_solve_transpose, lu_solve_transpose_left_matrix,
};

/// One elimination step: the node eliminated and where its data lives.
#[derive(Clone, Debug)]
struct Step {
    /// Node eliminated at this step.
    node: usize,
    /// Block dimension of the node.
    dim: usize,
    /// Offset of the node's rows in a node-ordered vector (and of its pivots).
    row: usize,
    /// Offset of the diagonal block `A_kk` in the value arena.
    diag: usize,
    /// Range of this step's later neighbours in [`BlockPattern::nbrs`].
    nbrs: Range<usize>,
    /// Range of this step's Schur updates in [`BlockPattern::updates`].
    updates: Range<usize>,
}

/// A neighbour `j` of the eliminated node `k` that is eliminated later.
#[derive(Clone, Debug)]
struct Nbr {
    /// Block dimension of `j`.
    dim: usize,
    /// Offset of `j`'s rows in a node-ordered vector.
    row: usize,
    /// Arena offset of block `(k, j)` (holds `U_kj` after factorisation).
    kj: usize,
    /// Arena offset of block `(j, k)` (holds `L_jk D_k` after factorisation).
    jk: usize,
    /// Block indices (into [`BlockPattern::cols`]) of `(k, j)` and `(j, k)`.
    kj_id: usize,
    jk_id: usize,
}

/// One Schur update `A_ij -= A_ik U_kj` of an elimination step `k`.
#[derive(Clone, Debug)]
struct Update {
    /// Arena offset of block `(i, j)`, the target.
    ij: usize,
    /// Arena offset of block `(i, k)`.
    ik: usize,
    /// Arena offset of block `(k, j)`.
    kj: usize,
    /// Block dimension of `i`.
    di: usize,
    /// Block dimension of `j`.
    dj: usize,
    /// Block indices of `(i, j)`, `(i, k)` and `(k, j)`.
    ids: [usize; 3],
}

/// Symbolic structure of a block-sparse matrix with symmetric pattern: immutable, built once.
///
/// Holds the block layout (including fill-in for the given elimination order) and the
/// precomputed per-step work lists used by [`BlockMatrix::factor`] and the solves.
#[derive(Clone, Debug)]
pub struct BlockPattern {
    /// Block dimension of each node.
    dims: Vec<usize>,
    /// Start of each node's rows in a node-ordered vector; `offsets[n]` is the total.
    offsets: Vec<usize>,
    /// Elimination order (`order[0]` first).
    order: Vec<usize>,
    /// CSR row starts into `cols` / `vals`, one row per node.
    row_ptr: Vec<usize>,
    /// Sorted column nodes of each row (diagonal, original and fill blocks).
    cols: Vec<usize>,
    /// Arena offset of each stored block, parallel to `cols`.
    vals: Vec<usize>,
    /// Arena length.
    nvalues: usize,
    /// Number of fill edges created by the elimination.
    nfill: usize,
    /// Largest block dimension.
    max_dim: usize,
    /// Elimination steps, in order.
    steps: Vec<Step>,
    /// Later neighbours of all steps, concatenated.
    nbrs: Vec<Nbr>,
    /// Schur updates of all steps, concatenated.
    updates: Vec<Update>,
    /// Per stored block: whether it is a fill block (zero as assembled, written only by the
    /// Schur updates).
    fill: Vec<bool>,
}

impl BlockPattern {
    /// Build the pattern of a graph with node block sizes `dims`, undirected `edges` and
    /// elimination `order`.
    ///
    /// `dims[i] >= 1` is the block size of node `i`; `edges` are pairs `(i, j)` with
    /// `i != j` (duplicates, in either direction, are ignored); `order` must be a
    /// permutation of `0..dims.len()`, `order[0]` being eliminated first. Computes the
    /// fill-in by the elimination game and precomputes all arena offsets and per-step
    /// update lists, so the numeric phase needs no hashing or allocation.
    pub fn new(dims: &[usize], edges: &[(usize, usize)], order: &[usize]) -> Result<Self, String> {
        let n = dims.len();
        if let Some(i) = dims.iter().position(|&d| d == 0) {
            return Err(format!("node {i} has block dimension 0"));
        }
        let pos = positions(order, n)?;
        let mut adj = adjacency(n, edges)?;
        let original = adj.clone();
        let nfill = eliminate(&mut adj, order, &pos);
        let mut offsets = Vec::with_capacity(n + 1);
        let mut total = 0;
        for &d in dims {
            offsets.push(total);
            total += d;
        }
        offsets.push(total);
        let mut p = Self {
            dims: dims.to_vec(),
            offsets,
            order: order.to_vec(),
            row_ptr: Vec::with_capacity(n + 1),
            cols: Vec::new(),
            vals: Vec::new(),
            nvalues: 0,
            nfill,
            max_dim: dims.iter().copied().max().unwrap_or(0),
            steps: Vec::with_capacity(n),
            nbrs: Vec::new(),
            updates: Vec::new(),
            fill: Vec::new(),
        };
        p.layout(&adj);
        p.fill = (0..n)
            .flat_map(|i| (p.row_ptr[i]..p.row_ptr[i + 1]).map(move |idx| (i, idx)))
            .map(|(i, idx)| p.cols[idx] != i && !original[i].contains(&p.cols[idx]))
            .collect();
        p.plan(&adj, &pos)?;
        Ok(p)
    }

    /// Lay out every stored block (diagonal + neighbours) row by row in the value arena.
    fn layout(&mut self, adj: &[BTreeSet<usize>]) {
        for (i, nbrs) in adj.iter().enumerate() {
            self.row_ptr.push(self.cols.len());
            let below = nbrs.range(..i).copied();
            let above = nbrs.range(i + 1..).copied();
            for j in below.chain(std::iter::once(i)).chain(above) {
                self.cols.push(j);
                self.vals.push(self.nvalues);
                self.nvalues += self.dims[i] * self.dims[j];
            }
        }
        self.row_ptr.push(self.cols.len());
    }

    /// Precompute, for each elimination step, its later neighbours and Schur updates.
    fn plan(&mut self, adj: &[BTreeSet<usize>], pos: &[usize]) -> Result<(), String> {
        for &k in &self.order {
            let later: Vec<usize> = adj[k]
                .iter()
                .copied()
                .filter(|&j| pos[j] > pos[k])
                .collect();
            let nbr_start = self.nbrs.len();
            let upd_start = self.updates.len();
            for &j in &later {
                let (kj, jk) = (self.stored(k, j)?, self.stored(j, k)?);
                let (dim, row) = (self.dims[j], self.offsets[j]);
                let (kj_id, jk_id) = (self.id(kj), self.id(jk));
                self.nbrs.push(Nbr {
                    dim,
                    row,
                    kj,
                    jk,
                    kj_id,
                    jk_id,
                });
            }
            for &i in &later {
                for &j in &later {
                    let (ij, ik, kj) = (self.stored(i, j)?, self.stored(i, k)?, self.stored(k, j)?);
                    let (di, dj) = (self.dims[i], self.dims[j]);
                    let ids = [self.id(ij), self.id(ik), self.id(kj)];
                    self.updates.push(Update {
                        ij,
                        ik,
                        kj,
                        di,
                        dj,
                        ids,
                    });
                }
            }
            self.steps.push(Step {
                node: k,
                dim: self.dims[k],
                row: self.offsets[k],
                diag: self.stored(k, k)?,
                nbrs: nbr_start..self.nbrs.len(),
                updates: upd_start..self.updates.len(),
            });
        }
        Ok(())
    }

    /// Block index (position in `cols` / `vals`) of the block stored at arena `offset`
    /// (`vals` is increasing by construction).
    fn id(&self, offset: usize) -> usize {
        self.vals.partition_point(|&v| v < offset)
    }

    /// Number of stored blocks (diagonal, original and fill).
    fn nblocks(&self) -> usize {
        self.cols.len()
    }

    /// [`Self::block`], as an error if the block is missing (an internal inconsistency).
    fn stored(&self, i: usize, j: usize) -> Result<usize, String> {
        self.block(i, j)
            .ok_or_else(|| format!("internal error: block ({i}, {j}) missing after fill-in"))
    }

    /// Number of nodes.
    pub fn nnodes(&self) -> usize {
        self.dims.len()
    }

    /// Block dimension of `node`.
    pub fn dim(&self, node: usize) -> usize {
        self.dims[node]
    }

    /// Largest block dimension (0 for an empty pattern).
    pub fn max_dim(&self) -> usize {
        self.max_dim
    }

    /// Sum of all block dimensions (the matrix size).
    pub fn total_dim(&self) -> usize {
        self.offsets[self.dims.len()]
    }

    /// Start of `node`'s rows in a flat vector laid out in node index order.
    pub fn offset(&self, node: usize) -> usize {
        self.offsets[node]
    }

    /// The elimination order (`order()[0]` is eliminated first).
    pub fn order(&self) -> &[usize] {
        &self.order
    }

    /// Offset in the value arena of block `(i, j)` (row node `i`, column node `j`), stored
    /// row-major as `dim(i) × dim(j)`.
    ///
    /// `Some` for `i == j`, for every original edge (both directions) and every fill edge;
    /// `None` otherwise (including out-of-range nodes).
    pub fn block(&self, i: usize, j: usize) -> Option<usize> {
        let row = *self.row_ptr.get(i)?..*self.row_ptr.get(i + 1)?;
        let cols = &self.cols[row.clone()];
        cols.binary_search(&j)
            .ok()
            .map(|idx| self.vals[row.start + idx])
    }

    /// Length of the value arena.
    pub fn nvalues(&self) -> usize {
        self.nvalues
    }

    /// Number of fill edges created by the elimination (each counted once).
    pub fn nfill(&self) -> usize {
        self.nfill
    }
}

/// Inverse of the permutation `order` of `0..n`, or an error if it is not one.
fn positions(order: &[usize], n: usize) -> Result<Vec<usize>, String> {
    if order.len() != n {
        return Err(format!("order has {} entries, expected {n}", order.len()));
    }
    let mut pos = vec![usize::MAX; n];
    for (p, &node) in order.iter().enumerate() {
        match pos.get_mut(node) {
            None => return Err(format!("order entry {node} out of range (n = {n})")),
            Some(slot) if *slot != usize::MAX => {
                return Err(format!("node {node} appears twice in order"));
            }
            Some(slot) => *slot = p,
        }
    }
    Ok(pos)
}

/// Sorted neighbour sets of the undirected graph, or an error for a bad edge.
fn adjacency(n: usize, edges: &[(usize, usize)]) -> Result<Vec<BTreeSet<usize>>, String> {
    let mut adj = vec![BTreeSet::new(); n];
    for &(i, j) in edges {
        if i >= n || j >= n {
            return Err(format!("edge ({i}, {j}) out of range (n = {n})"));
        }
        if i == j {
            return Err(format!("self edge ({i}, {i})"));
        }
        adj[i].insert(j);
        adj[j].insert(i);
    }
    Ok(adj)
}

/// Elimination game: eliminating `k` connects all its later neighbours pairwise.
/// Adds the fill edges to `adj` and returns how many were created.
fn eliminate(adj: &mut [BTreeSet<usize>], order: &[usize], pos: &[usize]) -> usize {
    let mut nfill = 0;
    for &k in order {
        let later: Vec<usize> = adj[k]
            .iter()
            .copied()
            .filter(|&j| pos[j] > pos[k])
            .collect();
        for (a, &i) in later.iter().enumerate() {
            for &j in &later[a + 1..] {
                if adj[i].insert(j) {
                    adj[j].insert(i);
                    nfill += 1;
                }
            }
        }
    }
    nfill
}

/// Borrow `v[out]` mutably and `v[a]`, `v[b]` immutably; `out` must be disjoint from both.
fn split3(
    v: &mut [f64],
    out: Range<usize>,
    a: Range<usize>,
    b: Range<usize>,
) -> (&mut [f64], &[f64], &[f64]) {
    let (lo, rest) = v.split_at_mut(out.start);
    let (mid, hi) = rest.split_at_mut(out.len());
    let (lo, hi): (&[f64], &[f64]) = (lo, hi);
    (mid, pick(lo, hi, out.end, a), pick(lo, hi, out.end, b))
}

/// The range `r` of the original slice, found in `lo` (before the hole) or `hi` (from `hi_start`).
fn pick<'a>(lo: &'a [f64], hi: &'a [f64], hi_start: usize, r: Range<usize>) -> &'a [f64] {
    if r.end <= lo.len() {
        &lo[r]
    } else {
        &hi[r.start - hi_start..r.end - hi_start]
    }
}

/// Numeric values and factorisation of a matrix with a given [`BlockPattern`], reused
/// every iteration.
///
/// Typical cycle: [`zero`](Self::zero), assemble with [`block_mut`](Self::block_mut) /
/// [`add_to_block`](Self::add_to_block), [`factor`](Self::factor), then any number of
/// [`solve`](Self::solve) / [`solve_transpose`](Self::solve_transpose) calls. Factoring
/// overwrites `values`, so zero and reassemble before factoring again.
#[derive(Clone, Debug)]
pub struct BlockMatrix {
    /// Value arena: block `(i, j)` is `values[p.block(i, j)..][..dim(i) * dim(j)]`, row-major.
    /// Fill blocks must be zero before [`factor`](Self::factor).
    pub values: Vec<f64>,
    /// Pivots of the diagonal blocks, laid out like a node-ordered vector.
    pivots: Vec<usize>,
    /// Scratch vector of length `max_dim` for the solves.
    scratch: Vec<f64>,
    /// Scratch of [`solve_transpose_many`](Self::solve_transpose_many), `max_dim × k`.
    many: Vec<f64>,
    /// Nodes left out of the factorisation and the solves (see [`Self::set_skipped`]).
    skip: Vec<bool>,
    /// Copy of the nonzero blocks of `values` as assembled (those of `assembled_nz`, outside
    /// skipped rows), taken by [`factor`](Self::factor) for the residuals of
    /// [`solve_refined`](Self::solve_refined).
    assembled: Vec<f64>,
    /// Three node-ordered scratch vectors for [`solve_refined`](Self::solve_refined).
    refine: [Vec<f64>; 3],
    /// Per stored block: whether it holds a nonzero in the factors (grown by the Schur
    /// updates). Blocks that stay zero are skipped by the factorisation and the solves: fill
    /// created for contact candidates that are inactive this step (e.g. between the limbs of a
    /// humanoid) costs nothing.
    nz: Vec<bool>,
    /// What the last [`factor`](Self::factor) left in (boxed: a workspace is moved around
    /// by value).
    live: Box<Live>,
}

/// The part of the matrix that the last factorisation did not skip. The solves and the
/// refinement touch only this: a step with a thousand inactive contact candidates and fifty
/// active ones costs what the fifty do.
#[derive(Clone, Debug, Default)]
struct Live {
    /// The nodes not skipped, in node order, and their elimination steps (indices into the
    /// pattern's steps); rebuilt when `stale` after [`BlockMatrix::set_skipped`] changed a node.
    nodes: Vec<usize>,
    steps: Vec<usize>,
    /// The fill blocks between two nodes not skipped, `(row node, block index)`: the ones
    /// [`BlockMatrix::zero`] clears if the last factorisation wrote them.
    zero_blocks: Vec<(usize, usize)>,
    /// The value ranges of those that are not fill blocks, adjacent ones merged: one `fill` a
    /// range instead of one a block (a `memset` call each, 2% of a humanoid step).
    zero_ranges: Vec<Range<usize>>,
    /// Those blocks themselves, `(row node, block index)` in row order: the ones a
    /// factorisation scans for nonzeros (the rows' blocks in skipped columns, most of a body
    /// row's among hundreds of inactive candidates, are zero: `nz` is cleared once here).
    scan: Vec<(usize, usize)>,
    stale: bool,
    /// Nonzero assembled blocks of their rows, `(row node, block index)`, row by row.
    blocks: Vec<(usize, usize)>,
    /// Their row ranges (adjacent nodes merged).
    rows: Vec<Range<usize>>,
    /// Whether the last factorisation kept `blocks` (see [`BlockMatrix::factor_keeping`]).
    refinable: bool,
    /// Scratch of the factorisation: positions among a step's later neighbours `i` with
    /// `A_ik ≠ 0` and `j` with `U_kj ≠ 0`.
    update_rows: Vec<usize>,
    update_cols: Vec<usize>,
}

impl BlockMatrix {
    /// A zero matrix with pattern `p`.
    pub fn new(p: &BlockPattern) -> Self {
        Self {
            values: vec![0.0; p.nvalues()],
            pivots: vec![0; p.total_dim()],
            scratch: vec![0.0; p.max_dim()],
            many: Vec::new(),
            skip: vec![false; p.nnodes()],
            assembled: vec![0.0; p.nvalues()],
            refine: std::array::from_fn(|_| vec![0.0; p.total_dim()]),
            nz: vec![true; p.nblocks()],
            live: Box::new(Live {
                nodes: (0..p.nnodes()).collect(),
                steps: (0..p.steps.len()).collect(),
                // (built by the first `refresh_live`)
                zero_blocks: Vec::new(),
                scan: Vec::new(),
                zero_ranges: Vec::new(),
                stale: true,
                blocks: Vec::with_capacity(p.nblocks()),
                rows: Vec::with_capacity(p.nnodes()),
                update_rows: Vec::with_capacity(p.nnodes()),
                update_cols: Vec::with_capacity(p.nnodes()),
                refinable: true,
            }),
        }
    }

    /// Leave `node` out of [`factor`](Self::factor) and the solves: its block row and column
    /// become those of the identity (diagonal block `I`, every coupling block zero), so the node
    /// decouples, its solution entries equal the right-hand side and it contributes nothing to
    /// the Schur complements; skipping it changes no result but saves its factorisation and
    /// updates. Used for inactive contact candidates. A skipped node's blocks must not be
    /// written; they keep the identity through [`zero`](Self::zero) and the factorisation, so
    /// a node skipped iteration after iteration costs nothing. Unskipping zeroes them.
    pub fn set_skipped(&mut self, p: &BlockPattern, node: usize, skipped: bool) {
        if self.skip[node] == skipped {
            return;
        }
        self.skip[node] = skipped;
        self.live.stale = true;
        // the pattern is symmetric: the row's column nodes are the column's row nodes
        for idx in p.row_ptr[node]..p.row_ptr[node + 1] {
            let (j, off) = (p.cols[idx], p.vals[idx]);
            // a skipped row is the identity's (`factor` visits only the live rows)
            self.nz[idx] = !skipped || j == node;
            let len = p.dims[node] * p.dims[j];
            self.values[off..off + len].fill(0.0);
            if j == node && skipped {
                (0..len)
                    .step_by(p.dims[j] + 1)
                    .for_each(|k| self.values[off + k] = 1.0);
            }
            if let Some(off) = p.block(j, node).filter(|_| j != node) {
                self.values[off..off + len].fill(0.0);
            }
        }
    }

    /// Rebuild the lists of live nodes and steps after [`Self::set_skipped`] changed a node.
    fn refresh_live(&mut self, p: &BlockPattern) {
        let live = &mut *self.live;
        if !live.stale {
            return;
        }
        live.nodes.clear();
        live.nodes
            .extend((0..p.nnodes()).filter(|&i| !self.skip[i]));
        live.steps.clear();
        let steps = (0..p.steps.len()).filter(|&k| !self.skip[p.steps[k].node]);
        live.steps.extend(steps);
        live.zero_blocks.clear();
        live.zero_ranges.clear();
        live.scan.clear();
        for &i in &live.nodes {
            for idx in p.row_ptr[i]..p.row_ptr[i + 1] {
                if self.skip[p.cols[idx]] {
                    // (a skipped node is never the row's own: its block stays zero)
                    self.nz[idx] = false;
                    continue;
                }
                if p.fill[idx] {
                    live.zero_blocks.push((i, idx));
                    continue;
                }
                live.scan.push((i, idx));
                let r = p.vals[idx]..p.vals[idx] + p.dims[i] * p.dims[p.cols[idx]];
                match live.zero_ranges.last_mut() {
                    Some(last) if last.end == r.start => last.end = r.end,
                    _ => live.zero_ranges.push(r),
                }
            }
        }
        live.stale = false;
    }

    /// Row ranges of the nodes the last [`factor`](Self::factor) did not skip: the only rows
    /// the solves read or write.
    pub fn live_rows(&self) -> &[Range<usize>] {
        &self.live.rows
    }

    /// Whether `node` is left out of the factorisation (see [`Self::set_skipped`]).
    #[inline]
    pub fn is_skipped(&self, node: usize) -> bool {
        self.skip[node]
    }

    /// Whether every node in `nodes` is skipped.
    pub fn all_skipped(&self, nodes: std::ops::Range<usize>) -> bool {
        !self.skip[nodes].contains(&false)
    }

    /// Set all values (including fill blocks) to zero, keeping the allocation, except the
    /// identity blocks of skipped nodes (see [`Self::set_skipped`]): with hundreds of inactive
    /// contact candidates, clearing their blocks every iteration cost more than the solve.
    pub fn zero(&mut self, p: &BlockPattern) {
        self.refresh_live(p);
        // (a list of the live blocks: scanning each live row's blocks for live columns cost
        // as much as clearing them, the A1's body rows holding hundreds of candidates)
        for r in &self.live.zero_ranges {
            self.values[r.clone()].fill(0.0);
        }
        for &(i, idx) in &self.live.zero_blocks {
            // a fill block holds values only if the last factorisation's updates wrote it
            if self.nz[idx] {
                let len = p.dims[i] * p.dims[p.cols[idx]];
                self.values[p.vals[idx]..p.vals[idx] + len].fill(0.0);
            }
        }
    }

    /// Mutable row-major view of block `(i, j)`, or `None` if it is not stored.
    pub fn block_mut(&mut self, p: &BlockPattern, i: usize, j: usize) -> Option<&mut [f64]> {
        let off = p.block(i, j)?;
        self.values.get_mut(off..off + p.dim(i) * p.dim(j))
    }

    /// `values[offset..offset + rows * cols] += src` (a row-major `rows × cols` block).
    ///
    /// Panics if the range is outside the arena or `src` is shorter than `rows * cols`.
    pub fn add_to_block(&mut self, offset: usize, rows: usize, cols: usize, src: &[f64]) {
        let dst = &mut self.values[offset..offset + rows * cols];
        for (d, s) in dst.iter_mut().zip(&src[..rows * cols]) {
            *d += s;
        }
    }

    /// `y = A x` with the current (unfactored) values; both vectors laid out in node order.
    ///
    /// Only meaningful before [`factor`](Self::factor), which overwrites the values.
    pub fn matvec(&self, p: &BlockPattern, x: &[f64], y: &mut [f64]) {
        block_matvec(p, &self.values, None, x, y);
    }

    /// Solve `A x = b` in place like [`solve`](Self::solve), then improve `x` by up to
    /// `rounds` steps of iterative refinement (`x += A⁻¹(b - A x)` with the residual taken
    /// against the matrix as assembled), stopping when the residual no longer halves or is
    /// within `enough` of the right-hand side's largest entry (max norms).
    ///
    /// Why: near the end of an interior-point solve the Newton matrix of a contact step has
    /// condition numbers of 1e10-1e14 and the block elimination pivots only inside blocks, so
    /// a plain solve can return a direction that does not decrease the merit function at all;
    /// one or two refinement steps restore a direction accurate to the conditioning of the
    /// problem at the cost of a mat-vec and a back-substitution each.
    ///
    /// Only the rows of nodes that are not skipped take part: a skipped node's solution entries
    /// are its right-hand side, so its residual rows are exactly zero and its corrections too.
    pub fn solve_refined(&mut self, p: &BlockPattern, b: &mut [f64], rounds: usize, enough: f64) {
        if !self.live.refinable {
            self.solve(p, b);
            return;
        }
        let [mut rhs, mut res, mut step] = std::mem::take(&mut self.refine);
        let rows = std::mem::take(&mut self.live.rows);
        let mut scale = 0.0f64;
        for r in &rows {
            rhs[r.clone()].copy_from_slice(&b[r.clone()]);
            scale = rhs[r.clone()].iter().fold(scale, |m, v| m.max(v.abs()));
        }
        self.solve(p, b);
        let mut last = f64::INFINITY;
        for round in 0..=rounds {
            // res = rhs - A x
            for r in &rows {
                res[r.clone()].fill(0.0);
            }
            for &(i, idx) in &self.live.blocks {
                let (oi, di, j) = (p.offsets[i], p.dims[i], p.cols[idx]);
                let xj = &b[p.offsets[j]..p.offsets[j] + p.dims[j]];
                gemv_add(
                    &mut res[oi..oi + di],
                    &self.assembled[p.vals[idx]..],
                    xj,
                    di,
                    xj.len(),
                );
            }
            let mut norm = 0.0f64;
            for r in &rows {
                for (r, f) in res[r.clone()].iter_mut().zip(&rhs[r.clone()]) {
                    *r = f - *r;
                    norm = norm.max(r.abs());
                }
            }
            if norm <= enough * scale {
                break;
            }
            // NaN compares false: a NaN residual stops the refinement like a growing one
            let halved = norm < 0.5 * last;
            if !halved {
                let improved = norm < last;
                if round > 0 && !improved {
                    // the last correction did not help: take it back
                    for r in &rows {
                        b[r.clone()]
                            .iter_mut()
                            .zip(&step[r.clone()])
                            .for_each(|(x, d)| *x -= d);
                    }
                }
                break;
            }
            if round == rounds || norm == 0.0 {
                break;
            }
            last = norm;
            for r in &rows {
                step[r.clone()].copy_from_slice(&res[r.clone()]);
            }
            // (the skipped rows of `step` are neither read nor written by the solve)
            self.solve(p, &mut step);
            for r in &rows {
                b[r.clone()]
                    .iter_mut()
                    .zip(&step[r.clone()])
                    .for_each(|(x, d)| *x += d);
            }
        }
        self.refine = [rhs, res, step];
        self.live.rows = rows;
    }
}

/// `y = A x` for the block values `values` laid out by pattern `p`; blocks flagged zero in
/// `nz` are skipped.
fn block_matvec(p: &BlockPattern, values: &[f64], nz: Option<&[bool]>, x: &[f64], y: &mut [f64]) {
    y.fill(0.0);
    for i in 0..p.nnodes() {
        let (oi, di) = (p.offset(i), p.dim(i));
        for idx in p.row_ptr[i]..p.row_ptr[i + 1] {
            if nz.is_some_and(|nz| !nz[idx]) {
                continue;
            }
            let (j, off) = (p.cols[idx], p.vals[idx]);
            let xj = &x[p.offset(j)..p.offset(j) + p.dim(j)];
            // y_i += A_ij x_j
            gemv_add(&mut y[oi..oi + di], &values[off..], xj, di, p.dim(j));
        }
    }
}

impl BlockMatrix {
    /// In-place block LU factorisation in the pattern's elimination order.
    ///
    /// Returns `Err(node)` if the (Schur-complemented) diagonal block of `node` is singular
    /// or not finite; the values are then partially factored and must be reassembled.
    pub fn factor(&mut self, p: &BlockPattern) -> Result<(), usize> {
        self.factor_keeping(p, true)
    }

    /// [`factor`](Self::factor) without keeping a copy of the matrix as assembled when
    /// `refinable` is false: the next solves are then not refined ([`solve_refined`] solves
    /// once). For callers that know no solve with this factorisation will be refined: copying
    /// the assembled blocks was 3.5% of a humanoid step, and the interior-point loop refines
    /// only near its solution (`ipm::REFINE_BELOW`).
    ///
    /// [`solve_refined`]: Self::solve_refined
    pub fn factor_keeping(&mut self, p: &BlockPattern, refinable: bool) -> Result<(), usize> {
        self.refresh_live(p);
        // keep the nonzero blocks of the nodes not skipped as assembled, for `solve_refined`
        // (a skipped node's row keeps the identity's `nz` from `set_skipped`)
        let live = &mut *self.live;
        live.blocks.clear();
        live.rows.clear();
        live.refinable = refinable;
        for &i in &live.nodes {
            let rows = p.offsets[i]..p.offsets[i + 1];
            match live.rows.last_mut() {
                Some(last) if last.end == rows.start => last.end = rows.end,
                _ => live.rows.push(rows),
            }
        }
        // fill blocks are zero as assembled (see `Self::values`); those of skipped columns
        // were cleared by `refresh_live`
        for &(_, idx) in &live.zero_blocks {
            self.nz[idx] = false;
        }
        for &(i, idx) in &live.scan {
            let range = p.vals[idx]..p.vals[idx] + p.dims[i] * p.dims[p.cols[idx]];
            let block = &self.values[range.clone()];
            // NaN != 0: a non-finite block is kept and reported by the factorisation
            self.nz[idx] = block.iter().any(|&v| v != 0.0);
            if self.nz[idx] && refinable {
                self.assembled[range.clone()].copy_from_slice(&self.values[range]);
                live.blocks.push((i, idx));
            }
        }
        for s in self.live.steps.iter().map(|&k| &p.steps[k]) {
            let dk = s.dim;
            let piv = &mut self.pivots[s.row..s.row + dk];
            // D_k = A_kk = P L U
            if !lu_factor(&mut self.values[s.diag..s.diag + dk * dk], dk, piv) {
                return Err(s.node);
            }
            let diag = s.diag..s.diag + dk * dk;
            for nb in p.nbrs[s.nbrs.clone()].iter().filter(|nb| self.nz[nb.kj_id]) {
                let kj = nb.kj..nb.kj + dk * nb.dim;
                let (akj, d, _) = split3(&mut self.values, kj, diag.clone(), diag.clone());
                // U_kj = D_k⁻¹ A_kj
                lu_solve_left_matrix(d, dk, piv, akj, nb.dim);
            }
            // A_ij -= A_ik U_kj only for later neighbours i with A_ik ≠ 0 and j with U_kj ≠ 0
            // (a body with many fill neighbours from inactive contacts has few of each)
            let nbrs = &p.nbrs[s.nbrs.clone()];
            let (rows, cols) = (&mut self.live.update_rows, &mut self.live.update_cols);
            rows.clear();
            cols.clear();
            for (a, nb) in nbrs.iter().enumerate() {
                if self.nz[nb.jk_id] {
                    rows.push(a);
                }
                if self.nz[nb.kj_id] {
                    cols.push(a);
                }
            }
            let pairs = rows
                .iter()
                .flat_map(|&a| cols.iter().map(move |&b| a * nbrs.len() + b));
            for u in pairs.map(|ab| &p.updates[s.updates.start + ab]) {
                let ij_id = u.ids[0];
                self.nz[ij_id] = true;
                let ij = u.ij..u.ij + u.di * u.dj;
                let (ik, kj) = (u.ik..u.ik + u.di * dk, u.kj..u.kj + dk * u.dj);
                let (aij, aik, ukj) = split3(&mut self.values, ij, ik, kj);
                // A_ij -= A_ik U_kj
                gemm_sub(aij, aik, ukj, u.di, dk, u.dj);
            }
        }
        Ok(())
    }

    /// Solve `A x = b` in place (`b` laid out in node order, see [`BlockPattern::offset`]),
    /// using the factorisation from a successful [`factor`](Self::factor).
    ///
    /// Panics if `b.len() != p.total_dim()`.
    pub fn solve(&mut self, p: &BlockPattern, b: &mut [f64]) {
        assert_eq!(
            b.len(),
            p.total_dim(),
            "right-hand side has the wrong length"
        );
        let z = &mut self.scratch;
        // Forward, L̃ z = b: z_k = D_k⁻¹ y_k, then y_i -= A_ik z_k for later i.
        for s in self.live.steps.iter().map(|&k| &p.steps[k]) {
            let (dk, rows) = (s.dim, s.row..s.row + s.dim);
            let piv = &self.pivots[rows.clone()];
            lu_solve(&self.values[s.diag..], dk, piv, &mut b[rows.clone()]);
            copy_small(z, &b[rows], dk);
            for nb in p.nbrs[s.nbrs.clone()].iter().filter(|nb| self.nz[nb.jk_id]) {
                let yi = &mut b[nb.row..nb.row + nb.dim];
                gemv_sub(yi, &self.values[nb.jk..], &z[..dk], nb.dim, dk);
            }
        }
        // Backward, Ũ x = z: x_k = z_k - Σ_{later j} U_kj x_j.
        for s in self.live.steps.iter().rev().map(|&k| &p.steps[k]) {
            let (dk, rows) = (s.dim, s.row..s.row + s.dim);
            copy_small(z, &b[rows.clone()], dk);
            for nb in p.nbrs[s.nbrs.clone()].iter().filter(|nb| self.nz[nb.kj_id]) {
                let xj = &b[nb.row..nb.row + nb.dim];
                gemv_sub(&mut z[..dk], &self.values[nb.kj..], xj, dk, nb.dim);
            }
            copy_small(&mut b[rows], z, dk);
        }
    }

    /// Solve `Aᵀ x = b` in place (`b` laid out in node order), using the same
    /// factorisation as [`solve`](Self::solve) (`Aᵀ = Ũᵀ L̃ᵀ`).
    pub fn solve_transpose(&mut self, p: &BlockPattern, b: &mut [f64]) {
        assert_eq!(
            b.len(),
            p.total_dim(),
            "right-hand side has the wrong length"
        );
        let w = &mut self.scratch;
        // Forward, Ũᵀ w = b: w_k = y_k, then y_j -= U_kjᵀ w_k for later j.
        for s in self.live.steps.iter().map(|&k| &p.steps[k]) {
            let (dk, rows) = (s.dim, s.row..s.row + s.dim);
            copy_small(w, &b[rows], dk);
            for nb in p.nbrs[s.nbrs.clone()].iter().filter(|nb| self.nz[nb.kj_id]) {
                let yj = &mut b[nb.row..nb.row + nb.dim];
                gemv_t_sub(yj, &self.values[nb.kj..], &w[..dk], dk, nb.dim);
            }
        }
        // Backward, L̃ᵀ x = w: x_k = D_k⁻ᵀ (w_k - Σ_{later i} A_ikᵀ x_i).
        for s in self.live.steps.iter().rev().map(|&k| &p.steps[k]) {
            let (dk, rows) = (s.dim, s.row..s.row + s.dim);
            copy_small(w, &b[rows.clone()], dk);
            for nb in p.nbrs[s.nbrs.clone()].iter().filter(|nb| self.nz[nb.jk_id]) {
                let xi = &b[nb.row..nb.row + nb.dim];
                gemv_t_sub(&mut w[..dk], &self.values[nb.jk..], xi, nb.dim, dk);
            }
            let piv = &self.pivots[rows.clone()];
            lu_solve_transpose(&self.values[s.diag..], dk, piv, &mut w[..dk]);
            copy_small(&mut b[rows], w, dk);
        }
    }

    /// [`solve_transpose`](Self::solve_transpose) for `k` right-hand sides at once: row `r`
    /// of the `total_dim × k` right-hand side (and solution) is `b[r * k..(r + 1) * k]`.
    /// Each block product becomes rank-one updates of `k`-long rows, which vectorise, in
    /// place of `k` passes over the factors; every entry sees the same floating-point
    /// operations in the same order as in `k` single solves, so the results are identical.
    /// Rows of skipped nodes are neither read nor written.
    ///
    /// Panics if `b.len() != p.total_dim() * k`.
    pub fn solve_transpose_many(&mut self, p: &BlockPattern, b: &mut [f64], k: usize) {
        assert_eq!(
            b.len(),
            p.total_dim() * k,
            "right-hand sides have the wrong length"
        );
        let Self {
            values,
            pivots,
            many,
            nz,
            live,
            ..
        } = self;
        many.resize(p.max_dim() * k, 0.0);
        let rows_of = |row: usize, dim: usize| row * k..(row + dim) * k;
        // `y -= Mᵀ x` for `M` `m × n` row-major, `x` `m × k` and `y` `n × k` row-major: row by
        // row of `M`, as `gemv_t_sub` does for one right-hand side
        let sub_t = |y: &mut [f64], m: &[f64], x: &[f64], rows: usize, cols: usize| {
            for (r, x_r) in x.chunks_exact(k).take(rows).enumerate() {
                for (c, y_c) in y.chunks_exact_mut(k).take(cols).enumerate() {
                    let a = m[r * cols + c];
                    y_c.iter_mut().zip(x_r).for_each(|(y, x)| *y -= x * a);
                }
            }
        };
        // Forward, Ũᵀ W = B: W_k = Y_k, then Y_j -= U_kjᵀ W_k for later j.
        for s in live.steps.iter().map(|&i| &p.steps[i]) {
            let dk = s.dim;
            let w = &mut many[..dk * k];
            w.copy_from_slice(&b[rows_of(s.row, dk)]);
            for nb in p.nbrs[s.nbrs.clone()].iter().filter(|nb| nz[nb.kj_id]) {
                let u = &values[nb.kj..nb.kj + dk * nb.dim];
                sub_t(&mut b[rows_of(nb.row, nb.dim)], u, w, dk, nb.dim);
            }
        }
        // Backward, L̃ᵀ X = W: X_k = D_k⁻ᵀ (W_k - Σ_{later i} A_ikᵀ X_i).
        for s in live.steps.iter().rev().map(|&i| &p.steps[i]) {
            let dk = s.dim;
            let w = &mut many[..dk * k];
            w.copy_from_slice(&b[rows_of(s.row, dk)]);
            for nb in p.nbrs[s.nbrs.clone()].iter().filter(|nb| nz[nb.jk_id]) {
                let a = &values[nb.jk..nb.jk + nb.dim * dk];
                sub_t(w, a, &b[rows_of(nb.row, nb.dim)], nb.dim, dk);
            }
            let piv = &pivots[s.row..s.row + dk];
            lu_solve_transpose_left_matrix(&values[s.diag..], dk, piv, w, k);
            b[rows_of(s.row, dk)].copy_from_slice(w);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};
    use proptest::prelude::*;

    use crate::solver::test_rng::Rng;

    /// Fill the diagonal blocks (random + `shift`·I) and both blocks of every edge (random).
    fn assemble(
        p: &BlockPattern,
        edges: &[(usize, usize)],
        shift: f64,
        rng: &mut Rng,
    ) -> BlockMatrix {
        let mut m = BlockMatrix::new(p);
        for i in 0..p.nnodes() {
            let d = p.dim(i);
            let blk = m.block_mut(p, i, i).unwrap();
            blk.copy_from_slice(&rng.vec(d * d));
            (0..d).for_each(|r| blk[r * d + r] += shift);
        }
        for &(i, j) in edges {
            for (r, c) in [(i, j), (j, i)] {
                let len = p.dim(r) * p.dim(c);
                m.block_mut(p, r, c).unwrap().copy_from_slice(&rng.vec(len));
            }
        }
        m
    }

    /// Dense copy of the (unfactored) matrix, in node order.
    fn dense(p: &BlockPattern, m: &BlockMatrix) -> DMatrix<f64> {
        let mut a = DMatrix::zeros(p.total_dim(), p.total_dim());
        for i in 0..p.nnodes() {
            for j in 0..p.nnodes() {
                let Some(off) = p.block(i, j) else { continue };
                let (di, dj) = (p.dim(i), p.dim(j));
                for r in 0..di {
                    for c in 0..dj {
                        a[(p.offset(i) + r, p.offset(j) + c)] = m.values[off + r * dj + c];
                    }
                }
            }
        }
        a
    }

    /// Relative error ‖x - y‖ / ‖y‖.
    fn rel(x: &[f64], y: &[f64]) -> f64 {
        let (xv, yv) = (DVector::from_column_slice(x), DVector::from_column_slice(y));
        (xv - &yv).norm() / yv.norm().max(f64::MIN_POSITIVE)
    }

    /// Factor, solve and transpose-solve; check residuals (< 1e-10) and against nalgebra.
    fn check(p: &BlockPattern, mut m: BlockMatrix, rng: &mut Rng) {
        let a = dense(p, &m);
        let orig = m.clone();
        m.factor(p).unwrap();
        let n = p.total_dim();
        for _ in 0..3 {
            let b = rng.vec(n);
            // A x = b
            let mut x = b.clone();
            m.solve(p, &mut x);
            let mut ax = vec![0.0; n];
            orig.matvec(p, &x, &mut ax);
            assert!(rel(&ax, &b) < 1e-10, "residual {}", rel(&ax, &b));
            let xr = a
                .clone()
                .lu()
                .solve(&DVector::from_column_slice(&b))
                .unwrap();
            assert!(rel(&x, xr.as_slice()) < 1e-8);
            // Aᵀ x = b
            let mut xt = b.clone();
            m.solve_transpose(p, &mut xt);
            let atx = a.transpose() * DVector::from_column_slice(&xt);
            assert!(rel(atx.as_slice(), &b) < 1e-10, "transposed residual");
            let xtr = a
                .transpose()
                .lu()
                .solve(&DVector::from_column_slice(&b))
                .unwrap();
            assert!(rel(&xt, xtr.as_slice()) < 1e-8);
        }
        // (its own random stream: the other tests' draws stay as they were)
        many_rhs_match_single_solves(p, &mut m, &mut Rng(n as u64));
    }

    /// `solve_transpose_many` gives, bit for bit, the `solve_transpose` of each column, and
    /// leaves the rows of skipped nodes as they were.
    fn many_rhs_match_single_solves(p: &BlockPattern, m: &mut BlockMatrix, rng: &mut Rng) {
        let (n, k) = (p.total_dim(), 3);
        let cols: Vec<Vec<f64>> = (0..k).map(|_| rng.vec(n)).collect();
        let mut many: Vec<f64> = (0..n * k).map(|i| cols[i % k][i / k]).collect();
        m.solve_transpose_many(p, &mut many, k);
        for (c, col) in cols.iter().enumerate() {
            let mut x = col.clone();
            m.solve_transpose(p, &mut x);
            for node in 0..p.nnodes() {
                for r in p.offset(node)..p.offset(node) + p.dim(node) {
                    let want = if m.is_skipped(node) { col[r] } else { x[r] };
                    assert_eq!(many[r * k + c].to_bits(), want.to_bits(), "row {r} rhs {c}");
                }
            }
        }
    }

    #[test]
    fn chain_has_no_fill() {
        let mut rng = Rng(1);
        let dims: Vec<usize> = (0..9).map(|i| [6, 5, 3, 6, 1, 2][i % 6]).collect();
        let edges: Vec<(usize, usize)> = (1..9).map(|i| (i - 1, i)).collect();
        // Both leaves inwards: 0, 8, 1, 7, ... meeting in the middle.
        let order = [0, 8, 1, 7, 2, 6, 3, 5, 4];
        let p = BlockPattern::new(&dims, &edges, &order).unwrap();
        assert_eq!(p.nfill(), 0);
        assert_eq!(p.total_dim(), dims.iter().sum::<usize>());
        assert!(p.block(0, 2).is_none() && p.block(3, 2).is_some());
        let m = assemble(&p, &edges, 4.0, &mut rng);
        check(&p, m, &mut rng);
    }

    #[test]
    fn branching_tree_has_no_fill() {
        let mut rng = Rng(2);
        let parent = [0, 0, 0, 1, 1, 2, 2, 2, 4, 4, 7];
        let dims = [6, 3, 6, 1, 5, 6, 2, 4, 6, 6, 3];
        let edges: Vec<(usize, usize)> = (1..11).map(|i| (parent[i], i)).collect();
        // Children have larger indices than parents: reverse index order is leaves first.
        let order: Vec<usize> = (0..11).rev().collect();
        let p = BlockPattern::new(&dims, &edges, &order).unwrap();
        assert_eq!(p.nfill(), 0);
        let m = assemble(&p, &edges, 3.0, &mut rng);
        check(&p, m, &mut rng);
    }

    #[test]
    fn cycle_creates_fill_and_stays_exact() {
        let mut rng = Rng(3);
        let dims = [6, 2, 6, 3, 6, 1];
        let edges: Vec<(usize, usize)> = (0..6).map(|i| (i, (i + 1) % 6)).collect();
        let p = BlockPattern::new(&dims, &edges, &[0, 1, 2, 3, 4, 5]).unwrap();
        // Eliminating around a 6-cycle links the last node to each remaining one.
        assert_eq!(p.nfill(), 3);
        assert!(p.block(1, 5).is_some() && p.block(5, 1).is_some());
        let m = assemble(&p, &edges, 2.0, &mut rng);
        check(&p, m, &mut rng);
    }

    /// Bodies (SPD 6×6) and joints (zero diagonal) of a random tree, plus `loops` loop joints.
    /// Order: each body, then the joint to its parent; loop joints last.
    fn multibody(nb: usize, loops: usize, rng: &mut Rng) -> (BlockPattern, BlockMatrix) {
        let mut dims = vec![6; nb];
        let mut links = Vec::new(); // (joint, child body, parent body < child)
        for b in 1..nb {
            links.push((dims.len(), b, rng.below(b)));
            dims.push(1 + rng.below(5));
        }
        let mut order = Vec::new();
        for b in (1..nb).rev() {
            order.extend([b, nb + b - 1]);
        }
        order.push(0);
        for _ in 0..loops {
            let (a, b) = (rng.below(nb), rng.below(nb));
            links.push((dims.len(), a, if a == b { (a + 1) % nb } else { b }));
            order.push(dims.len());
            dims.push(1 + rng.below(3));
        }
        let edges: Vec<(usize, usize)> = links
            .iter()
            .flat_map(|&(j, a, b)| [(j, a), (j, b)])
            .collect();
        let p = BlockPattern::new(&dims, &edges, &order).unwrap();
        let mut m = BlockMatrix::new(&p);
        for b in 0..nb {
            // M = R Rᵀ + I
            let r = DMatrix::from_row_slice(6, 6, &rng.vec(36));
            let mass = &r * r.transpose() + DMatrix::identity(6, 6);
            m.block_mut(&p, b, b)
                .unwrap()
                .copy_from_slice(mass.transpose().as_slice());
        }
        for &(j, a, b) in &links {
            for body in [a, b] {
                let dj = p.dim(j);
                m.block_mut(&p, j, body)
                    .unwrap()
                    .copy_from_slice(&rng.vec(dj * 6));
                m.block_mut(&p, body, j)
                    .unwrap()
                    .copy_from_slice(&rng.vec(6 * dj));
            }
        }
        (p, m)
    }

    #[test]
    fn saddle_point_tree() {
        let mut rng = Rng(4);
        for _ in 0..20 {
            let (p, m) = multibody(8, 0, &mut rng);
            assert_eq!(p.nfill(), 0);
            check(&p, m, &mut rng);
        }
    }

    #[test]
    fn saddle_point_with_loop_joints() {
        let mut rng = Rng(5);
        for _ in 0..20 {
            let (p, m) = multibody(7, 2, &mut rng);
            check(&p, m, &mut rng);
        }
    }

    /// Iterative refinement: on badly scaled saddle systems (bodies with masses 1e-6..1e6, the
    /// spread of a 1:1000 stack's Newton matrix) the refined solution's residual is at round-off
    /// and never worse than the plain solve's.
    #[test]
    fn refinement_reduces_residual_of_badly_scaled_systems() {
        let mut rng = Rng(7);
        let (mut worst_plain, mut worst_refined) = (0.0f64, 0.0f64);
        for trial in 0..20 {
            let (p, mut m) = multibody(8, 1, &mut rng);
            for b in 0..8 {
                let scale = 10f64.powi((b as i32 + trial) % 13 - 6);
                m.block_mut(&p, b, b)
                    .unwrap()
                    .iter_mut()
                    .for_each(|v| *v *= scale);
            }
            let orig = m.clone();
            m.factor(&p).unwrap();
            let n = p.total_dim();
            let b = rng.vec(n);
            let (mut plain, mut refined) = (b.clone(), b.clone());
            m.solve(&p, &mut plain);
            m.solve_refined(&p, &mut refined, 2, 0.0);
            let mut ax = vec![0.0; n];
            orig.matvec(&p, &plain, &mut ax);
            let r_plain = rel(&ax, &b);
            orig.matvec(&p, &refined, &mut ax);
            let r_refined = rel(&ax, &b);
            worst_plain = worst_plain.max(r_plain);
            assert!(
                r_refined <= r_plain * 1.0001 + 1e-15,
                "{r_refined} > {r_plain}"
            );
            worst_refined = worst_refined.max(r_refined);
        }
        eprintln!("worst relative residual: plain {worst_plain:.1e}, refined {worst_refined:.1e}");
        // the scaling does hurt the plain solve, and refinement recovers most of it
        assert!(worst_plain > 1e-12, "plain residual {worst_plain}");
        assert!(worst_refined < 0.1 * worst_plain);
    }

    #[test]
    fn singular_diagonal_block_is_reported() {
        let edges = [(0, 1), (1, 2)];
        let p = BlockPattern::new(&[2, 3, 2], &edges, &[1, 0, 2]).unwrap();
        let mut m = assemble(&p, &edges, 3.0, &mut Rng(6));
        m.block_mut(&p, 1, 1).unwrap().fill(0.0);
        assert_eq!(m.factor(&p), Err(1));
        // A Schur complement that becomes exactly zero: [[1, 1], [1, 1]].
        let p = BlockPattern::new(&[1, 1], &[(0, 1)], &[0, 1]).unwrap();
        let mut m = BlockMatrix::new(&p);
        m.values.fill(1.0);
        assert_eq!(m.factor(&p), Err(1));
    }

    #[test]
    fn zero_diagonal_needs_pivoting_inside_block() {
        // Diagonal block [[0, 1], [1, 0]] only factors with row pivoting.
        let p = BlockPattern::new(&[2], &[], &[0]).unwrap();
        let mut m = BlockMatrix::new(&p);
        m.add_to_block(p.block(0, 0).unwrap(), 2, 2, &[0.0, 1.0, 1.0, 0.0]);
        let mut rng = Rng(7);
        check(&p, m, &mut rng);
    }

    #[test]
    fn invalid_input_is_rejected() {
        assert!(BlockPattern::new(&[1, 0], &[], &[0, 1]).is_err());
        assert!(BlockPattern::new(&[1, 1], &[(0, 0)], &[0, 1]).is_err());
        assert!(BlockPattern::new(&[1, 1], &[(0, 2)], &[0, 1]).is_err());
        assert!(BlockPattern::new(&[1, 1], &[], &[0, 0]).is_err());
        assert!(BlockPattern::new(&[1, 1], &[], &[0]).is_err());
        assert!(BlockPattern::new(&[1, 1], &[], &[0, 2]).is_err());
        let p = BlockPattern::new(&[1, 2], &[(0, 1), (1, 0), (0, 1)], &[1, 0]).unwrap();
        assert_eq!(p.nvalues(), 1 + 2 + 2 + 4);
        assert!(p.block(2, 0).is_none() && p.block(0, 2).is_none());
    }

    #[test]
    fn zero_keeps_pattern_and_refactors() {
        let mut rng = Rng(8);
        let edges = [(0, 1), (1, 2), (2, 0)];
        let p = BlockPattern::new(&[3, 2, 4], &edges, &[0, 1, 2]).unwrap();
        let mut m = assemble(&p, &edges, 3.0, &mut rng);
        m.factor(&p).unwrap();
        m.zero(&p);
        assert!(m.values.iter().all(|&v| v == 0.0));
        assert_eq!(m.values.len(), p.nvalues());
        let fresh = assemble(&p, &edges, 3.0, &mut rng);
        m.values.copy_from_slice(&fresh.values);
        check(&p, m, &mut rng);
    }

    /// A random tree on `n` nodes (block sizes 1-6) plus up to `extra` edges, in a random
    /// elimination order: the pattern and its edges.
    fn random_graph(n: usize, extra: usize, rng: &mut Rng) -> (BlockPattern, Vec<(usize, usize)>) {
        let dims: Vec<usize> = (0..n).map(|_| 1 + rng.below(6)).collect();
        let mut edges: Vec<(usize, usize)> = (1..n).map(|i| (rng.below(i), i)).collect();
        for _ in 0..extra {
            let (i, j) = (rng.below(n), rng.below(n));
            if i != j {
                edges.push((i, j));
            }
        }
        let mut order: Vec<usize> = (0..n).collect();
        rng.shuffle(&mut order);
        (BlockPattern::new(&dims, &edges, &order).unwrap(), edges)
    }

    /// Assemble into `m` as the Newton iterations do: `zero`, mark the `skipped` nodes, add
    /// the other nodes' blocks of `full` (adding, so stale values would show).
    fn reassemble(p: &BlockPattern, m: &mut BlockMatrix, full: &BlockMatrix, skipped: &[bool]) {
        m.zero(p);
        for (i, &s) in skipped.iter().enumerate() {
            m.set_skipped(p, i, s);
        }
        for i in (0..p.nnodes()).filter(|&i| !skipped[i]) {
            for j in (0..p.nnodes()).filter(|&j| !skipped[j]) {
                if let Some(off) = p.block(i, j) {
                    let len = p.dim(i) * p.dim(j);
                    m.add_to_block(off, p.dim(i), p.dim(j), &full.values[off..off + len]);
                }
            }
        }
    }

    proptest! {
        /// Skipped nodes keep identity rows and columns through `zero`, the factorisation and
        /// changes of the skipped set between assemblies: each solve equals the dense solve
        /// of the matrix with those rows and columns replaced by the identity's.
        #[test]
        fn skipped_nodes_decouple_across_reassembly(
            n in 2usize..14, extra in 0usize..8, seed in any::<u64>()
        ) {
            let mut rng = Rng(seed);
            let (p, edges) = random_graph(n, extra, &mut rng);
            let shift = p.total_dim() as f64 + 1.0;
            let full = assemble(&p, &edges, shift, &mut rng);
            let mut m = BlockMatrix::new(&p);
            for _ in 0..4 {
                let skipped: Vec<bool> = (0..n).map(|_| rng.below(3) == 0).collect();
                reassemble(&p, &mut m, &full, &skipped);
                let mut a = dense(&p, &full);
                for (i, _) in skipped.iter().enumerate().filter(|(_, s)| **s) {
                    let o = p.offset(i);
                    for r in o..o + p.dim(i) {
                        for c in 0..p.total_dim() {
                            a[(r, c)] = f64::from(r == c);
                            a[(c, r)] = f64::from(r == c);
                        }
                    }
                }
                prop_assert_eq!(&dense(&p, &m), &a);
                m.factor(&p).unwrap();
                let b = rng.vec(p.total_dim());
                let mut x = b.clone();
                m.solve_refined(&p, &mut x, 2, 0.0);
                let xr = a.lu().solve(&DVector::from_column_slice(&b)).unwrap();
                prop_assert!(rel(&x, xr.as_slice()) < 1e-10);
                many_rhs_match_single_solves(&p, &mut m, &mut Rng(seed ^ 0x5eed));
            }
        }

        #[test]
        fn random_graphs_and_orders(n in 1usize..14, extra in 0usize..8, seed in any::<u64>()) {
            let mut rng = Rng(seed);
            let (p, edges) = random_graph(n, extra, &mut rng);
            // Strict row diagonal dominance: off-diagonal entries are in [-1, 1).
            let shift = p.total_dim() as f64 + 1.0;
            let m = assemble(&p, &edges, shift, &mut rng);
            check(&p, m, &mut rng);
        }

        /// Stored blocks that are zero this time (edges of inactive contacts, one direction of
        /// a coupling) are skipped by the factorisation and the solves; the result must still
        /// be exact, also when the same matrix is refactored with a different zero set.
        #[test]
        fn numerically_zero_blocks_are_skipped_exactly(
            n in 2usize..14, extra in 0usize..8, seed in any::<u64>()
        ) {
            let mut rng = Rng(seed);
            let (p, edges) = random_graph(n, extra, &mut rng);
            let shift = p.total_dim() as f64 + 1.0;
            let mut m = assemble(&p, &edges, shift, &mut rng);
            for round in 0..2 {
                if round == 1 {
                    // refactor the same matrix (stale flags from the first factorisation)
                    m.factor(&p).unwrap();
                    let fresh = assemble(&p, &edges, shift, &mut rng);
                    m.values.copy_from_slice(&fresh.values);
                }
                for &(i, j) in &edges {
                    let pick = rng.below(4);
                    for (r, c, zero) in [(i, j, pick == 0 || pick == 1), (j, i, pick == 0 || pick == 2)] {
                        if zero {
                            m.block_mut(&p, r, c).unwrap().fill(0.0);
                        }
                    }
                }
                check(&p, m.clone(), &mut rng);
            }
        }
    }
}
