//! Kernel maps built on a GPU: a forward pass has each level's coordinates on the device (the
//! input's uploaded, 16 bytes a voxel, the coarser levels made there by
//! `crate::geometry::device_down`) instead of building and uploading its tables (27 × 4 bytes a
//! voxel each way for a submanifold map, and the host's hashing and probing). Here: the
//! submanifold maps and, for every map kind, the weight gradient's pairs.
//!
//! - a hash of the coordinates: open addressing over `u32` slots holding `row + 1`, claimed with
//!   a compare-and-swap (32-bit atomics, which every Vulkan driver has; a weak exchange's spurious
//!   failure is told from a lost race by reading the slot back) and compared on all four
//!   coordinates, so no key packing limits the range;
//! - the forward's table: one unit per (row, offset) probes for `row + offset`; the feature
//!   gradient's table is the same entry at the negated offset `volume − 1 − k`;
//! - the weight gradient's pairs grouped by offset, in output-row order within an offset, as
//!   `KernelMap::pairs` orders them on the host: a count per (offset, block of rows), a scan by
//!   one cube, and a scatter that walks each block's rows in order.
//!
//! The tables equal the host's ([`KernelMap::submanifold`]) entry for entry, tested on lavapipe.
//!
//! [`KernelMap::submanifold`]: crate::KernelMap::submanifold

use burn_cubecl::cubecl;
use burn_cubecl::cubecl::client::Client;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::cubecl::server::Handle;

use crate::geometry::kernel_map::offsets;
use crate::kernels::cube::upload;

/// Rows a unit of the pair count and scatter walks.
const BLOCK_ROWS: usize = 512;

/// Units of the one cube that scans the pair counts.
const SCAN_UNITS: usize = 256;

/// A map's tables on a device.
pub(crate) struct DeviceMap {
    /// `rows × volume`: for each output row, its input row at each offset (`NONE`: none).
    pub forward: Handle,
    /// For each input row, its output row at each offset.
    pub backward: Handle,
    /// The forward table's rows (the map's outputs) and offsets.
    pub rows: usize,
    pub volume: usize,
}

/// The weight gradient's pairs on a device: `start` has `volume + 1` entries (read on the device
/// only); `input` and `output` have room for every (row, offset), the first `start[volume]` used.
pub(crate) struct DevicePairs {
    pub start: Handle,
    pub input: Handle,
    pub output: Handle,
    /// Entries `input` and `output` have room for.
    pub capacity: usize,
}

pub(crate) fn launch_1d(client: &Client, units: usize) -> (CubeCount, CubeDim) {
    let dim = CubeDim::new_1d(256);
    (cubecl::calculate_cube_count_elemwise(client, units.max(1), dim), dim)
}

/// The exclusive scan, by one cube, of `groups × blocks` counts laid out group by group: where
/// each (group, block)'s items begin into `firsts`, where each group's begin into
/// `start[group]`, and the total into `start[groups]`. What every count/scan/scatter build here
/// and in `device_down`, `device_tiles` shares.
pub(crate) fn scan_counts(client: &Client, counts: &Handle, firsts: &Handle, start: &Handle, groups: usize, blocks: usize) {
    // Safety: one cube reads `groups · blocks` counts and writes as many firsts and `groups + 1`
    // starts, the buffers' sizes by the callers; its units' stretches are clamped to the counts.
    unsafe {
        pair_scan_kernel::launch_unchecked(
            client,
            CubeCount::Static(1, 1, 1),
            CubeDim::new_1d(SCAN_UNITS as u32),
            BufferArg::from_raw_parts(counts.clone(), groups * blocks),
            BufferArg::from_raw_parts(firsts.clone(), groups * blocks),
            BufferArg::from_raw_parts(start.clone(), groups + 1),
            groups,
            blocks,
            SCAN_UNITS,
        );
    }
}

/// `handle[..len] = value`, by a kernel: a build runs in the middle of a forward pass, and an
/// upload there may wait for the queue.
pub(crate) fn fill(client: &Client, handle: &Handle, len: usize, value: u32) {
    if len == 0 {
        return;
    }
    let (count, dim) = launch_1d(client, len);
    // Safety: unit `i < len` writes entry `i` of a buffer of at least `len`.
    unsafe {
        fill_kernel::launch_unchecked(client, count, dim, BufferArg::from_raw_parts(handle.clone(), len), len, value);
    }
}

impl DeviceMap {
    /// The same tables read the other way: the map transposed, whose outputs are the `rows`
    /// inputs of this one.
    pub fn transposed(&self, rows: usize) -> Self {
        Self { forward: self.backward.clone(), backward: self.forward.clone(), rows, volume: self.volume }
    }

    /// The tables of the submanifold map of an odd `kernel` over the `rows` coordinates `coords`
    /// (`[rows, 4]` `i32` on the device) at tensor `stride`. The coordinates must be unique (a
    /// [`crate::SparseTensor`]'s are).
    pub fn submanifold(client: &Client, coords_handle: &Handle, rows: usize, kernel: usize, stride: i32) -> Self {
        let offsets: Vec<i32> = offsets(kernel, -(kernel as i32 / 2), stride).into_iter().flatten().collect();
        let volume = offsets.len() / 3;
        let capacity = (2 * rows).next_power_of_two().max(64);
        let slots = client.empty(capacity * size_of::<u32>());
        fill(client, &slots, capacity, 0);
        let forward = client.empty(rows.max(1) * volume * size_of::<u32>());
        let backward = client.empty(rows.max(1) * volume * size_of::<u32>());
        if rows > 0 {
            let mask = (capacity - 1) as u32;
            let (count, dim) = launch_1d(client, rows);
            // Safety: unit `r < rows` reads coordinates `4r..4r + 4`; slots are masked to the
            // table's power-of-two capacity, which is at least twice the rows (never full).
            unsafe {
                hash_insert_kernel::launch_unchecked(
                    client,
                    count,
                    dim,
                    BufferArg::from_raw_parts(coords_handle.clone(), 4 * rows),
                    BufferArg::from_raw_parts(slots.clone(), capacity),
                    rows,
                    mask,
                );
            }
            let offsets_handle = upload(client, &offsets);
            let (count, dim) = launch_1d(client, rows * volume);
            // Safety: unit `(r, k)` with `r < rows`, `k < volume` writes entry `(r, k)` of the
            // forward table and `(r, volume − 1 − k)` of the backward one; probes are masked.
            unsafe {
                submanifold_table_kernel::launch_unchecked(
                    client,
                    count,
                    dim,
                    BufferArg::from_raw_parts(coords_handle.clone(), 4 * rows),
                    BufferArg::from_raw_parts(slots, capacity),
                    BufferArg::from_raw_parts(offsets_handle, 3 * volume),
                    BufferArg::from_raw_parts(forward.clone(), rows * volume),
                    BufferArg::from_raw_parts(backward.clone(), rows * volume),
                    rows,
                    volume,
                    mask,
                );
            }
        }
        Self { forward, backward, rows, volume }
    }

    /// The forward table's pairs grouped by offset, output rows in order within an offset.
    pub fn pairs(&self, client: &Client) -> DevicePairs {
        let (rows, volume) = (self.rows, self.volume);
        let capacity = (rows * volume).max(1);
        let blocks = rows.div_ceil(BLOCK_ROWS).max(1);
        let counts = client.empty(volume * blocks * size_of::<u32>());
        let firsts = client.empty(volume * blocks * size_of::<u32>());
        // The scan writes every start; with no rows nothing runs, so those are zeroed here.
        let start = if rows == 0 { upload(client, &vec![0u32; volume + 1]) } else { client.empty((volume + 1) * size_of::<u32>()) };
        let input = client.empty(capacity * size_of::<u32>());
        let output = client.empty(capacity * size_of::<u32>());
        if rows > 0 {
            // Safety: the forward table holds `rows · volume` entries.
            let table = || unsafe { BufferArg::from_raw_parts(self.forward.clone(), rows * volume) };
            let (count, dim) = launch_1d(client, volume * blocks);
            // Safety: unit `(k, b)` reads rows `b·BLOCK_ROWS..` below `rows` at offset `k` and
            // writes its own count.
            unsafe {
                pair_count_kernel::launch_unchecked(
                    client,
                    count.clone(),
                    dim,
                    table(),
                    BufferArg::from_raw_parts(counts.clone(), volume * blocks),
                    rows,
                    volume,
                    blocks,
                    BLOCK_ROWS,
                );
            }
            scan_counts(client, &counts, &firsts, &start, volume, blocks);
            // Safety: unit `(k, b)` writes its block's pairs of offset `k` from its first, the
            // scan's sum of the counts before it: ranges of distinct units do not overlap and
            // end at most at `rows · volume`.
            unsafe {
                pair_scatter_kernel::launch_unchecked(
                    client,
                    count,
                    dim,
                    table(),
                    BufferArg::from_raw_parts(firsts, volume * blocks),
                    BufferArg::from_raw_parts(input.clone(), capacity),
                    BufferArg::from_raw_parts(output.clone(), capacity),
                    rows,
                    volume,
                    blocks,
                    BLOCK_ROWS,
                );
            }
        }
        DevicePairs { start, input, output, capacity }
    }
}

/// `values[i] = value` for `i < len`.
#[cube(launch_unchecked)]
fn fill_kernel(values: &mut [u32], len: usize, value: u32) {
    if ABSOLUTE_POS >= len {
        terminate!();
    }
    values[ABSOLUTE_POS] = value;
}

/// A slot for coordinate `(b, x, y, z)`, before masking: a multiplicative mix of the four.
#[cube]
pub(crate) fn slot_of(b: i32, x: i32, y: i32, z: i32) -> u32 {
    let mut h = u32::cast_from(b) * 0x9E37_79B1u32;
    h = (h ^ u32::cast_from(x)) * 0x85EB_CA77u32;
    h = (h ^ u32::cast_from(y)) * 0xC2B2_AE3Du32;
    h = (h ^ u32::cast_from(z)) * 0x27D4_EB2Fu32;
    h ^ (h >> 15u32)
}

/// Claims a slot for each row: the first empty one from the coordinate's own, by linear probing.
#[cube(launch_unchecked)]
fn hash_insert_kernel(coords: &[i32], slots: &mut [Atomic<u32>], rows: usize, mask: u32) {
    let r = ABSOLUTE_POS;
    if r >= rows {
        terminate!();
    }
    let mine = r as u32 + 1u32;
    let mut h = slot_of(coords[4 * r], coords[4 * r + 1], coords[4 * r + 2], coords[4 * r + 3]) & mask;
    loop {
        let previous = slots[h as usize].compare_exchange_weak(0u32, mine);
        if previous == 0u32 {
            // A weak exchange may fail with no competitor (WGSL's may, on Metal through naga):
            // the slot says whether it took. Empty still: try the same slot again.
            let now = slots[h as usize].load();
            if now == mine {
                break;
            }
            if now != 0u32 {
                h = (h + 1u32) & mask;
            }
        } else {
            h = (h + 1u32) & mask;
        }
    }
}

/// Entry `(r, k)` of the forward table, `r + offset_k`'s row or `NONE` (`u32::MAX`), and the same entry at
/// the negated offset of the backward table.
#[cube(launch_unchecked)]
#[allow(clippy::too_many_arguments)]
fn submanifold_table_kernel(
    coords: &[i32],
    slots: &[u32],
    offsets: &[i32],
    forward: &mut [u32],
    backward: &mut [u32],
    rows: usize,
    volume: usize,
    mask: u32,
) {
    let pos = ABSOLUTE_POS;
    if pos >= rows * volume {
        terminate!();
    }
    let r = pos / volume;
    let k = pos % volume;
    let b = coords[4 * r];
    let x = coords[4 * r + 1] + offsets[3 * k];
    let y = coords[4 * r + 2] + offsets[3 * k + 1];
    let z = coords[4 * r + 3] + offsets[3 * k + 2];
    let mut h = slot_of(b, x, y, z) & mask;
    let mut found = 0xFFFF_FFFFu32;
    loop {
        let slot = slots[h as usize];
        if slot == 0u32 {
            break;
        }
        let o = (slot - 1u32) as usize;
        if coords[4 * o] == b && coords[4 * o + 1] == x && coords[4 * o + 2] == y && coords[4 * o + 3] == z {
            found = slot - 1u32;
            break;
        }
        h = (h + 1u32) & mask;
    }
    forward[r * volume + k] = found;
    backward[r * volume + (volume - 1 - k)] = found;
}

/// `counts[k · blocks + b]`: the rows of block `b` with a partner at offset `k`.
// The row's bound is checked before the table is read, in its own `if`: a kernel's `&&` need not
// short-circuit.
#[allow(clippy::collapsible_if)]
#[cube(launch_unchecked)]
fn pair_count_kernel(table: &[u32], counts: &mut [u32], rows: usize, volume: usize, blocks: usize, #[comptime] block_rows: usize) {
    let pos = ABSOLUTE_POS;
    if pos >= volume * blocks {
        terminate!();
    }
    let k = pos / blocks;
    let first = (pos % blocks) * block_rows;
    let mut count = 0u32;
    for j in 0..block_rows {
        let r = first + j;
        if r < rows {
            if table[r * volume + k] != 0xFFFF_FFFFu32 {
                count += 1u32;
            }
        }
    }
    counts[pos] = count;
}

/// Where each (offset, block)'s pairs begin, offset by offset and block by block, and where each
/// offset's begin (`start[volume]`: all pairs): an exclusive scan of the counts by one cube, each
/// of its `units` units over its own stretch of them, the stretches' sums scanned by the first.
// CubeCL kernels index their buffers; they have no slice iterators.
#[allow(clippy::needless_range_loop)]
#[cube(launch_unchecked)]
fn pair_scan_kernel(counts: &[u32], firsts: &mut [u32], start: &mut [u32], volume: usize, blocks: usize, #[comptime] units: usize) {
    let len = volume * blocks;
    let u = UNIT_POS as usize;
    let stretch = len.div_ceil(units);
    let from = u * stretch;
    let mut to = from + stretch;
    if to > len {
        to = len;
    }
    let mut partial = Shared::<[u32]>::new_slice(units);
    let mut sum = 0u32;
    for i in from..to {
        sum += counts[i];
    }
    partial[u] = sum;
    sync_cube();
    if u == 0 {
        let mut run = 0u32;
        for j in 0..units {
            let c = partial[j];
            partial[j] = run;
            run += c;
        }
        start[volume] = run;
    }
    sync_cube();
    let mut next = partial[u];
    for i in from..to {
        firsts[i] = next;
        if i % blocks == 0 {
            start[i / blocks] = next;
        }
        next += counts[i];
    }
}

/// Writes block `b`'s pairs of offset `k` (input: the partner, output: the row) in row order from
/// the block's first slot.
#[cube(launch_unchecked)]
#[allow(clippy::too_many_arguments)]
fn pair_scatter_kernel(
    table: &[u32],
    firsts: &[u32],
    input: &mut [u32],
    output: &mut [u32],
    rows: usize,
    volume: usize,
    blocks: usize,
    #[comptime] block_rows: usize,
) {
    let pos = ABSOLUTE_POS;
    if pos >= volume * blocks {
        terminate!();
    }
    let k = pos / blocks;
    let first = (pos % blocks) * block_rows;
    let mut at = firsts[pos] as usize;
    for j in 0..block_rows {
        let r = first + j;
        if r < rows {
            let partner = table[r * volume + k];
            if partner != 0xFFFF_FFFFu32 {
                input[at] = partner;
                output[at] = r as u32;
                at += 1;
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::geometry::coords::{Coord, CoordIndex};
    use crate::geometry::kernel_map::KernelMap;

    pub(crate) fn client() -> Option<Client> {
        let device = match crate::wgpu_device() {
            Ok(device) => device,
            Err(e) if std::env::var("PMUNET_REQUIRE_WGPU").is_ok_and(|v| v == "1") => panic!("PMUNET_REQUIRE_WGPU=1 but {e}"),
            Err(e) => {
                eprintln!("skipping the device maps' test: {e}");
                return None;
            }
        };
        match device.as_dispatch() {
            burn::backend::DispatchDevice::Cube(d) => Some(d.client()),
            _ => unreachable!("wgpu_device is a cube device"),
        }
    }

    pub(crate) fn read_u32(client: &Client, handle: &Handle, len: usize) -> Vec<u32> {
        let bytes = client.read_one(handle.clone()).expect("read back");
        u32::from_bytes(&bytes)[..len].to_vec()
    }

    /// Unique coordinates on the grid of `stride`: two batch entries, negative and positive
    /// coordinates, clusters dense enough that most offsets find a neighbour somewhere.
    pub(crate) fn scene(n: usize, stride: i32, seed: u64) -> Vec<Coord> {
        let mut state = seed;
        let mut next = |m: i32| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 33) % m as u64) as i32
        };
        let mut coords: Vec<Coord> =
            (0..n).map(|_| [next(2), (next(21) - 10) * stride, (next(17) - 8) * stride, (next(9) - 4) * stride]).collect();
        coords.sort();
        coords.dedup();
        // Not sorted: the device must not rely on the order.
        let len = coords.len();
        for i in 0..len {
            coords.swap(i, (i * 7919) % len);
        }
        coords
    }

    #[test]
    fn device_tables_and_pairs_are_the_hosts() {
        let Some(client) = client() else { return };
        // The last two scan more counts (offsets × blocks of rows) than the scan has units.
        let mut longer_than_the_scan = 0;
        for (n, stride, kernel) in [(0, 1, 3), (1, 1, 3), (900, 1, 3), (2500, 2, 3), (700, 4, 5), (3000, 1, 1), (12000, 1, 3), (5000, 2, 5)] {
            let coords = scene(n, stride, n as u64 + 1);
            let host = KernelMap::submanifold(&coords, &CoordIndex::build(&coords).unwrap(), kernel, stride);
            let flat: Vec<i32> = coords.iter().flatten().copied().collect();
            let device = DeviceMap::submanifold(&client, &upload(&client, &flat), coords.len(), kernel, stride);
            let (rows, volume) = (coords.len(), host.volume());
            let what = format!("{rows} rows, stride {stride}, kernel {kernel}");
            assert_eq!(read_u32(&client, &device.forward, rows * volume), host.out_table().as_slice(), "forward table, {what}");
            assert_eq!(read_u32(&client, &device.backward, rows * volume), host.in_table().as_slice(), "backward table, {what}");
            let pairs = device.pairs(&client);
            let expected = host.pairs();
            let start: Vec<usize> = read_u32(&client, &pairs.start, volume + 1).into_iter().map(|s| s as usize).collect();
            assert_eq!(start, expected.start, "pair starts, {what}");
            let total = expected.input.len();
            assert_eq!(read_u32(&client, &pairs.input, total), expected.input, "pair inputs, {what}");
            assert_eq!(read_u32(&client, &pairs.output, total), expected.output, "pair outputs, {what}");
            longer_than_the_scan += (volume * rows.div_ceil(BLOCK_ROWS) > SCAN_UNITS) as usize;
        }
        assert_eq!(longer_than_the_scan, 2);
    }
}
