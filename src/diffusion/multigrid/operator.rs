//! The operator the hierarchy is built from: a symmetric 7-point stencil on its unknowns, read
//! row by row ([`Stencils`]), and its Galerkin coarsening by 2×2×2 aggregation ([`coarsen`]).

use crate::par::{for_chunks, map_chunks, map_each, map_range};
use super::{CHUNK, NONE};

/// One unknown of an [`Operator`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// Its cell in the operator's box (x fastest).
    pub cell: u32,
    /// The unknowns of its +x, +y, +z neighbours ([`NONE`]: not an unknown).
    pub up_nbr: [u32; 3],
    /// Diagonal (> 0).
    pub diag: f64,
    /// Matrix entries to its +x, +y, +z neighbours (0 where there is none).
    pub up: [f64; 3],
}

impl Node {
    /// An unknown at `cell` with no couplings yet.
    pub fn at(cell: u32) -> Node {
        Node {
            cell,
            up_nbr: [NONE; 3],
            diag: 0.0,
            up: [0.0; 3],
        }
    }
}

/// A symmetric 7-point operator stored on its unknowns only: the form the callers assemble
/// (48 B per unknown, nothing per cell of the box). The unknowns are in box order (increasing
/// `cell`); each −a coupling is its −a neighbour's +a one.
#[derive(Clone, Debug)]
pub struct Operator {
    /// Cells per axis of the box the unknowns' cells index.
    pub dims: [usize; 3],
    pub nodes: Vec<Node>,
}

/// One unknown's full row of a symmetric 7-point operator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stencil {
    /// Diagonal (> 0).
    pub diag: f64,
    /// Matrix entries to the −x, +x, −y, +y, −z, +z neighbours (0 where there is none).
    pub off: [f64; 6],
    /// Those neighbours' unknowns ([`NONE`]: not an unknown).
    pub nbr: [u32; 6],
}

/// A symmetric 7-point operator read one unknown at a time, its unknowns in box order: an
/// [`Operator`] ([`Operator::rows`]) or rows made on demand from what they are assembled from,
/// so that the finest level's build need not hold them all (the diffusion bands' assembly).
pub trait Stencils: Sync {
    /// Cells per axis of the box the unknowns' cells index.
    fn dims(&self) -> [usize; 3];
    /// Unknowns.
    fn len(&self) -> usize;
    /// Box cell (x fastest) of unknown `u`.
    fn cell(&self, u: usize) -> u32;
    /// Unknown `u`'s row.
    fn stencil(&self, u: usize) -> Stencil;

    /// Unknown `u` in [`Operator`] form (its +a half of the row).
    fn node(&self, u: usize) -> Node {
        let st = self.stencil(u);
        Node {
            cell: self.cell(u),
            up_nbr: [st.nbr[1], st.nbr[3], st.nbr[5]],
            diag: st.diag,
            up: [st.off[1], st.off[3], st.off[5]],
        }
    }

    /// Cell (i, j, k) of unknown `u`.
    fn ijk(&self, u: usize) -> [usize; 3] {
        let [nx, ny, _] = self.dims();
        let c = self.cell(u) as usize;
        [c % nx, (c / nx) % ny, c / (nx * ny)]
    }
}

impl Operator {
    /// The operator's full rows (each unknown's −a neighbours found once, 8 B per unknown).
    pub fn rows(&self) -> OperatorRows<'_> {
        let mut down = vec![[NONE; 2]; self.nodes.len()];
        for (u, nd) in self.nodes.iter().enumerate() {
            for ax in 1..3 {
                if nd.up_nbr[ax] != NONE {
                    down[nd.up_nbr[ax] as usize][ax - 1] = u as u32;
                }
            }
        }
        OperatorRows { a: self, down }
    }
}

/// An [`Operator`] read as [`Stencils`]: each −a entry is the −a neighbour's +a one.
pub struct OperatorRows<'a> {
    pub(super) a: &'a Operator,
    /// Each unknown's −y and −z neighbours (the −x one is the unknown before it, if that is
    /// coupled to it).
    pub(super) down: Vec<[u32; 2]>,
}

impl Stencils for OperatorRows<'_> {
    fn dims(&self) -> [usize; 3] {
        self.a.dims
    }

    fn len(&self) -> usize {
        self.a.nodes.len()
    }

    fn cell(&self, u: usize) -> u32 {
        self.a.nodes[u].cell
    }

    fn stencil(&self, u: usize) -> Stencil {
        let nodes = &self.a.nodes;
        let nd = &nodes[u];
        let mut st = Stencil {
            diag: nd.diag,
            off: [0.0; 6],
            nbr: [NONE; 6],
        };
        for ax in 0..3 {
            let d = match ax {
                0 => match u.checked_sub(1) {
                    Some(d) if nodes[d].up_nbr[0] == u as u32 => d as u32,
                    _ => NONE,
                },
                _ => self.down[u][ax - 1],
            };
            if d != NONE {
                (st.off[2 * ax], st.nbr[2 * ax]) = (nodes[d as usize].up[ax], d);
            }
            (st.off[2 * ax + 1], st.nbr[2 * ax + 1]) = (nd.up[ax], nd.up_nbr[ax]);
        }
        st
    }

    fn node(&self, u: usize) -> Node {
        self.a.nodes[u]
    }
}

/// The first unknown of `a` whose cell is at least `cell` (the unknowns are in box order).
pub(super) fn first_at(a: &impl Stencils, cell: usize) -> usize {
    let (mut lo, mut hi) = (0, a.len());
    while lo < hi {
        let mid = (lo + hi) / 2;
        if (a.cell(mid) as usize) < cell {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

/// Galerkin coarse operator PᵀAP of `a` for 2×2×2 piecewise-constant aggregation, and each
/// unknown's aggregate. A coarse unknown exists where any child is one; its diagonal sums its
/// children's diagonals and the couplings inside it (twice: both directions), a coarse coupling
/// the fine ones across the shared face. Children add in box order, as the box-array form did.
/// Also `a`'s [`Maxima`], from the same reading of its rows (the finest level's rows are made
/// on demand: a pass of their own cost ~1 % of `full`'s instructions).
pub(super) fn coarsen(a: &impl Stencils) -> (Operator, Vec<u32>, Maxima) {
    let [nx, ny, nz] = a.dims();
    let cd = [nx.div_ceil(2), ny.div_ceil(2), nz.div_ceil(2)];
    let key = |ijk: [usize; 3]| (ijk[0] / 2 + cd[0] * (ijk[1] / 2 + cd[1] * (ijk[2] / 2))) as u32;
    // One task per coarse z plane: its aggregates' children are the fine unknowns of two
    // fine planes (contiguous, as the unknowns are in box order). Aggregates are numbered
    // in box order through a rank per coarse cell (NONE: no child), and each adds its
    // children in the fine order a serial pass would, so nothing depends on the thread count.
    let plane = cd[0] * cd[1];
    let fine_planes: Vec<std::ops::Range<usize>> = (0..cd[2])
        .map(|k| first_at(a, 2 * k * nx * ny)..first_at(a, (2 * k + 2) * nx * ny))
        .collect();
    let mut rank = vec![NONE; plane * cd[2]];
    let counts: Vec<u32> = map_chunks(&mut rank, plane, &|k, r| {
            for u in fine_planes[k].clone() {
                r[key(a.ijk(u)) as usize - k * plane] = 0;
            }
            let mut c = 0;
            for v in r.iter_mut().filter(|v| **v == 0) {
                *v = c;
                c += 1;
            }
            c
        });
    let offsets: Vec<u32> = counts
        .iter()
        .scan(0, |s, c| {
            *s += c;
            Some(*s - c)
        })
        .collect();
    for_chunks(&mut rank, plane, &|k, r| {
        r.iter_mut().filter(|v| **v != NONE).for_each(|v| *v += offsets[k]);
    });
    let mut parent = vec![0; a.len()];
    for_chunks(&mut parent, CHUNK, &|ci, ps| {
        for (p, u) in ps.iter_mut().zip(ci * CHUNK..) {
            *p = rank[key(a.ijk(u)) as usize];
        }
    });
    let node_chunks = map_range(rank.len().div_ceil(CHUNK), &|ci| {
        (ci * CHUNK..rank.len().min((ci + 1) * CHUNK))
            .filter(|c| rank[*c] != NONE)
            .map(|c| Node::at(c as u32))
            .collect::<Vec<_>>()
    });
    let mut nodes: Vec<Node> = node_chunks.concat();
    drop(rank);
    let mut planes = Vec::with_capacity(cd[2]);
    let (mut rest, mut base) = (&mut nodes[..], 0);
    for (fine, here) in fine_planes.into_iter().zip(counts) {
        let (mine, more) = rest.split_at_mut(here as usize);
        planes.push((fine, base, mine));
        (rest, base) = (more, base + here as usize);
    }
    let maxima = map_each(planes, &|_, (fine, base, mine)| {
            let mut m = Maxima::default();
            for u in fine {
                let st = a.stencil(u);
                m = m.max(Maxima::of(&st));
                let ijk = a.ijk(u);
                let p = &mut mine[parent[u] as usize - base];
                p.diag += st.diag;
                for (ax, at) in ijk.iter().enumerate() {
                    let (v, up) = (st.nbr[2 * ax + 1], st.off[2 * ax + 1]);
                    if v == NONE {
                        continue;
                    }
                    if at % 2 == 0 {
                        p.diag += 2.0 * up;
                    } else {
                        p.up[ax] += up;
                        p.up_nbr[ax] = parent[v as usize];
                    }
                }
            }
            m
        })
        .into_iter()
        .fold(Maxima::default(), Maxima::max);
    (Operator { dims: cd, nodes }, parent, maxima)
}

/// The largest values of an operator's rows, from which a level's codes take their scales
/// ([`Scaled16::exponent_for`](crate::half::Scaled16::exponent_for)): coupling magnitude, diagonal, row sum.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Maxima {
    pub(super) cpl: f64,
    pub(super) diag: f64,
    pub(super) sum: f64,
}

impl Maxima {
    /// Those of one row.
    pub(super) fn of(st: &Stencil) -> Maxima {
        let cpl = st
            .off
            .iter()
            .zip(st.nbr)
            .filter(|(_, v)| *v != NONE)
            .fold(0f64, |m, (c, _)| m.max(-c));
        Maxima {
            cpl,
            diag: st.diag,
            sum: row_sum(st),
        }
    }

    /// Each the larger of the two (the same in any order: thread-count independent).
    pub(super) fn max(self, o: Maxima) -> Maxima {
        Maxima {
            cpl: self.cpl.max(o.cpl),
            diag: self.diag.max(o.diag),
            sum: self.sum.max(o.sum),
        }
    }

    /// Those of all of `a`'s rows (a pass over them: for a level not read by [`coarsen`]).
    pub(super) fn all(a: &impl Stencils) -> Maxima {
        map_range(a.len().div_ceil(CHUNK), &|ci| {
            (ci * CHUNK..a.len().min((ci + 1) * CHUNK)).fold(Maxima::default(), |m, u| m.max(Maxima::of(&a.stencil(u))))
        })
        .into_iter()
        .fold(Maxima::default(), Maxima::max)
    }
}

/// The row's sum: its diagonal plus its couplings to its neighbours, in f64 as assembled.
pub(super) fn row_sum(st: &Stencil) -> f64 {
    st.off
        .iter()
        .zip(st.nbr)
        .filter(|(_, v)| *v != NONE)
        .fold(st.diag, |s, (o, _)| s + o)
}
