//! The exact order: voxel centres sorted by world distance from the eye, farthest first, with a
//! parallel radix sort (rdst).

use rdst::{RadixKey, RadixSort};

use super::distance::DistanceTable;
use super::traverse::{Plan, Sink, walk};
use super::view::ViewCase;
use crate::grid::SparseGrid;

/// Sort key: inverted squared distance (so that ascending order is farthest first), then id.
#[derive(Debug, Clone, Copy)]
struct Key {
    inverted_distance: u64,
    id: u32,
}

impl RadixKey for Key {
    const LEVELS: usize = 12;

    #[inline]
    fn get_level(&self, level: usize) -> u8 {
        // rdst reads levels from the least significant byte up.
        if level < 4 {
            (self.id >> (level * 8)) as u8
        } else {
            (self.inverted_distance >> ((level - 4) * 8)) as u8
        }
    }
}

/// Keys kept between frames.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    keys: Vec<Key>,
    table: DistanceTable,
}

struct KeySink<'a> {
    keys: &'a mut Vec<Key>,
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
        // Non-negative floats order like their bit patterns.
        let q = self.table.distance_squared(self.k).max(0.0);
        self.keys.push(Key {
            inverted_distance: !q.to_bits(),
            id,
        });
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
        out.extend(self.keys.iter().map(|k| k.id));
    }
}
