//! An oracle for the visibility orderings that shares no code with them.
//!
//! `splatscene::order::reference` sorts with the library's own helpers (`pbtf_subvolumes`,
//! `rows::compare`, `pyramid::compare`, `ViewCase::permutation`), so a bug in one of those is
//! restated by the reference and passes its tests. Here each ordering's definition, as stated
//! in the documentation of `splatscene::order` (and of its `pyramid` and `rows` modules, and the
//! tie rules stated on `AxisView` and `ViewCase::permutation`), is derived again in this file
//! from the raw inputs only: the grid's dims and voxel-to-world columns, the eye in index
//! coordinates, the view direction, and the list of significant voxel ids (drawn here by a
//! small LCG). The expected order is a brute-force comparison sort (`sort_by` over the
//! definition's keys) written in this file. From the library the test calls only the
//! constructors (`VolumeGeometry::new`, `ViewCase::new`, `SparseGrid::from_mask`), the ordering
//! under test (`Orderer::order`), and reads `ViewCase::eye`, the eye in index coordinates that
//! every definition starts from (checked against the eye the test placed: exactly on the
//! dyadic grids, where the tie cases live, and to 1e-9 elsewhere). No permutation, split,
//! subvolume, row axis, distance or comparison of the library is used.
//!
//! Tie rules, from the documentation:
//! - along one axis a voxel is farther the larger `|k - e|` is; equal distances put the lower
//!   coordinate first (`order` module docs);
//! - the plane through the eye puts a centre exactly on it on the upper side (`AxisView::Split`:
//!   `kv = ceil(e)`), so an axis has voxels on both sides when `0 < e <= n - 1`;
//! - IP-PBTF's permutation (`ViewCase::permutation`): axes with voxels on only one side of the
//!   eye first, then the others; within each group the axis most nearly along the view
//!   direction (`|unit(column) . unit(forward)|`) first. Equal alignments are not ordered by
//!   the docs, so every permutation they allow is accepted;
//! - BTF walks an axis downwards when the view direction in index space is positive along it;
//!   a direction orthogonal to the axis takes the end farther from the eye (either end when
//!   the eye is half-way).
//!
//! `DESIGN.md` splits an axis at `round(e)` and asks for an axis that is not split to be
//! slowest; the code's documentation splits at `ceil(e)` (the plane through the eye itself,
//! see `AxisView::Split` for why) and puts one-sided axes first, which differs from "not split"
//! for an eye at most half a voxel beyond the outermost centres. The oracle follows the code's
//! documentation, the more precise statement.
//!
//! Where the definition fixes a total order the library's list must equal the oracle's; where
//! it leaves a choice (equal alignments, equally far PBTF subvolumes, distances equal up to
//! rounding, bucket edges) the library's list must be one of the orders it allows. Every
//! ordering in `Ordering::ALL` is covered. The bucketed order is checked more weakly than the
//! others: where its buckets start (the nearest point of the grid's box) and its f32 distances
//! are not part of its documented definition, so the oracle checks what the definition implies
//! for any placement of the bucket edges (see [`check_bucketed`]).

use std::cmp::Ordering as Cmp;
use std::sync::OnceLock;

use glam::{DAffine3, DMat3, DVec3};
use splatscene::grid::SparseGrid;
use splatscene::order::{OrderOptions, Orderer, Ordering, ViewCase, VolumeGeometry};

type V3 = [f64; 3];

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn det(c: &[V3; 3]) -> f64 {
    dot(c[0], cross(c[1], c[2]))
}

/// The world offset of an index offset `v` for a grid with columns `c`.
fn apply(c: &[V3; 3], v: V3) -> V3 {
    std::array::from_fn(|i| c[0][i] * v[0] + c[1][i] * v[1] + c[2][i] * v[2])
}

/// The index offset whose world offset is `w` (Cramer's rule).
fn solve(c: &[V3; 3], w: V3) -> V3 {
    let d = det(c);
    std::array::from_fn(|a| {
        let mut m = *c;
        m[a] = w;
        det(&m) / d
    })
}

const PERMUTATIONS: [[usize; 3]; 6] = [
    [0, 1, 2],
    [0, 2, 1],
    [1, 0, 2],
    [1, 2, 0],
    [2, 0, 1],
    [2, 1, 0],
];

/// A grid placed in the world: voxel `k` sits at `origin + sum_a k_a * cols[a]`.
#[derive(Debug, Clone, Copy)]
struct Placement {
    name: &'static str,
    dims: [u32; 3],
    cols: [V3; 3],
    origin: V3,
    /// Every column, the origin and every eye and target are dyadic with few bits, so the
    /// library's f64 arithmetic is exact and the tie cases are really ties.
    dyadic: bool,
}

impl Placement {
    fn world(&self, index: V3) -> V3 {
        let w = apply(&self.cols, index);
        std::array::from_fn(|i| self.origin[i] + w[i])
    }

    fn geometry(&self) -> VolumeGeometry {
        let [x, y, z] = self.cols.map(DVec3::from);
        VolumeGeometry::new(
            self.dims,
            DAffine3::from_mat3_translation(DMat3::from_cols(x, y, z), self.origin.into()),
        )
        .expect("a valid placement")
    }

    fn voxels(&self) -> u32 {
        self.dims.iter().product()
    }
}

fn diagonal(s: V3) -> [V3; 3] {
    [[s[0], 0.0, 0.0], [0.0, s[1], 0.0], [0.0, 0.0, s[2]]]
}

fn placements() -> Vec<Placement> {
    let dyadic = |name, dims, spacing, origin| Placement {
        name,
        dims,
        cols: diagonal(spacing),
        origin,
        dyadic: true,
    };
    vec![
        dyadic("5x4x3 unit", [5, 4, 3], [1.0; 3], [0.0; 3]),
        dyadic(
            "5x4x3 spacing 0.5,2,1",
            [5, 4, 3],
            [0.5, 2.0, 1.0],
            [8.0, -4.0, 2.0],
        ),
        dyadic("4x4x4 unit", [4, 4, 4], [1.0; 3], [0.0; 3]),
        dyadic(
            "1x6x5 spacing 1,0.5,0.25",
            [1, 6, 5],
            [1.0, 0.5, 0.25],
            [0.0; 3],
        ),
        dyadic(
            "4x1x6 spacing 2,1,0.5",
            [4, 1, 6],
            [2.0, 1.0, 0.5],
            [1.0; 3],
        ),
        dyadic("1x1x6 unit", [1, 1, 6], [1.0; 3], [0.0; 3]),
        Placement {
            name: "7x6x5 spacing 0.7,0.7,2.5",
            dims: [7, 6, 5],
            cols: diagonal([0.7, 0.7, 2.5]),
            origin: [3.0, -2.0, 1.0],
            dyadic: false,
        },
        Placement {
            name: "6x4x5 x flipped, spacing 0.8,1.3,1.9",
            dims: [6, 4, 5],
            cols: diagonal([-0.8, 1.3, 1.9]),
            origin: [2.0, 0.0, -3.0],
            dyadic: false,
        },
        Placement {
            name: "6x5x4 sheared",
            dims: [6, 5, 4],
            cols: [[1.0, 0.2, 0.0], [0.0, 0.8, 0.3], [0.1, 0.0, 2.0]],
            origin: [-4.0, 5.0, 0.5],
            dyadic: false,
        },
        Placement {
            name: "5x6x3 sheared the other way",
            dims: [5, 6, 3],
            cols: [[0.9, 0.0, -0.3], [0.35, 1.1, 0.0], [0.0, 0.4, 1.7]],
            origin: [1.0, 2.0, 3.0],
            dyadic: false,
        },
    ]
}

/// Eye coordinates along one axis of `n` voxels: far and just outside each end, on the
/// boundaries `-0.5` and `n - 0.5`, on voxel centres and half-way between two (dyadic grids
/// only), and generic places inside.
fn eye_coords(n: u32, axis: usize, dyadic: bool) -> Vec<f64> {
    let nf = f64::from(n);
    let mut coords = if dyadic {
        let mid = f64::from(n / 2);
        vec![
            -2.75,
            -0.5,
            -0.25,
            0.0,
            mid - 0.5,
            mid,
            mid + 0.375,
            nf - 1.0,
            nf - 0.5,
            nf + 1.75,
        ]
    } else {
        let t = 0.013 * axis as f64;
        vec![
            -3.13 - t,
            -0.61 - t,
            -0.29 - t,
            0.31 * nf + 0.07 + t,
            0.64 * nf + 0.19 + t,
            nf - 0.77 + t,
            nf - 0.37 + t,
            nf + 2.29 + t,
        ]
    };
    coords.sort_by(f64::total_cmp);
    coords.dedup();
    coords
}

/// Deterministic pseudo-random significance: about `percent` of the voxels.
fn mask(voxels: u32, percent: u64, seed: u64) -> Vec<bool> {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..voxels)
        .map(|_| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 33) % 100 < percent
        })
        .collect()
}

#[derive(Debug, Clone)]
struct Case {
    placement: Placement,
    /// Eye and target in index coordinates.
    eye: V3,
    target: V3,
    percent: u64,
    seed: u64,
    cull: bool,
}

impl Case {
    fn label(&self) -> String {
        format!(
            "[{}] eye {:?} target {:?} density {}% seed {} cull {}",
            self.placement.name, self.eye, self.target, self.percent, self.seed, self.cull
        )
    }
}

/// Every case: each placement with every combination of its per-axis eye coordinates, a few
/// targets, masks from dense to very sparse (each density with each kind of target), culling
/// on every third case.
fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    let (mut counter, mut combos) = (0u64, 0usize);
    for placement in placements() {
        let d = placement.dims;
        let coords: [Vec<f64>; 3] = std::array::from_fn(|a| eye_coords(d[a], a, placement.dyadic));
        let centre: V3 = std::array::from_fn(|a| (f64::from(d[a]) - 1.0) / 2.0);
        for &ex in &coords[0] {
            for &ey in &coords[1] {
                for &ez in &coords[2] {
                    let eye = [ex, ey, ez];
                    // The grid's centre, and one of a few directions in turn: along a
                    // diagonal of two axes (equal alignments on a unit grid, and an axis the
                    // view is orthogonal to), straight down z, and skew ones.
                    let offsets: &[V3] = if placement.dyadic {
                        &[[1.0, -1.0, 0.0], [0.0, 0.0, -1.0], [-0.375, 0.625, 0.875]]
                    } else {
                        &[[-0.31, 0.53, 0.87], [0.93, 0.11, -0.41]]
                    };
                    let o = offsets[combos % offsets.len()];
                    combos += 1;
                    let targets = [centre, std::array::from_fn(|a| eye[a] + o[a])];
                    for target in targets {
                        counter += 1;
                        out.push(Case {
                            placement,
                            eye,
                            target,
                            percent: [100, 65, 30, 8][((counter + counter / 2) % 4) as usize],
                            seed: counter,
                            cull: counter % 3 == 0,
                        });
                    }
                }
            }
        }
    }
    // A larger CT-like grid, so that rows hold several runs.
    let ct = Placement {
        name: "12x9x7 spacing 0.7,0.7,2.5",
        dims: [12, 9, 7],
        cols: diagonal([0.7, 0.7, 2.5]),
        origin: [0.0; 3],
        dyadic: false,
    };
    for (i, eye) in [
        [4.37, 3.61, 2.29],
        [-5.13, 4.21, 3.07],
        [13.6, -2.3, 9.1],
        [5.71, 11.3, -4.2],
        [2.17, 2.93, 20.3],
    ]
    .into_iter()
    .enumerate()
    {
        for percent in [100, 40] {
            out.push(Case {
                placement: ct,
                eye,
                target: [5.5, 4.0, 3.0],
                percent,
                seed: 1000 + i as u64,
                cull: i % 2 == 1,
            });
        }
    }
    out
}

/// Everything a definition needs, derived here from the case and the eye in index
/// coordinates.
struct Oracle {
    dims: [u32; 3],
    cols: [V3; 3],
    eye: V3,
    /// World view direction, target minus eye (not normalised).
    forward: V3,
    /// The same in index coordinates.
    dir_index: V3,
    /// The significant voxels in front of the eye (all of them without culling).
    kept: Vec<u32>,
    /// Voxels so close to the eye plane that rounding decides whether they are culled.
    borderline: Vec<u32>,
}

impl Oracle {
    fn new(case: &Case, view_eye: V3, significant: &[bool]) -> Self {
        let p = &case.placement;
        for a in 0..3 {
            let ok = if p.dyadic {
                view_eye[a] == case.eye[a]
            } else {
                (view_eye[a] - case.eye[a]).abs() <= 1e-9 * (1.0 + case.eye[a].abs())
            };
            assert!(
                ok,
                "{}: the view's eye {view_eye:?} is not the eye placed",
                case.label()
            );
        }
        let world_eye = p.world(case.eye);
        let world_target = p.world(case.target);
        let forward: V3 = std::array::from_fn(|i| world_target[i] - world_eye[i]);
        let mut oracle = Self {
            dims: p.dims,
            cols: p.cols,
            eye: view_eye,
            forward,
            dir_index: solve(&p.cols, forward),
            kept: Vec::new(),
            borderline: Vec::new(),
        };
        let scale = dot(forward, forward).sqrt();
        for id in 0..p.voxels() {
            if !significant[id as usize] {
                continue;
            }
            if !case.cull {
                oracle.kept.push(id);
                continue;
            }
            let w = apply(&oracle.cols, oracle.offset(oracle.coords(id)));
            let plane = dot(forward, w);
            let tolerance = 1e-9 * scale * (1.0 + dot(w, w).sqrt());
            if plane.abs() <= tolerance {
                oracle.borderline.push(id);
            } else if plane > 0.0 {
                oracle.kept.push(id);
            }
        }
        oracle
    }

    fn coords(&self, id: u32) -> [u32; 3] {
        let [nx, ny, _] = self.dims;
        [id % nx, (id / nx) % ny, id / (nx * ny)]
    }

    fn offset(&self, k: [u32; 3]) -> V3 {
        std::array::from_fn(|a| f64::from(k[a]) - self.eye[a])
    }

    /// World squared distance from the eye to the centre of voxel `k`.
    fn distance_squared(&self, k: [u32; 3]) -> f64 {
        let w = apply(&self.cols, self.offset(k));
        dot(w, w)
    }

    /// Squared world length of one step along `axis` (`g_aa`).
    fn g(&self, axis: usize) -> f64 {
        let c = self.cols[axis];
        c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
    }

    /// Far to near along `axis`: `Less` when coordinate `x` is drawn before `y`.
    fn toward_eye(&self, axis: usize, x: u32, y: u32) -> Cmp {
        let e = self.eye[axis];
        let (dx, dy) = ((f64::from(x) - e).abs(), (f64::from(y) - e).abs());
        dy.total_cmp(&dx).then(x.cmp(&y))
    }

    /// Whether voxels lie on both sides of the plane through the eye along `axis` (a centre on
    /// the plane counts as the upper side).
    fn two_sided(&self, axis: usize) -> bool {
        let e = self.eye[axis];
        e > 0.0 && e <= f64::from(self.dims[axis]) - 1.0
    }

    /// `|unit(column a) . unit(forward)|`.
    fn alignment(&self, axis: usize) -> f64 {
        let c = self.cols[axis];
        dot(c, self.forward).abs() / (dot(c, c).sqrt() * dot(self.forward, self.forward).sqrt())
    }

    /// Permutations, slowest first, ordered by `group` ascending and then by alignment
    /// descending; equal alignments (up to rounding) either way.
    fn permutations_by(&self, group: impl Fn(usize) -> u8) -> Vec<[usize; 3]> {
        let al: V3 = std::array::from_fn(|a| self.alignment(a));
        PERMUTATIONS
            .into_iter()
            .filter(|p| {
                (0..3).all(|i| {
                    (i + 1..3).all(|j| {
                        let (x, y) = (p[i], p[j]);
                        group(x) < group(y) || (group(x) == group(y) && al[x] + 1e-12 >= al[y])
                    })
                })
            })
            .collect()
    }

    /// IP-PBTF's permutations: one-sided axes first, then by alignment.
    fn ip_pbtf_permutations(&self) -> Vec<[usize; 3]> {
        self.permutations_by(|a| u8::from(self.two_sided(a)))
    }

    /// BTF directions allowed per axis (`true`: walked downwards, from the high end).
    fn btf_directions(&self) -> Vec<[bool; 3]> {
        let norm = dot(self.dir_index, self.dir_index).sqrt();
        let allowed: [Vec<bool>; 3] = std::array::from_fn(|a| {
            let d = self.dir_index[a];
            let mid = (f64::from(self.dims[a]) - 1.0) / 2.0;
            if d == 0.0 {
                match self.eye[a].total_cmp(&mid) {
                    Cmp::Less => vec![true],
                    Cmp::Greater => vec![false],
                    Cmp::Equal => vec![true, false],
                }
            } else if d.abs() <= 1e-12 * norm {
                // Zero up to rounding: the sign is the library's arithmetic's to pick.
                vec![true, false]
            } else {
                vec![d > 0.0]
            }
        });
        let mut out = Vec::new();
        for &x in &allowed[0] {
            for &y in &allowed[1] {
                for &z in &allowed[2] {
                    out.push([x, y, z]);
                }
            }
        }
        out
    }

    fn btf_cmp(&self, perm: [usize; 3], down: [bool; 3], a: u32, b: u32) -> Cmp {
        let (ka, kb) = (self.coords(a), self.coords(b));
        for axis in perm {
            if ka[axis] != kb[axis] {
                return if (ka[axis] > kb[axis]) == down[axis] {
                    Cmp::Less
                } else {
                    Cmp::Greater
                };
            }
        }
        Cmp::Equal
    }

    fn ip_pbtf_cmp(&self, perm: [usize; 3], a: u32, b: u32) -> Cmp {
        let (ka, kb) = (self.coords(a), self.coords(b));
        for axis in perm {
            let c = self.toward_eye(axis, ka[axis], kb[axis]);
            if c != Cmp::Equal {
                return c;
            }
        }
        Cmp::Equal
    }

    /// PBTF subvolume of `k`: per axis, whether `k` is on the upper side of the plane through
    /// the eye (a centre on the plane is on the upper side; an eye below the grid puts every
    /// voxel on the upper side, one above it every voxel on the lower side).
    fn subvolume(&self, k: [u32; 3]) -> usize {
        (0..3)
            .map(|a| usize::from(f64::from(k[a]) >= self.eye[a]) << a)
            .sum()
    }

    /// Squared world distance of each subvolume's farthest voxel centre (over the whole grid,
    /// significant or not), `None` for an empty subvolume.
    fn subvolume_reach(&self) -> [Option<f64>; 8] {
        let mut reach = [None; 8];
        for id in 0..self.dims.iter().product::<u32>() {
            let k = self.coords(id);
            let d = self.distance_squared(k);
            let r: &mut Option<f64> = &mut reach[self.subvolume(k)];
            *r = Some(r.map_or(d, |x: f64| x.max(d)));
        }
        reach
    }

    /// Pyramid order, from the `pyramid` module's definition, with `perm` as the tie order of
    /// pyramids.
    fn pyramid_cmp(&self, perm: [usize; 3], a: u32, b: u32) -> Cmp {
        const SLAB_AXES: [(usize, usize); 3] = [(2, 1), (2, 0), (1, 0)];
        let m =
            |axis: usize, k: [u32; 3]| (f64::from(k[axis]) - self.eye[axis]).abs() * self.g(axis);
        let pyramid = |k: [u32; 3]| {
            // The largest `m`, the earliest in `perm` among equals.
            let mut best = (0, f64::NEG_INFINITY);
            for (rank, &axis) in perm.iter().enumerate() {
                if m(axis, k) > best.1 {
                    best = (rank, m(axis, k));
                }
            }
            best
        };
        let row = |axis: usize, k: [u32; 3]| {
            let (o, i) = SLAB_AXES[axis];
            if m(o, k) >= m(i, k) {
                (m(o, k), 0u8, k[o], i)
            } else {
                (m(i, k), 1u8, k[i], o)
            }
        };
        let (ka, kb) = (self.coords(a), self.coords(b));
        let ((rank_a, key_a), (rank_b, key_b)) = (pyramid(ka), pyramid(kb));
        let axis = perm[rank_a];
        key_b
            .total_cmp(&key_a)
            .then(rank_a.cmp(&rank_b))
            .then(ka[axis].cmp(&kb[axis]))
            .then_with(|| {
                let (ra, fixed_a, ca, along) = row(axis, ka);
                let (rb, fixed_b, cb, _) = row(axis, kb);
                rb.total_cmp(&ra)
                    .then(fixed_a.cmp(&fixed_b))
                    .then(ca.cmp(&cb))
                    .then_with(|| self.toward_eye(along, ka[along], kb[along]))
            })
    }

    /// Row axes the rows order may pick: the smallest `g_aa * mean_k |k - e_a|`, ties to the
    /// lower axis. With `exact` arithmetic (dyadic grids) that is one axis; otherwise scores
    /// equal up to rounding may go either way.
    fn row_axes(&self, exact: bool) -> Vec<usize> {
        let score: V3 = std::array::from_fn(|a| {
            let n = self.dims[a];
            let sum: f64 = (0..n).map(|k| (f64::from(k) - self.eye[a]).abs()).sum();
            self.g(a) * (sum / f64::from(n))
        });
        let best = score.iter().copied().fold(f64::INFINITY, f64::min);
        if exact {
            vec![(0..3).find(|&a| score[a] == best).unwrap()]
        } else {
            (0..3)
                .filter(|&a| score[a] <= best + 1e-9 * (1.0 + best))
                .collect()
        }
    }

    /// World squared distance from the eye to the line through voxel `k` along `axis`.
    fn row_distance_squared(&self, axis: usize, k: [u32; 3]) -> f64 {
        // From the point of the line level with the eye along `axis`, so that every voxel of
        // a row gets the same value.
        let mut d = self.offset(k);
        d[axis] = 0.0;
        let w = apply(&self.cols, d);
        let c = self.cols[axis];
        let along = dot(w, c);
        let q = dot(w, w) - along * along / dot(c, c);
        q.max(0.0)
    }

    fn rows_cmp(&self, axis: usize, a: u32, b: u32) -> Cmp {
        let (u, v) = match axis {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        };
        let (ka, kb) = (self.coords(a), self.coords(b));
        let index = |k: [u32; 3]| k[u] + self.dims[u] * k[v];
        let (qa, qb) = (
            self.row_distance_squared(axis, ka),
            self.row_distance_squared(axis, kb),
        );
        qb.total_cmp(&qa)
            .then(index(ka).cmp(&index(kb)))
            .then_with(|| self.toward_eye(axis, ka[axis], kb[axis]))
    }
}

/// The library's list holds every voxel the oracle keeps, none it drops, and any of the
/// borderline ones; returns that set sorted by id.
fn check_set(oracle: &Oracle, got: &[u32]) -> Result<Vec<u32>, String> {
    let mut set = got.to_vec();
    set.sort_unstable();
    if set.windows(2).any(|w| w[0] == w[1]) {
        return Err("a voxel is drawn twice".into());
    }
    let allowed = |id: &u32| {
        oracle.kept.binary_search(id).is_ok() || oracle.borderline.binary_search(id).is_ok()
    };
    if let Some(id) = set.iter().find(|id| !allowed(id)) {
        return Err(format!(
            "voxel {:?} is drawn but is not significant or is behind the eye",
            oracle.coords(*id)
        ));
    }
    if let Some(id) = oracle.kept.iter().find(|id| set.binary_search(id).is_err()) {
        return Err(format!(
            "voxel {:?} is significant and in front of the eye but not drawn",
            oracle.coords(*id)
        ));
    }
    Ok(set)
}

/// The library's list equals the brute-force sort under one of the comparators the
/// definition allows (`params` picks one).
fn check_total<P: std::fmt::Debug>(
    oracle: &Oracle,
    got: &[u32],
    params: &[P],
    cmp: impl Fn(&P, u32, u32) -> Cmp,
) -> Result<(), String> {
    let set = check_set(oracle, got)?;
    let mut first_failure = None;
    for p in params {
        let mut expected = set.clone();
        expected.sort_by(|&a, &b| cmp(p, a, b));
        for w in expected.windows(2) {
            assert_eq!(
                cmp(p, w[0], w[1]),
                Cmp::Less,
                "the oracle's comparator is not a total order under {p:?}"
            );
        }
        if expected == got {
            return Ok(());
        }
        if first_failure.is_none() {
            let i = (0..got.len()).find(|&i| got[i] != expected[i]).unwrap();
            first_failure = Some(format!(
                "under {p:?} (of {} allowed), position {i} of {}: the library draws voxel {:?} where the definition draws {:?}",
                params.len(),
                got.len(),
                oracle.coords(got[i]),
                oracle.coords(expected[i]),
            ));
        }
    }
    Err(first_failure.unwrap_or_else(|| "no allowed parameters".into()))
}

/// The library's list is non-decreasing under one of the allowed comparators (whose `Equal`
/// means the definition leaves the pair's order open).
fn check_sorted<P: std::fmt::Debug>(
    oracle: &Oracle,
    got: &[u32],
    params: &[P],
    cmp: impl Fn(&P, u32, u32) -> Cmp,
) -> Result<(), String> {
    check_set(oracle, got)?;
    let mut first_failure = None;
    for p in params {
        match got
            .windows(2)
            .position(|w| cmp(p, w[0], w[1]) == Cmp::Greater)
        {
            None => return Ok(()),
            Some(i) if first_failure.is_none() => {
                first_failure = Some(format!(
                    "under {p:?} (of {} allowed), position {i}: voxel {:?} is drawn before voxel {:?}, which the definition puts first",
                    params.len(),
                    oracle.coords(got[i]),
                    oracle.coords(got[i + 1]),
                ));
            }
            Some(_) => {}
        }
    }
    Err(first_failure.unwrap_or_else(|| "no allowed parameters".into()))
}

/// PBTF: every subvolume drawn whole, subvolumes farthest first (equally far ones in any
/// order: the docs' "lower subvolume index" never says how subvolumes are numbered), each in
/// BTF nesting (z slowest) with every axis walked toward the eye.
fn check_pbtf(oracle: &Oracle, got: &[u32]) -> Result<(), String> {
    check_set(oracle, got)?;
    let reach = oracle.subvolume_reach();
    let mut runs: Vec<(usize, Vec<u32>)> = Vec::new();
    for &id in got {
        let s = oracle.subvolume(oracle.coords(id));
        match runs.last_mut() {
            Some((last, ids)) if *last == s => ids.push(id),
            _ => {
                if runs.iter().any(|(r, _)| *r == s) {
                    return Err(format!(
                        "subvolume {s:03b} (zyx, 1 = upper side) is drawn in two pieces, again at voxel {:?}",
                        oracle.coords(id)
                    ));
                }
                runs.push((s, vec![id]));
            }
        }
    }
    for pair in runs.windows(2) {
        let (far, near) = (pair[0].0, pair[1].0);
        let (d_far, d_near) = (reach[far].unwrap(), reach[near].unwrap());
        if d_near > d_far * (1.0 + 1e-12) {
            return Err(format!(
                "subvolume {near:03b} (farthest centre at {:.6}) is drawn after subvolume {far:03b} (farthest centre at {:.6}): nearer first",
                d_near.sqrt(),
                d_far.sqrt()
            ));
        }
    }
    for (s, ids) in &runs {
        let mut expected = ids.clone();
        expected.sort_by(|&a, &b| oracle.ip_pbtf_cmp([2, 1, 0], a, b));
        if &expected != ids {
            let i = (0..ids.len()).find(|&i| ids[i] != expected[i]).unwrap();
            return Err(format!(
                "inside subvolume {s:03b}, the library draws voxel {:?} where the definition draws {:?}",
                oracle.coords(ids[i]),
                oracle.coords(expected[i])
            ));
        }
    }
    Ok(())
}

/// Bucketed: world distance quantised into buckets of `width`, farthest bucket first,
/// IP-PBTF order inside a bucket. Where the buckets start and the f32 arithmetic that places a
/// voxel near an edge are the library's own, so the oracle checks what holds for every
/// placement of the edges: a voxel drawn after another is less than one bucket farther, and
/// wherever two consecutive voxels are out of IP-PBTF order a bucket edge lies between them,
/// so everything drawn before is at least as far as everything drawn after.
fn check_bucketed(oracle: &Oracle, got: &[u32], width: f64) -> Result<(), String> {
    check_set(oracle, got)?;
    let r: Vec<f64> = got
        .iter()
        .map(|&id| oracle.distance_squared(oracle.coords(id)).sqrt())
        .collect();
    let slack = |x: f64| 1e-5 * (1.0 + x);
    let mut prefix_min = vec![f64::INFINITY; r.len()];
    let mut suffix_max = vec![f64::NEG_INFINITY; r.len()];
    for i in 0..r.len() {
        prefix_min[i] = r[i].min(if i > 0 {
            prefix_min[i - 1]
        } else {
            f64::INFINITY
        });
    }
    for i in (0..r.len()).rev() {
        suffix_max[i] = r[i].max(suffix_max.get(i + 1).copied().unwrap_or(f64::NEG_INFINITY));
    }
    for i in 1..r.len() {
        let bound = prefix_min[i - 1] + width;
        if r[i] > bound + slack(bound) {
            return Err(format!(
                "voxel {:?} at distance {:.6} is drawn after a voxel at {:.6}, more than a bucket ({width}) nearer",
                oracle.coords(got[i]),
                r[i],
                prefix_min[i - 1]
            ));
        }
    }
    let permutations = oracle.ip_pbtf_permutations();
    let mut first_failure = None;
    for &perm in &permutations {
        let bad = (1..r.len()).find(|&i| {
            oracle.ip_pbtf_cmp(perm, got[i - 1], got[i]) == Cmp::Greater
                && suffix_max[i] > prefix_min[i - 1] + slack(prefix_min[i - 1])
        });
        match bad {
            None => return Ok(()),
            Some(i) if first_failure.is_none() => {
                first_failure = Some(format!(
                    "under {perm:?} (of {} allowed), position {i}: voxels {:?} then {:?} are out of IP-PBTF order with no bucket edge between them (a voxel at {:.6} drawn before, one at {:.6} after)",
                    permutations.len(),
                    oracle.coords(got[i - 1]),
                    oracle.coords(got[i]),
                    prefix_min[i - 1],
                    suffix_max[i]
                ));
            }
            Some(_) => {}
        }
    }
    Err(first_failure.unwrap_or_else(|| "no allowed permutation".into()))
}

/// A case with its view, grid and oracle, built once for all the tests.
struct Prepared {
    case: Case,
    view: ViewCase,
    grid: SparseGrid,
    oracle: Oracle,
}

fn prepared() -> &'static [Prepared] {
    static CASES: OnceLock<Vec<Prepared>> = OnceLock::new();
    CASES.get_or_init(|| {
        cases()
            .into_iter()
            .filter_map(|case| {
                let p = &case.placement;
                let to_world = |x: V3| DVec3::from(p.world(x));
                // Eye on the target: no view direction, nothing to order.
                let view =
                    ViewCase::new(&p.geometry(), to_world(case.eye), to_world(case.target)).ok()?;
                let significant = mask(p.voxels(), case.percent, case.seed);
                let grid = SparseGrid::from_mask(p.dims, |id| significant[id as usize]).unwrap();
                let oracle = Oracle::new(&case, view.eye.to_array(), &significant);
                Some(Prepared {
                    case,
                    view,
                    grid,
                    oracle,
                })
            })
            .collect()
    })
}

/// Runs `ordering` on every case and checks it with `check`; fails with the first mismatches.
fn run(
    ordering: Ordering,
    bucket_width: Option<f64>,
    check: impl Fn(&Case, &Oracle, &[u32]) -> Result<(), String>,
) -> usize {
    let mut orderer = Orderer::new();
    let mut out = Vec::new();
    let mut failures = Vec::new();
    let cases = prepared();
    for Prepared {
        case,
        view,
        grid,
        oracle,
    } in cases
    {
        let options = OrderOptions {
            cull_behind_eye: case.cull,
            bucket_width,
        };
        orderer
            .order(grid, view, ordering, &options, &mut out)
            .unwrap();
        if let Err(message) = check(case, oracle, &out) {
            failures.push(format!("{}: {message}", case.label()));
        }
    }
    assert!(
        failures.is_empty(),
        "{ordering} differs from its definition in {} of {} cases; first:\n{}",
        failures.len(),
        cases.len(),
        failures[..failures.len().min(5)].join("\n")
    );
    cases.len()
}

#[test]
fn btf_is_its_definition() {
    let checked = run(Ordering::Btf, None, |_, o, got| {
        let params: Vec<_> = o
            .btf_directions()
            .into_iter()
            .map(|d| ([2, 1, 0], d))
            .collect();
        check_total(o, got, &params, |&(perm, down), a, b| {
            o.btf_cmp(perm, down, a, b)
        })
    });
    assert!(checked > 5000, "only {checked} cases");
}

#[test]
fn wbtf_is_its_definition() {
    run(Ordering::Wbtf, None, |_, o, got| {
        let mut params = Vec::new();
        for perm in o.permutations_by(|_| 0) {
            for down in o.btf_directions() {
                params.push((perm, down));
            }
        }
        check_total(o, got, &params, |&(perm, down), a, b| {
            o.btf_cmp(perm, down, a, b)
        })
    });
}

#[test]
fn pbtf_is_its_definition() {
    run(Ordering::Pbtf, None, |_, o, got| check_pbtf(o, got));
}

fn check_ip_pbtf(ordering: Ordering) {
    run(ordering, None, |_, o, got| {
        check_total(o, got, &o.ip_pbtf_permutations(), |&perm, a, b| {
            o.ip_pbtf_cmp(perm, a, b)
        })
    });
}

/// Grids large enough that the library walks IP-PBTF in slabs of slices on several threads:
/// eyes outside the grid, within two axes' extents, within all three (culling behind the eye),
/// each ordering's list the definition's.
#[test]
fn ip_pbtf_walked_in_slabs_is_its_definition() {
    let placement = Placement {
        name: "90x70x60 sheared",
        dims: [90, 70, 60],
        cols: [[0.7, 0.1, 0.0], [0.0, 0.7, 0.2], [0.05, 0.0, 1.6]],
        origin: [-20.0, 4.0, 9.0],
        dyadic: false,
    };
    let cases = [
        ([-40.3, 150.2, 95.7], [45.0, 35.0, 30.0], false),
        ([44.6, 31.3, 140.9], [40.1, 35.2, 30.0], false),
        ([52.35, 18.6, 21.2], [10.0, 60.0, 40.0], true),
        ([30.2, 40.7, 35.4], [31.0, 41.0, 90.0], true),
    ];
    for (i, (eye, target, cull)) in cases.into_iter().enumerate() {
        let case = Case {
            placement,
            eye,
            target,
            percent: [60, 45][i % 2],
            seed: 7 + i as u64,
            cull,
        };
        let to_world = |x: V3| DVec3::from(placement.world(x));
        let view = ViewCase::new(&placement.geometry(), to_world(eye), to_world(target)).unwrap();
        let significant = mask(placement.voxels(), case.percent, case.seed);
        let grid = SparseGrid::from_mask(placement.dims, |id| significant[id as usize]).unwrap();
        assert!(grid.len() > 1 << 17, "{}", grid.len());
        let oracle = Oracle::new(&case, view.eye.to_array(), &significant);
        let options = OrderOptions {
            cull_behind_eye: cull,
            bucket_width: None,
        };
        for ordering in [Ordering::IpPbtfImplicit, Ordering::IpPbtfExplicit] {
            let mut got = Vec::new();
            Orderer::new()
                .order(&grid, &view, ordering, &options, &mut got)
                .unwrap();
            check_total(
                &oracle,
                &got,
                &oracle.ip_pbtf_permutations(),
                |&perm, a, b| oracle.ip_pbtf_cmp(perm, a, b),
            )
            .unwrap_or_else(|e| panic!("{ordering} {}: {e}", case.label()));
        }
    }
}

#[test]
fn ip_pbtf_explicit_is_its_definition() {
    check_ip_pbtf(Ordering::IpPbtfExplicit);
}

#[test]
fn ip_pbtf_implicit_is_its_definition() {
    check_ip_pbtf(Ordering::IpPbtfImplicit);
}

#[test]
fn exact_is_its_definition() {
    run(Ordering::Exact, None, |case, o, got| {
        let distance = |id: u32| o.distance_squared(o.coords(id));
        if case.placement.dyadic {
            // Exact arithmetic: equal distances are equal, and go by increasing id.
            check_total(o, got, &[()], |_, a, b| {
                distance(b).total_cmp(&distance(a)).then(a.cmp(&b))
            })
        } else {
            check_sorted(o, got, &[()], |_, a, b| {
                let (da, db) = (distance(a), distance(b));
                if (da - db).abs() <= 1e-12 * da.max(db) {
                    Cmp::Equal
                } else {
                    db.total_cmp(&da)
                }
            })
        }
    });
}

#[test]
fn bucketed_is_its_definition() {
    for width in [None, Some(0.3), Some(3.1)] {
        run(Ordering::Bucketed, width, |_, o, got| {
            let smallest = (0..3).map(|a| o.g(a).sqrt()).fold(f64::INFINITY, f64::min);
            check_bucketed(o, got, width.unwrap_or(0.5 * smallest))
        });
    }
}

#[test]
fn pyramid_is_its_definition() {
    run(Ordering::Pyramid, None, |_, o, got| {
        check_total(o, got, &o.ip_pbtf_permutations(), |&perm, a, b| {
            o.pyramid_cmp(perm, a, b)
        })
    });
}

#[test]
fn rows_is_its_definition() {
    run(Ordering::Rows, None, |case, o, got| {
        let axes = o.row_axes(case.placement.dyadic);
        check_total(o, got, &axes, |&axis, a, b| o.rows_cmp(axis, a, b))
    });
}

/// The cases reach every view case, the tie places, both kinds of IP-PBTF permutation, equal
/// alignments, and view directions orthogonal to an axis.
#[test]
fn the_cases_cover_the_view_cases() {
    let mut kinds = std::collections::BTreeMap::new();
    let (mut ties, mut one_sided_slowest, mut all_two_sided) = (0, 0, 0);
    let (mut equal_alignments, mut orthogonal) = (0, 0);
    for Prepared {
        case, view, oracle, ..
    } in prepared()
    {
        *kinds.entry(view.kind.name()).or_insert(0) += 1;
        if case.eye.iter().any(|e| (2.0 * e).fract() == 0.0) {
            ties += 1;
        }
        let perms = oracle.ip_pbtf_permutations();
        if (0..3).any(|a| oracle.two_sided(a)) && !oracle.two_sided(perms[0][0]) {
            one_sided_slowest += 1;
        }
        if (0..3).all(|a| oracle.two_sided(a)) {
            all_two_sided += 1;
        }
        equal_alignments += usize::from(perms.len() > 1);
        orthogonal += usize::from(oracle.dir_index.contains(&0.0));
    }
    for kind in ["corner-on", "edge-on", "face-on", "volume-on"] {
        assert!(kinds.get(kind).copied().unwrap_or(0) > 100, "{kinds:?}");
    }
    assert!(ties > 1000 && one_sided_slowest > 1000 && all_two_sided > 100);
    assert!(equal_alignments > 100 && orthogonal > 1000);
}
