//! The gather's tile plan ([`RowTiles`]) made on a GPU from a table already there, so a forward
//! or backward pass whose maps live on the device never reads them back to plan its tiles.
//!
//! - each row's offset set as a bit mask (kernels of up to 32 offsets: 3×3×3 and 2×2×2);
//! - the rows sorted by mask, equal masks by row, as the host sorts them: a stable LSD radix sort
//!   on 9-bit digits, each pass a count per (digit, block of rows), a scan by one cube, and a
//!   scatter that walks each block's rows in order;
//! - per tile of `tile_rows` sorted rows, the union of their masks, then its offsets in ascending
//!   order from the tile's place in a scan of the tiles' offset counts.
//!
//! The plan equals [`RowTiles::new`]'s entry for entry (tested on lavapipe); only the offsets
//! buffer is sized for the most a plan can hold, as the host does not read how many there are.
//!
//! [`RowTiles`]: crate::geometry::row_tiles::RowTiles
//! [`RowTiles::new`]: crate::geometry::row_tiles::RowTiles::new

use burn_cubecl::cubecl;
use burn_cubecl::cubecl::client::Client;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::cubecl::server::Handle;

use crate::geometry::device_maps::{launch_1d, scan_counts};

/// Most offsets a kernel may have for its plan to be made on the device (one `u32` mask a row).
pub(crate) const MAX_VOLUME: usize = 32;

/// Bits of the sort key taken per pass.
const DIGIT_BITS: usize = 9;

/// Buckets of one pass.
const BUCKETS: usize = 1 << DIGIT_BITS;

/// Rows a unit of the sort's count and scatter walks.
const SORT_BLOCK_ROWS: usize = 512;

/// A tile plan on a device: what the tiled gather reads.
pub(crate) struct DeviceRowTiles {
    /// Row indices in tile order (`rows` entries).
    pub order: Handle,
    /// `tiles + 1` entries: tile `t`'s offsets are `offsets[start[t]..start[t + 1]]`.
    pub start: Handle,
    /// Room for `tiles · volume` entries, the first `start[tiles]` used.
    pub offsets: Handle,
    pub tiles: usize,
    /// Entries `offsets` has room for.
    pub offsets_capacity: usize,
}

impl DeviceRowTiles {
    /// The plan of `tile_rows`-row tiles over `table` (`rows × volume` on the device), whose
    /// entries below `n_src` are partners. `volume` is at most [`MAX_VOLUME`].
    pub fn build(client: &Client, table: &Handle, rows: usize, volume: usize, n_src: usize, tile_rows: usize) -> Self {
        assert!(volume <= MAX_VOLUME, "a device tile plan needs at most {MAX_VOLUME} offsets, got {volume}");
        assert!(rows > 0 && tile_rows > 0, "a tile plan is made for a gather with rows");
        let tiles = rows.div_ceil(tile_rows);
        let masks = client.empty(rows * size_of::<u32>());
        let (count, dim) = launch_1d(client, rows);
        // Safety: unit `r < rows` reads row `r` of the table and writes mask `r`.
        unsafe {
            row_mask_kernel::launch_unchecked(
                client,
                count,
                dim,
                BufferArg::from_raw_parts(table.clone(), rows * volume),
                BufferArg::from_raw_parts(masks.clone(), rows),
                rows,
                volume,
                n_src as u32,
            );
        }
        let order = sort_by_mask(client, &masks, rows, volume);
        let tile_masks = client.empty(tiles * size_of::<u32>());
        let tile_counts = client.empty(tiles * size_of::<u32>());
        let (count, dim) = launch_1d(client, tiles);
        // Safety: unit `t < tiles` reads the sorted rows of its tile (below `rows`) and writes
        // its own mask and count.
        unsafe {
            tile_mask_kernel::launch_unchecked(
                client,
                count.clone(),
                dim,
                BufferArg::from_raw_parts(order.clone(), rows),
                BufferArg::from_raw_parts(masks, rows),
                BufferArg::from_raw_parts(tile_masks.clone(), tiles),
                BufferArg::from_raw_parts(tile_counts.clone(), tiles),
                rows,
                tiles,
                volume,
                tile_rows,
            );
        }
        // The scan over `tiles` groups of one block each: `start[t]` is the count before tile `t`,
        // `start[tiles]` all of them.
        let firsts = client.empty(tiles * size_of::<u32>());
        let start = client.empty((tiles + 1) * size_of::<u32>());
        scan_counts(client, &tile_counts, &firsts, &start, tiles, 1);
        let offsets_capacity = tiles * volume.max(1);
        let offsets = client.empty(offsets_capacity * size_of::<u32>());
        // Safety: unit `t < tiles` writes its tile's offsets from `start[t]`, at most `volume`
        // of them: ranges of distinct tiles do not overlap and end within `tiles · volume`.
        unsafe {
            tile_offsets_kernel::launch_unchecked(
                client,
                count,
                dim,
                BufferArg::from_raw_parts(tile_masks, tiles),
                BufferArg::from_raw_parts(start.clone(), tiles + 1),
                BufferArg::from_raw_parts(offsets.clone(), offsets_capacity),
                tiles,
                volume,
            );
        }
        Self { order, start, offsets, tiles, offsets_capacity }
    }
}

/// Row indices sorted by `masks` (the low `bits` bits), equal masks by row: a stable LSD radix
/// sort, as the host's `radix_order`.
fn sort_by_mask(client: &Client, masks: &Handle, rows: usize, bits: usize) -> Handle {
    let blocks = rows.div_ceil(SORT_BLOCK_ROWS);
    let counts = client.empty(BUCKETS * blocks * size_of::<u32>());
    let firsts = client.empty(BUCKETS * blocks * size_of::<u32>());
    let bucket_starts = client.empty((BUCKETS + 1) * size_of::<u32>());
    let mut order = client.empty(rows * size_of::<u32>());
    let mut next = client.empty(rows * size_of::<u32>());
    let (count, dim) = launch_1d(client, blocks);
    let passes = bits.div_ceil(DIGIT_BITS).max(1);
    for pass in 0..passes {
        let shift = (pass * DIGIT_BITS) as u32;
        // The first pass reads the rows in their own order (no order buffer yet).
        let identity = pass == 0;
        // Safety: unit `b < blocks` reads its block's rows below `rows` and writes its own
        // column `b` of the `BUCKETS × blocks` counts.
        unsafe {
            digit_count_kernel::launch_unchecked(
                client,
                count.clone(),
                dim,
                BufferArg::from_raw_parts(order.clone(), rows),
                BufferArg::from_raw_parts(masks.clone(), rows),
                BufferArg::from_raw_parts(counts.clone(), BUCKETS * blocks),
                rows,
                blocks,
                shift,
                identity,
                SORT_BLOCK_ROWS,
                BUCKETS,
            );
        }
        scan_counts(client, &counts, &firsts, &bucket_starts, BUCKETS, blocks);
        // Safety: unit `b` places its block's rows from its firsts, the scan's sums of the counts
        // before them: every row lands once, below `rows`.
        unsafe {
            digit_scatter_kernel::launch_unchecked(
                client,
                count.clone(),
                dim,
                BufferArg::from_raw_parts(order.clone(), rows),
                BufferArg::from_raw_parts(masks.clone(), rows),
                BufferArg::from_raw_parts(firsts.clone(), BUCKETS * blocks),
                BufferArg::from_raw_parts(next.clone(), rows),
                rows,
                blocks,
                shift,
                identity,
                SORT_BLOCK_ROWS,
                BUCKETS,
            );
        }
        std::mem::swap(&mut order, &mut next);
    }
    order
}

/// `masks[r]`: bit `k` set where row `r` has a partner (an entry below `n_src`) at offset `k`.
#[cube(launch_unchecked)]
fn row_mask_kernel(table: &[u32], masks: &mut [u32], rows: usize, volume: usize, n_src: u32) {
    let r = ABSOLUTE_POS;
    if r >= rows {
        terminate!();
    }
    let mut mask = 0u32;
    for k in 0..volume {
        if table[r * volume + k] < n_src {
            mask |= 1u32 << (k as u32);
        }
    }
    masks[r] = mask;
}

/// The row at place `i` of the order being sorted: `i` itself on the first pass.
#[cube]
fn row_at(order: &[u32], i: usize, #[comptime] identity: bool) -> usize {
    if comptime!(identity) { i } else { order[i] as usize }
}

/// `counts[d · blocks + b]`: the rows of block `b` (in the current order) whose digit is `d`.
#[cube(launch_unchecked)]
#[allow(clippy::too_many_arguments)]
fn digit_count_kernel(
    order: &[u32],
    masks: &[u32],
    counts: &mut [u32],
    rows: usize,
    blocks: usize,
    shift: u32,
    #[comptime] identity: bool,
    #[comptime] block_rows: usize,
    #[comptime] buckets: usize,
) {
    let b = ABSOLUTE_POS;
    if b >= blocks {
        terminate!();
    }
    for d in 0..buckets {
        counts[d * blocks + b] = 0u32;
    }
    let first = b * block_rows;
    for j in 0..block_rows {
        let i = first + j;
        if i < rows {
            let d = ((masks[row_at(order, i, identity)] >> shift) & comptime!((buckets - 1) as u32)) as usize;
            counts[d * blocks + b] += 1u32;
        }
    }
}

/// Places block `b`'s rows, in their current order, at their digit's next free place.
#[cube(launch_unchecked)]
#[allow(clippy::too_many_arguments)]
fn digit_scatter_kernel(
    order: &[u32],
    masks: &[u32],
    firsts: &mut [u32],
    next: &mut [u32],
    rows: usize,
    blocks: usize,
    shift: u32,
    #[comptime] identity: bool,
    #[comptime] block_rows: usize,
    #[comptime] buckets: usize,
) {
    let b = ABSOLUTE_POS;
    if b >= blocks {
        terminate!();
    }
    let first = b * block_rows;
    for j in 0..block_rows {
        let i = first + j;
        if i < rows {
            let r = row_at(order, i, identity);
            let slot = ((masks[r] >> shift) & comptime!((buckets - 1) as u32)) as usize * blocks + b;
            let at = firsts[slot];
            next[at as usize] = r as u32;
            firsts[slot] = at + 1u32;
        }
    }
}

/// Tile `t`'s mask (the union of its rows') and how many offsets that is.
// The row's bound is checked before the order is read, in its own `if`: a kernel's `&&` need not
// short-circuit.
#[allow(clippy::collapsible_if)]
#[cube(launch_unchecked)]
#[allow(clippy::too_many_arguments)]
fn tile_mask_kernel(
    order: &[u32],
    masks: &[u32],
    tile_masks: &mut [u32],
    tile_counts: &mut [u32],
    rows: usize,
    tiles: usize,
    volume: usize,
    tile_rows: usize,
) {
    let t = ABSOLUTE_POS;
    if t >= tiles {
        terminate!();
    }
    let mut mask = 0u32;
    for j in 0..tile_rows {
        let i = t * tile_rows + j;
        if i < rows {
            mask |= masks[order[i] as usize];
        }
    }
    let mut n = 0u32;
    for k in 0..volume {
        n += (mask >> (k as u32)) & 1u32;
    }
    tile_masks[t] = mask;
    tile_counts[t] = n;
}

/// Tile `t`'s offsets, ascending, from `start[t]`.
#[cube(launch_unchecked)]
fn tile_offsets_kernel(tile_masks: &[u32], start: &[u32], offsets: &mut [u32], tiles: usize, volume: usize) {
    let t = ABSOLUTE_POS;
    if t >= tiles {
        terminate!();
    }
    let mask = tile_masks[t];
    let mut at = start[t] as usize;
    for k in 0..volume {
        if (mask >> (k as u32)) & 1u32 == 1u32 {
            offsets[at] = k as u32;
            at += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::coords::{Coord, CoordIndex};
    use crate::geometry::device_maps::tests::{client, read_u32, scene};
    use crate::geometry::kernel_map::KernelMap;
    use crate::geometry::row_tiles::RowTiles;
    use crate::kernels::cube::upload;

    /// The device's plan equals the host's over submanifold tables (forward and backward) and
    /// down-sampling ones, for scenes of one tile to several sort blocks.
    #[test]
    fn device_tile_plans_are_the_hosts() {
        let Some(client) = client() else { return };
        let mut several_blocks = 0;
        for (n, stride, tile_rows) in [(1, 1, 64), (40, 1, 64), (900, 1, 64), (2500, 2, 16), (12000, 1, 64)] {
            let coords: Vec<Coord> = scene(n, stride, n as u64 + 3);
            let sub = KernelMap::submanifold(&coords, &CoordIndex::build(&coords).unwrap(), 3, stride);
            let (down, _) = KernelMap::down(&coords, 2, stride).unwrap();
            let up = down.transposed();
            for (what, map) in [("submanifold", &sub), ("down", &down), ("up", &up)] {
                for (side, table, n_src) in [("forward", map.out_table(), map.n_in()), ("backward", map.in_table(), map.n_out())] {
                    let rows = table.rows();
                    let host = RowTiles::new(table, n_src, tile_rows);
                    let device = DeviceRowTiles::build(&client, &upload(&client, table.as_slice()), rows, table.volume(), n_src, tile_rows);
                    let at = format!("{what} {side}, {rows} rows, tiles of {tile_rows}");
                    assert_eq!(device.tiles, host.tiles(), "{at}: tiles");
                    assert_eq!(read_u32(&client, &device.order, rows), host.order, "{at}: order");
                    assert_eq!(read_u32(&client, &device.start, device.tiles + 1), host.start, "{at}: starts");
                    assert_eq!(read_u32(&client, &device.offsets, host.offsets.len()), host.offsets, "{at}: offsets");
                    several_blocks += (rows > 2 * SORT_BLOCK_ROWS) as usize;
                }
            }
        }
        assert!(several_blocks >= 4, "the scenes must sort over several blocks");
    }
}
