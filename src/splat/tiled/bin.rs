//! Binning: each projected splat appended to the list of every tile its rectangle touches,
//! keeping the draw order within each tile.

use super::TILE;
use super::project::Projected;

/// The tile lists of one chunk of a batch: `entries[starts[t]..starts[t + 1]]` are the chunk's
/// splats touching tile `t`, in draw order.
#[derive(Debug, Default)]
pub(super) struct ChunkBins {
    pub(super) starts: Vec<u32>,
    pub(super) entries: Vec<u32>,
    pub(super) next: Vec<u32>,
    /// Splats of the chunk that landed on the image.
    pub(super) projected: usize,
}

/// Counts, then lists, the tiles each splat of a chunk touches (a counting sort by tile, which
/// keeps the draw order within every tile). `splats` are those of the chunk that landed on the
/// image, as [`Group::project`] packs them; `first` is the index of the first.
pub(super) fn bin_chunk(
    splats: &[Projected],
    first: u32,
    tx: usize,
    ty: usize,
    bins: &mut ChunkBins,
) {
    let tiles = tx * ty;
    bins.starts.clear();
    bins.starts.resize(tiles + 1, 0);
    let range = |p: &Projected| {
        let t = TILE as i32;
        (p.x0 / t, p.x1 / t, p.y0 / t, p.y1 / t)
    };
    bins.projected = splats.len();
    for p in splats {
        let (a, b, c, d) = range(p);
        for y in c..=d {
            for x in a..=b {
                bins.starts[y as usize * tx + x as usize + 1] += 1;
            }
        }
    }
    for t in 0..tiles {
        bins.starts[t + 1] += bins.starts[t];
    }
    bins.entries.clear();
    bins.entries.resize(bins.starts[tiles] as usize, 0);
    bins.next.clear();
    bins.next.extend_from_slice(&bins.starts[..tiles]);
    for (i, p) in splats.iter().enumerate() {
        let (a, b, c, d) = range(p);
        for y in c..=d {
            for x in a..=b {
                let slot = &mut bins.next[y as usize * tx + x as usize];
                bins.entries[*slot as usize] = first + i as u32;
                *slot += 1;
            }
        }
    }
}
