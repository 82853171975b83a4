//! The exact order: voxel centres sorted by world distance from the eye, farthest first, with a
//! parallel radix sort (rdst).

use rdst::RadixSort;

use super::distance::{DistanceTable, FarthestFirst};
use super::traverse::{Plan, Sink, walk};
use super::view::ViewCase;
use crate::grid::SparseGrid;

/// Keys kept between frames.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    keys: Vec<FarthestFirst>,
    table: DistanceTable,
}

struct KeySink<'a> {
    keys: &'a mut Vec<FarthestFirst>,
    table: &'a DistanceTable,
    k: [u32; 3],
    axis: usize,
}

impl Sink for KeySink<'_> {
    #[inline]
    fn row(&mut self, k: [u32; 3], axis: usize) {
        self.k = k;
        self.axis = axis;
    }

    #[inline]
    fn voxel(&mut self, id: u32, k: u32) {
        self.k[self.axis] = k;
        let q = self.table.distance_squared(self.k);
        self.keys.push(FarthestFirst::new(q, id));
    }
}

impl Scratch {
    pub(crate) fn order(
        &mut self,
        grid: &SparseGrid,
        view: &ViewCase,
        id_order: &Plan<'_>,
        cull: Option<&ViewCase>,
        out: &mut Vec<u32>,
    ) {
        self.table.prepare(view);
        self.keys.clear();
        self.keys.reserve(grid.len());
        let mut sink = KeySink {
            keys: &mut self.keys,
            table: &self.table,
            k: [0; 3],
            axis: 0,
        };
        walk(grid, id_order, cull, &mut sink);
        self.keys.radix_sort_unstable();
        out.extend(self.keys.iter().map(|k| k.index));
    }
}
