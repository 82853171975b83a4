//! A grid's bitmap held by pages: only the pages with a significant voxel are stored.
//!
//! A refinement is classified only within the bricks a view shows, and its significant voxels
//! are a few percent of a grid of up to 2^31 voxels; a flat bitmap with a rank a word spanned
//! the whole grid (384 MiB at 2^31 voxels, a third of a close-up's memory). Pages of
//! [`PAGE_WORDS`] words with no bit set are not stored; a page table says where each stored
//! one lies. (A general compressed bitmap crate such as `roaring` keeps containers of 2^16
//! ids and ranks by scanning them; the orderings and texels ask for a voxel's rank once per
//! run and per neighbour, so this keeps the flat bitmap's constant-time rank instead.)

/// Words of 64 voxels a page.
pub(super) const PAGE_WORDS: usize = 16;
/// Voxels a page.
const PAGE_BITS: u64 = 64 * PAGE_WORDS as u64;
/// The page table's mark for a page with no bit set (not stored).
const EMPTY: u32 = u32::MAX;

/// Bits over ids `0..64 * len` in pages, with a rank index.
#[derive(Debug, Clone, Default)]
pub(super) struct PagedBits {
    /// Words the bitmap spans (a flat bitmap's length).
    len: usize,
    /// Per page, its place among the stored pages, or [`EMPTY`].
    table: Vec<u32>,
    /// The stored pages' words, [`PAGE_WORDS`] each, in page order.
    words: Vec<u64>,
    /// Per stored page, the set bits of the pages before it.
    page_rank: Vec<u32>,
    /// Per stored word, the set bits of the words before it in its page.
    word_rank: Vec<u16>,
    /// Set bits in all.
    count: u64,
}

impl PagedBits {
    /// The bits of `words` (bit `i % 64` of word `i / 64` for id `i`), compacted in place: its
    /// pages with no bit set are dropped and the others moved down over them.
    pub(super) fn from_flat(mut words: Vec<u64>) -> Self {
        let len = words.len();
        let pages = len.div_ceil(PAGE_WORDS);
        let mut table = vec![EMPTY; pages];
        let mut stored = 0usize;
        for (p, slot) in table.iter_mut().enumerate() {
            let from = p * PAGE_WORDS;
            let to = (from + PAGE_WORDS).min(len);
            if words[from..to].iter().all(|&w| w == 0) {
                continue;
            }
            // Stored pages move down (never up: `stored <= p`), the last one padded.
            words.copy_within(from..to, stored * PAGE_WORDS);
            let (tail, end) = (
                stored * PAGE_WORDS + to - from,
                ((stored + 1) * PAGE_WORDS).min(len),
            );
            if tail < end {
                words[tail..end].fill(0);
            }
            *slot = stored as u32;
            stored += 1;
        }
        words.resize(stored * PAGE_WORDS, 0);
        words.shrink_to_fit();
        Self::indexed(len, table, words)
    }

    /// The bits of `parts` laid end to end over `len` words: each part's ids must lie past
    /// the ones before it ([`BitsPart::first`] above the last part's [`BitsPart::last`]), and
    /// only a part's first page may be the page the part before it ended in. The parts are
    /// freed as they are taken.
    pub(super) fn from_parts(len: usize, parts: Vec<BitsPart>) -> Self {
        let stored: usize = parts.iter().map(|p| p.pages.len()).sum();
        let mut table = vec![EMPTY; len.div_ceil(PAGE_WORDS)];
        let mut pages: Vec<u32> = Vec::with_capacity(stored);
        let mut words: Vec<u64> = Vec::with_capacity(stored * PAGE_WORDS);
        for part in parts {
            for (page, from) in part.pages.iter().zip(part.words.chunks_exact(PAGE_WORDS)) {
                if pages.last() == Some(page) {
                    let at = words.len() - PAGE_WORDS;
                    for (w, f) in words[at..].iter_mut().zip(from) {
                        *w |= f;
                    }
                } else if let Some(slot) = table.get_mut(*page as usize) {
                    *slot = pages.len() as u32;
                    pages.push(*page);
                    words.extend_from_slice(from);
                }
            }
        }
        Self::indexed(len, table, words)
    }

    /// The page of voxel `id`.
    pub(super) fn page_of(id: u32) -> u32 {
        (u64::from(id) / PAGE_BITS) as u32
    }

    fn indexed(len: usize, table: Vec<u32>, words: Vec<u64>) -> Self {
        let mut page_rank = Vec::with_capacity(words.len() / PAGE_WORDS);
        let mut word_rank = Vec::with_capacity(words.len());
        let mut total = 0u64;
        for page in words.chunks(PAGE_WORDS) {
            page_rank.push(total as u32);
            let mut within = 0u16;
            for w in page {
                word_rank.push(within);
                within += w.count_ones() as u16;
            }
            total += u64::from(within);
        }
        Self {
            len,
            table,
            words,
            page_rank,
            word_rank,
            count: total,
        }
    }

    /// Set bits in all.
    pub(super) fn count(&self) -> u64 {
        self.count
    }

    /// Words the bitmap spans.
    #[cfg(test)]
    pub(super) fn len(&self) -> usize {
        self.len
    }

    /// The stored place of flat word `w`, if its page is stored.
    #[inline]
    fn place(&self, w: usize) -> Option<usize> {
        let slot = *self.table.get(w / PAGE_WORDS)?;
        (slot != EMPTY).then(|| slot as usize * PAGE_WORDS + w % PAGE_WORDS)
    }

    /// Flat word `w` (0 past the end and in pages not stored).
    #[inline]
    pub(super) fn word(&self, w: usize) -> u64 {
        self.place(w).map_or(0, |i| self.words[i])
    }

    /// Whether bit `id` is set.
    #[inline]
    pub(super) fn contains(&self, id: u32) -> bool {
        self.word((id / 64) as usize) >> (id % 64) & 1 == 1
    }

    /// Whether words `from..to` lie in pages not stored (so that all are 0); false where a
    /// stored page overlaps them, whatever its words there.
    #[inline]
    pub(super) fn clear_between(&self, from: usize, to: usize) -> bool {
        from >= to
            || (from / PAGE_WORDS..=(to - 1) / PAGE_WORDS)
                .all(|p| self.table.get(p).is_none_or(|&s| s == EMPTY))
    }

    /// Set bits before bit `id`, if it is set.
    #[inline]
    pub(super) fn rank(&self, id: u32) -> Option<u32> {
        let i = self.place((id / 64) as usize)?;
        let word = self.words[i];
        let bit = id % 64;
        if word >> bit & 1 == 0 {
            return None;
        }
        let below = word & ((1u64 << bit) - 1);
        Some(self.page_rank[i / PAGE_WORDS] + u32::from(self.word_rank[i]) + below.count_ones())
    }

    /// The bitmap and its rank index as one list of 32-bit words, as the GPU passes read it
    /// (`texel_of` in `shaders/splat.wgsl`): three offsets (of the page ranks, the word ranks
    /// and the words), then the page table, the page ranks, the word ranks (one a word) and
    /// the stored words (low half first).
    pub(super) fn to_gpu_words(&self) -> Vec<u32> {
        let ranks = 3 + self.table.len();
        let word_ranks = ranks + self.page_rank.len();
        let words = word_ranks + self.word_rank.len();
        let mut out = Vec::with_capacity(words + 2 * self.words.len());
        out.extend([ranks, word_ranks, words].map(|o| o as u32));
        out.extend_from_slice(&self.table);
        out.extend_from_slice(&self.page_rank);
        out.extend(self.word_rank.iter().map(|&r| u32::from(r)));
        out.extend(
            self.words
                .iter()
                .flat_map(|&w| [w as u32, (w >> 32) as u32]),
        );
        out
    }

    /// The stored pages in order: the flat index of each one's first word, and its words (a
    /// last page past the bitmap's end padded with zeros).
    pub(super) fn pages(&self) -> impl Iterator<Item = (usize, &[u64])> + '_ {
        self.table
            .iter()
            .enumerate()
            .filter(|(_, s)| **s != EMPTY)
            .map(|(p, &s)| {
                let at = s as usize * PAGE_WORDS;
                (p * PAGE_WORDS, &self.words[at..at + PAGE_WORDS])
            })
    }

    /// Page `p`'s words, if it is stored.
    fn page(&self, p: usize) -> Option<&[u64]> {
        let s = *self.table.get(p)?;
        (s != EMPTY).then(|| &self.words[s as usize * PAGE_WORDS..(s as usize + 1) * PAGE_WORDS])
    }

    /// The word pairs of this bitmap and `other` (of the same length) over the pages either
    /// stores, in order; pages neither stores are left out.
    pub(super) fn word_pairs<'a>(
        &'a self,
        other: &'a PagedBits,
    ) -> impl Iterator<Item = (u64, u64)> + 'a {
        const NONE: [u64; PAGE_WORDS] = [0; PAGE_WORDS];
        (0..self.table.len().max(other.table.len())).flat_map(move |p| {
            let (a, b) = (self.page(p), other.page(p));
            let pair =
                (a.is_some() || b.is_some()).then(|| (a.unwrap_or(&NONE), b.unwrap_or(&NONE)));
            pair.into_iter()
                .flat_map(|(a, b)| a.iter().copied().zip(b.iter().copied()))
        })
    }

    /// The bits of this bitmap or `other` (of the same length), or `None` where the two share
    /// a set bit.
    pub(super) fn union_of_disjoint(&self, other: &PagedBits) -> Option<Self> {
        let pages = self.table.len();
        let mut table = vec![EMPTY; pages];
        let mut words = Vec::new();
        for (p, slot) in table.iter_mut().enumerate() {
            let page = match (self.page(p), other.page(p)) {
                (None, None) => continue,
                (Some(a), None) | (None, Some(a)) => a.to_vec(),
                (Some(a), Some(b)) => {
                    if a.iter().zip(b).any(|(a, b)| a & b != 0) {
                        return None;
                    }
                    a.iter().zip(b).map(|(a, b)| a | b).collect()
                }
            };
            *slot = (words.len() / PAGE_WORDS) as u32;
            words.extend_from_slice(&page);
        }
        Some(Self::indexed(self.len, table, words))
    }

    /// Bytes held (the page table, the stored pages and their ranks).
    pub(super) fn bytes(&self) -> usize {
        self.table.len() * 4
            + self.words.len() * 8
            + self.page_rank.len() * 4
            + self.word_rank.len() * 2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat bitmap with bits set at `ids`.
    fn flat(len: usize, ids: &[u32]) -> Vec<u64> {
        let mut words = vec![0u64; len];
        for &id in ids {
            words[id as usize / 64] |= 1 << (id % 64);
        }
        words
    }

    /// The GPU's list gives every id the rank `rank` gives (and none where no bit is set),
    /// read as `texel_of` in shaders/splat.wgsl reads it, 32-bit halves and all: pages not
    /// stored, bits in either half of a word, the last page padded.
    #[test]
    fn the_gpu_words_rank_as_the_bitmap_does() {
        let len = 5 * PAGE_WORDS + 3;
        let mut ids = vec![0, 31, 32, 33, 63, 64, 1000];
        // Page 1 empty; pages 2 and 3 dense in stretches; the last, short page set at its end.
        ids.extend((2 * PAGE_BITS as u32..2 * PAGE_BITS as u32 + 700).filter(|i| i % 3 != 0));
        ids.extend(3 * PAGE_BITS as u32 + 5..3 * PAGE_BITS as u32 + 90);
        ids.push(64 * len as u32 - 1);
        let bits = PagedBits::from_flat(flat(len, &ids));
        let list = bits.to_gpu_words();
        let word = |i: u32| list[i as usize];
        let gpu_rank = |id: u32| -> Option<u32> {
            let w = id / 64;
            let page = 3 + w / PAGE_WORDS as u32;
            if page >= word(0) || word(page) == u32::MAX {
                return None;
            }
            let slot = word(page);
            let i = slot * PAGE_WORDS as u32 + w % PAGE_WORDS as u32;
            let (lo, hi) = (word(word(2) + 2 * i), word(word(2) + 2 * i + 1));
            let bit = id % 64;
            let (below, found) = if bit < 32 {
                ((lo & ((1 << bit) - 1)).count_ones(), lo >> bit & 1 == 1)
            } else {
                let b = bit - 32;
                (
                    lo.count_ones() + (hi & ((1 << b) - 1)).count_ones(),
                    hi >> b & 1 == 1,
                )
            };
            found.then(|| word(word(0) + slot) + word(word(1) + i) + below)
        };
        for id in 0..64 * len as u32 + 200 {
            assert_eq!(gpu_rank(id), bits.rank(id), "id {id}");
        }
        assert_eq!(gpu_rank(64 * len as u32 - 1), Some(ids.len() as u32 - 1));
    }

    #[test]
    fn pages_with_no_bit_are_not_stored_and_ranks_count_across_pages() {
        // Clusters of bits with whole pages empty between them, a last page cut short, a
        // page full: every id's membership and rank as a plain list's.
        let len = 10 * PAGE_WORDS + 5;
        let mut ids: Vec<u32> = Vec::new();
        ids.extend([0, 1, 63, 64, 200]);
        ids.extend((3 * PAGE_BITS as u32)..(4 * PAGE_BITS as u32));
        ids.extend([7 * PAGE_BITS as u32 + 1000, 10 * PAGE_BITS as u32 + 319]);
        let bits = PagedBits::from_flat(flat(len, &ids));
        assert_eq!(bits.count(), ids.len() as u64);
        assert_eq!(bits.len(), len);
        let stored: Vec<usize> = bits.pages().map(|(w, _)| w / PAGE_WORDS).collect();
        assert_eq!(stored, [0, 3, 7, 10]);
        assert_eq!(bits.words.len(), 4 * PAGE_WORDS);
        for id in 0..(len * 64) as u32 {
            let rank = ids.iter().position(|&i| i == id).map(|r| r as u32);
            assert_eq!(bits.rank(id), rank, "{id}");
            assert_eq!(bits.contains(id), rank.is_some(), "{id}");
        }
        for w in 0..len + 3 {
            assert_eq!(bits.word(w), flat(len, &ids).get(w).copied().unwrap_or(0));
        }
        // Made from parts, one of them cut inside a page, the same bits.
        let parts = [&ids[..2], &ids[2..]].map(|ids| {
            let mut part = BitsPart::default();
            for &id in ids {
                part.push(id);
            }
            part
        });
        assert_eq!(PagedBits::page_of(ids[1]), PagedBits::page_of(ids[2]));
        let made = PagedBits::from_parts(len, parts.into());
        assert_eq!(made.words, bits.words);
        assert_eq!(made.table, bits.table);
        assert_eq!(made.word_rank, bits.word_rank);
    }

    #[test]
    fn a_union_keeps_every_bit_and_refuses_a_shared_one() {
        let len = 6 * PAGE_WORDS;
        let a_ids = [5u32, 70, 2 * PAGE_BITS as u32 + 9];
        let b_ids = [6u32, 5 * PAGE_BITS as u32 + 1];
        let a = PagedBits::from_flat(flat(len, &a_ids));
        let b = PagedBits::from_flat(flat(len, &b_ids));
        let u = a.union_of_disjoint(&b).unwrap();
        let mut all: Vec<u32> = a_ids.iter().chain(&b_ids).copied().collect();
        all.sort_unstable();
        for (r, &id) in all.iter().enumerate() {
            assert_eq!(u.rank(id), Some(r as u32));
        }
        assert_eq!(u.count(), 5);
        assert_eq!(u.pages().count(), 3);
        assert!(a.union_of_disjoint(&a).is_none());
        // Words in pages not stored, and stretches that reach into a stored one.
        assert!(b.clear_between(PAGE_WORDS, 5 * PAGE_WORDS));
        assert!(!b.clear_between(PAGE_WORDS, 5 * PAGE_WORDS + 1));
        assert!(!b.clear_between(PAGE_WORDS - 1, 2 * PAGE_WORDS));
        assert!(b.clear_between(3, 3) && b.clear_between(7 * PAGE_WORDS, 9 * PAGE_WORDS));
        // The pairs cover the pages either stores, word for word.
        let pairs: Vec<(u64, u64)> = a.word_pairs(&b).collect();
        assert_eq!(pairs.len(), 3 * PAGE_WORDS);
        assert_eq!(pairs[0], (1 << 5, 1 << 6));
        assert_eq!(pairs[1], (1 << 6, 0));
        let ones: u32 = pairs.iter().map(|(a, b)| (a | b).count_ones()).sum();
        assert_eq!(ones, 5);
    }
}

/// Voxel ids given one at a time in increasing order, held as the bitmap pages they fall in: a
/// stretch of a grid made piece by piece, as a classification's slabs make theirs, joined by
/// [`crate::grid::SparseGrid::from_bit_parts`]. A page (1024 voxels) takes 132 bytes however
/// many of its voxels are set, where a list takes 4 bytes an id: the 0.75 mm abdomen CT with
/// a window of soft tissue sets 41M of 86.5M voxels, 165 MB of ids against 11 MB of pages.
/// (The final grid stores the same pages; see the module's note on `roaring`.)
#[derive(Debug, Clone, Default)]
pub struct BitsPart {
    /// The pages set, increasing.
    pages: Vec<u32>,
    /// Their words, [`PAGE_WORDS`] a page.
    words: Vec<u64>,
    /// The first id and the last.
    ends: Option<(u32, u32)>,
    /// Ids set.
    count: usize,
    /// The place of the first id that was not past the one before it (and was not set).
    unsorted: Option<usize>,
}

impl BitsPart {
    /// Sets `id`, which must lie past the ids set before (one that does not is not set, and
    /// [`BitsPart::unsorted`] tells where it came).
    #[inline]
    pub fn push(&mut self, id: u32) {
        match &mut self.ends {
            Some((_, last)) if id <= *last => {
                self.unsorted.get_or_insert(self.count);
                return;
            }
            Some((_, last)) => *last = id,
            None => self.ends = Some((id, id)),
        }
        let page = PagedBits::page_of(id);
        if self.pages.last() != Some(&page) {
            self.pages.push(page);
            self.words.resize(self.words.len() + PAGE_WORDS, 0);
        }
        let at = self.words.len() - PAGE_WORDS + (u64::from(id) % PAGE_BITS / 64) as usize;
        self.words[at] |= 1 << (id % 64);
        self.count += 1;
    }

    /// Ids set.
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether no id is set.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The first id set.
    pub fn first(&self) -> Option<u32> {
        self.ends.map(|(first, _)| first)
    }

    /// The last id set.
    pub fn last(&self) -> Option<u32> {
        self.ends.map(|(_, last)| last)
    }

    /// Where the first id not past the one before it was given (counting the ids set before
    /// it), if one was.
    pub fn unsorted(&self) -> Option<usize> {
        self.unsorted
    }

    /// Frees the room its lists hold past their length.
    pub fn shrink_to_fit(&mut self) {
        self.pages.shrink_to_fit();
        self.words.shrink_to_fit();
    }
}
