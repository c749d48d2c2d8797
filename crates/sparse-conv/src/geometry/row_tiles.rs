//! A gather's rows cut into tiles of rows that use the same kernel offsets, for the GPU kernel.
//!
//! A GPU tile stages its rows' partners at one offset and multiplies them by that offset's weight
//! in shared memory; a row without a partner there is a zero row, arithmetic spent on nothing.
//! LiDAR maps are sparse (about 3 partners of 27 per voxel), so tiles of rows in voxel order would
//! use nearly every offset, each for a few rows. Sorting rows by the set of offsets they use (as
//! spconv's implicit GEMM does) makes a tile's rows alike, and each tile lists only the offsets
//! some row of it uses.

use crate::geometry::kernel_map::NeighborTable;

/// Rows in tile order and, per tile, the offsets its rows use.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct RowTiles {
    /// Row indices in tile order: tile `t` is `order[t·rows .. (t+1)·rows]` (the last one shorter).
    pub order: Vec<u32>,
    /// Tile `t` uses the offsets `offsets[start[t] .. start[t+1]]`, ascending.
    pub start: Vec<u32>,
    pub offsets: Vec<u32>,
}

impl RowTiles {
    /// Tiles of `tile_rows` rows of `table`, whose entries below `n_src` are partners.
    pub fn new(table: &NeighborTable, n_src: usize, tile_rows: usize) -> Self {
        // Serial on purpose: it runs on the host between GPU launches of a forward pass, where a
        // thread pool's wake-ups cost more than this work (measured on a 16-core GPU host).
        let present = |p: u32| (p as usize) < n_src;
        let volume = table.volume();
        // Each row's offset set, folded onto 64 bits for kernels over 4×4×4 (the sort key only).
        let masks: Vec<u64> = (0..table.rows())
            .map(|r| table.row(r).iter().enumerate().fold(0u64, |m, (k, &p)| m | (present(p) as u64) << (k % 64)))
            .collect();
        // Sorted by offset set, then by row, so the order is one and the same on every run.
        let order = radix_order(&masks);
        let mut start = vec![0u32];
        let mut offsets = Vec::new();
        let mut used = vec![false; volume];
        for tile in order.chunks(tile_rows.max(1)) {
            if volume <= 64 {
                let mask = tile.iter().fold(0u64, |m, &r| m | masks[r as usize]);
                offsets.extend((0..volume as u32).filter(|&k| mask >> k & 1 == 1));
            } else {
                used.fill(false);
                for &r in tile {
                    for (k, &p) in table.row(r as usize).iter().enumerate() {
                        used[k] |= present(p);
                    }
                }
                offsets.extend(used.iter().enumerate().filter(|&(_, &u)| u).map(|(k, _)| k as u32));
            }
            start.push(offsets.len() as u32);
        }
        Self { order, start, offsets }
    }

    /// Number of tiles.
    pub fn tiles(&self) -> usize {
        self.start.len() - 1
    }
}

/// Row indices ordered by `keys`, equal keys by index: a stable LSD radix sort on 11-bit digits
/// up to the highest bit any key sets (27 bits for a 3×3×3 kernel: three passes).
fn radix_order(keys: &[u64]) -> Vec<u32> {
    const DIGIT: u32 = 11;
    let bits = 64 - keys.iter().fold(0u64, |m, &k| m | k).leading_zeros();
    let mut order: Vec<u32> = (0..keys.len() as u32).collect();
    let mut next = vec![0u32; keys.len()];
    let mut shift = 0;
    while shift < bits {
        let digit = |r: u32| ((keys[r as usize] >> shift) & ((1 << DIGIT) - 1)) as usize;
        let mut count = vec![0u32; (1 << DIGIT) + 1];
        for &r in &order {
            count[digit(r) + 1] += 1;
        }
        for d in 1..count.len() {
            count[d] += count[d - 1];
        }
        for &r in &order {
            let slot = &mut count[digit(r)];
            next[*slot as usize] = r;
            *slot += 1;
        }
        std::mem::swap(&mut order, &mut next);
        shift += DIGIT;
    }
    order
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::coords::{Coord, CoordIndex};
    use crate::geometry::kernel_map::KernelMap;

    #[test]
    fn radix_order_is_the_order_by_key_then_index() {
        let keys: Vec<u64> = (0..5000u64).map(|i| ((i * 2654435761) % 97) | ((i % 7) << 40)).collect();
        let mut expected: Vec<u32> = (0..keys.len() as u32).collect();
        expected.sort_by_key(|&r| (keys[r as usize], r));
        assert_eq!(radix_order(&keys), expected);
        assert_eq!(radix_order(&[]), Vec::<u32>::new());
    }

    #[test]
    fn tiles_cover_every_row_once_and_list_exactly_the_offsets_their_rows_use() {
        let coords: Vec<Coord> = (0..300).map(|i| [0, (i * 7) % 23, (i * 13) % 17, (i * 5) % 11]).collect::<std::collections::BTreeSet<_>>().into_iter().collect();
        let index = CoordIndex::build(&coords).unwrap();
        let map = KernelMap::submanifold(&coords, &index, 3, 1);
        let table = map.out_table();
        let tiles = RowTiles::new(table, map.n_in(), 16);
        let mut seen = tiles.order.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..coords.len() as u32).collect::<Vec<_>>());
        assert_eq!(tiles.tiles(), coords.len().div_ceil(16));
        for t in 0..tiles.tiles() {
            let rows = &tiles.order[t * 16..((t + 1) * 16).min(coords.len())];
            let expected: Vec<u32> = (0..table.volume() as u32)
                .filter(|&k| rows.iter().any(|&r| (table.row(r as usize)[k as usize] as usize) < map.n_in()))
                .collect();
            assert_eq!(&tiles.offsets[tiles.start[t] as usize..tiles.start[t + 1] as usize], &expected[..], "tile {t}");
        }
        // Rows sorted by offset set: fewer offset uses than tiles in voxel order.
        let unsorted: usize = (0..tiles.tiles())
            .map(|t| (0..table.volume()).filter(|&k| (t * 16..((t + 1) * 16).min(coords.len())).any(|r| (table.row(r)[k] as usize) < map.n_in())).count())
            .sum();
        assert!(tiles.offsets.len() <= unsorted, "{} > {unsorted}", tiles.offsets.len());
    }
}
