//! Down-sampling maps built on a GPU from a level's coordinates there, with the coarser level's
//! coordinates, so a forward pass keeps every level on the device. The host needs one number per
//! level, the coarse level's voxel count (a tensor shape): the caller gives it (counted on the
//! host before the pass, `level::coarse_level_sizes`) or it is read back, which waits for the
//! device's queue.
//!
//! - each fine row's coarse voxel `floor(c / s')·s'` (`s'` = kernel × stride) and its offset in it;
//! - a hash of the coarse voxels (the same open addressing as `device_maps`), each slot also
//!   keeping the lowest fine row that maps to it (an atomic minimum): that row owns the voxel;
//! - the coarse voxels numbered in their owners' row order by a count per block of rows, the
//!   one-cube scan, and a walk of each block in order: the host's order of first appearance;
//! - both tables, one entry per fine row.
//!
//! The map and the coarse coordinates equal [`KernelMap::down`]'s (tested on lavapipe).
//!
//! [`KernelMap::down`]: crate::KernelMap::down

use burn_cubecl::cubecl;
use burn_cubecl::cubecl::client::Client;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::cubecl::server::Handle;

use crate::geometry::device_maps::{DeviceMap, fill, launch_1d, scan_counts, slot_of};
use crate::geometry::kernel_map::NONE;

/// Rows a unit of the numbering walks.
const BLOCK_ROWS: usize = 512;

/// A down-sampling map made on a device, with its coarse level.
pub(crate) struct DeviceDown {
    /// The map's tables (outputs: the coarse voxels).
    pub map: DeviceMap,
    /// The coarse voxels' coordinates, `[coarse, 4]` `i32`.
    pub coarse_coords: Handle,
    /// Number of coarse voxels.
    pub coarse: usize,
}

impl DeviceDown {
    /// The down-sampling map (kernel = stride = `kernel`) of the `rows` coordinates `coords`
    /// (`[rows, 4]` `i32` on the device, unique, on the grid of tensor `stride`), whose coarse
    /// level has `coarse` voxels if the caller knows (read back otherwise).
    pub fn build(client: &Client, coords: &Handle, rows: usize, kernel: usize, stride: i32, coarse: Option<usize>) -> Self {
        assert!(rows > 0, "a device down-sampling map is made for a level with voxels");
        let volume = kernel.pow(3);
        let capacity = (2 * rows).next_power_of_two().max(64);
        let mask = (capacity - 1) as u32;
        let u32_buffer = |len: usize| client.empty(len.max(1) * size_of::<u32>());
        let parents = client.empty(4 * rows * size_of::<i32>());
        let offset_of_row = u32_buffer(rows);
        let slot_of_row = u32_buffer(rows);
        let slots = u32_buffer(capacity);
        let owners = u32_buffer(capacity);
        let number_of_slot = u32_buffer(capacity);
        fill(client, &slots, capacity, 0);
        fill(client, &owners, capacity, NONE);
        let (count, dim) = launch_1d(client, rows);
        // Safety: unit `r < rows` reads coordinates `4r..4r + 4` and writes its own parent,
        // offset and slot; slots are masked to a power-of-two capacity of at least twice the
        // rows, so the table never fills.
        unsafe {
            parent_insert_kernel::launch_unchecked(
                client,
                count.clone(),
                dim,
                BufferArg::from_raw_parts(coords.clone(), 4 * rows),
                BufferArg::from_raw_parts(parents.clone(), 4 * rows),
                BufferArg::from_raw_parts(offset_of_row.clone(), rows),
                BufferArg::from_raw_parts(slot_of_row.clone(), rows),
                BufferArg::from_raw_parts(slots, capacity),
                BufferArg::from_raw_parts(owners.clone(), capacity),
                rows,
                stride,
                kernel as i32,
                mask,
            );
        }
        let blocks = rows.div_ceil(BLOCK_ROWS);
        let counts = u32_buffer(blocks);
        let firsts = u32_buffer(blocks);
        let total = u32_buffer(2);
        let (block_count, block_dim) = launch_1d(client, blocks);
        // Safety: unit `b < blocks` reads its block's rows below `rows` and writes count `b`.
        unsafe {
            owner_count_kernel::launch_unchecked(
                client,
                block_count.clone(),
                block_dim,
                BufferArg::from_raw_parts(slot_of_row.clone(), rows),
                BufferArg::from_raw_parts(owners.clone(), capacity),
                BufferArg::from_raw_parts(counts.clone(), blocks),
                rows,
                blocks,
                BLOCK_ROWS,
            );
        }
        // One group of `blocks` blocks: `total[1]` is the number of coarse voxels.
        scan_counts(client, &counts, &firsts, &total, 1, blocks);
        let coarse = coarse.unwrap_or_else(|| {
            crate::profile::count_read_back();
            let bytes = client.read_one(total).expect("reading the coarse voxel count back");
            u32::from_bytes(&bytes)[1] as usize
        });
        let coarse_coords = client.empty(4 * coarse.max(1) * size_of::<i32>());
        // Safety: unit `b` numbers its block's owners from its first, the scan's count of the
        // owners before the block: distinct owners get distinct numbers below `coarse`.
        unsafe {
            number_kernel::launch_unchecked(
                client,
                block_count,
                block_dim,
                BufferArg::from_raw_parts(parents, 4 * rows),
                BufferArg::from_raw_parts(slot_of_row.clone(), rows),
                BufferArg::from_raw_parts(owners, capacity),
                BufferArg::from_raw_parts(firsts, blocks),
                BufferArg::from_raw_parts(number_of_slot.clone(), capacity),
                BufferArg::from_raw_parts(coarse_coords.clone(), 4 * coarse.max(1)),
                rows,
                blocks,
                coarse,
                BLOCK_ROWS,
            );
        }
        let forward = u32_buffer(coarse.max(1) * volume);
        let backward = u32_buffer(rows * volume);
        fill(client, &forward, coarse * volume, NONE);
        fill(client, &backward, rows * volume, NONE);
        // Safety: unit `r < rows` writes entry `(r, k_r)` of the backward table and
        // `(number, k_r)` of the forward one where `number < coarse` (always, with the right
        // count; the guard keeps a wrong one from writing out of bounds); fine rows are unique,
        // so no two share a (coarse voxel, offset).
        unsafe {
            down_table_kernel::launch_unchecked(
                client,
                count,
                dim,
                BufferArg::from_raw_parts(offset_of_row, rows),
                BufferArg::from_raw_parts(slot_of_row, rows),
                BufferArg::from_raw_parts(number_of_slot, capacity),
                BufferArg::from_raw_parts(forward.clone(), coarse.max(1) * volume),
                BufferArg::from_raw_parts(backward.clone(), rows * volume),
                rows,
                volume,
                coarse,
            );
        }
        Self { map: DeviceMap { forward, backward, rows: coarse, volume }, coarse_coords, coarse }
    }
}

/// `floor(a / step) · step` for `step > 0` (a kernel's `/` truncates towards zero).
#[cube]
fn floor_to(a: i32, step: i32) -> i32 {
    let mut q = a / step;
    if a % step != 0 && a < 0 {
        q -= 1;
    }
    q * step
}

/// Row `r`'s coarse voxel (into `parents`) and its offset in it, the voxel's slot in the hash
/// (claimed by compare-and-swap or found holding the same voxel), and the row offered as the
/// slot's owner (an atomic minimum).
#[cube(launch_unchecked)]
#[allow(clippy::too_many_arguments)]
fn parent_insert_kernel(
    coords: &[i32],
    parents: &mut [i32],
    offset_of_row: &mut [u32],
    slot_of_row: &mut [u32],
    slots: &mut [Atomic<u32>],
    owners: &mut [Atomic<u32>],
    rows: usize,
    stride: i32,
    kernel: i32,
    mask: u32,
) {
    let r = ABSOLUTE_POS;
    if r >= rows {
        terminate!();
    }
    let step = stride * kernel;
    let b = coords[4 * r];
    let x = floor_to(coords[4 * r + 1], step);
    let y = floor_to(coords[4 * r + 2], step);
    let z = floor_to(coords[4 * r + 3], step);
    parents[4 * r] = b;
    parents[4 * r + 1] = x;
    parents[4 * r + 2] = y;
    parents[4 * r + 3] = z;
    // x-major, as `KernelMap::down`'s offsets.
    let kx = (coords[4 * r + 1] - x) / stride;
    let ky = (coords[4 * r + 2] - y) / stride;
    let kz = (coords[4 * r + 3] - z) / stride;
    offset_of_row[r] = u32::cast_from((kx * kernel + ky) * kernel + kz);
    let mine = r as u32 + 1u32;
    let mut h = slot_of(b, x, y, z) & mask;
    loop {
        let previous = slots[h as usize].compare_exchange_weak(0u32, mine);
        // The slot's holder: `previous`, or after a weak exchange's failure with no competitor
        // (`previous` 0, the slot still empty), nobody yet: try the same slot again.
        let mut holder = previous;
        if previous == 0u32 {
            holder = slots[h as usize].load();
        }
        if holder == mine {
            break;
        }
        if holder != 0u32 {
            let q = (holder - 1u32) as usize;
            // The holder's parent from its coordinates (written before the launch, so visible
            // here), not from `parents`, which another unit may not have made visible yet.
            if coords[4 * q] == b
                && floor_to(coords[4 * q + 1], step) == x
                && floor_to(coords[4 * q + 2], step) == y
                && floor_to(coords[4 * q + 3], step) == z
            {
                break;
            }
            h = (h + 1u32) & mask;
        }
    }
    slot_of_row[r] = h;
    owners[h as usize].fetch_min(r as u32);
}

/// `counts[b]`: the rows of block `b` that own their coarse voxel.
// The row's bound is checked before the slot is read, in its own `if`: a kernel's `&&` need not
// short-circuit.
#[allow(clippy::collapsible_if)]
#[cube(launch_unchecked)]
fn owner_count_kernel(slot_of_row: &[u32], owners: &[u32], counts: &mut [u32], rows: usize, blocks: usize, #[comptime] block_rows: usize) {
    let b = ABSOLUTE_POS;
    if b >= blocks {
        terminate!();
    }
    let mut n = 0u32;
    for j in 0..block_rows {
        let r = b * block_rows + j;
        if r < rows {
            if owners[slot_of_row[r] as usize] == r as u32 {
                n += 1u32;
            }
        }
    }
    counts[b] = n;
}

/// Numbers block `b`'s owners in row order from `firsts[b]`: each owner's slot gets its number
/// and the number's coarse coordinates are the owner's parent (numbers from `coarse` on, which
/// only a wrong count gives, are not written).
#[cube(launch_unchecked)]
#[allow(clippy::too_many_arguments)]
fn number_kernel(
    parents: &[i32],
    slot_of_row: &[u32],
    owners: &[u32],
    firsts: &[u32],
    number_of_slot: &mut [u32],
    coarse_coords: &mut [i32],
    rows: usize,
    blocks: usize,
    coarse: usize,
    #[comptime] block_rows: usize,
) {
    let b = ABSOLUTE_POS;
    if b >= blocks {
        terminate!();
    }
    let mut at = firsts[b] as usize;
    for j in 0..block_rows {
        let r = b * block_rows + j;
        if r < rows {
            let slot = slot_of_row[r] as usize;
            if owners[slot] == r as u32 && at < coarse {
                number_of_slot[slot] = at as u32;
                coarse_coords[4 * at] = parents[4 * r];
                coarse_coords[4 * at + 1] = parents[4 * r + 1];
                coarse_coords[4 * at + 2] = parents[4 * r + 2];
                coarse_coords[4 * at + 3] = parents[4 * r + 3];
                at += 1;
            }
        }
    }
}

/// Row `r`'s entries: its coarse voxel in the backward table, the row itself in the forward one.
#[cube(launch_unchecked)]
#[allow(clippy::too_many_arguments)]
fn down_table_kernel(
    offset_of_row: &[u32],
    slot_of_row: &[u32],
    number_of_slot: &[u32],
    forward: &mut [u32],
    backward: &mut [u32],
    rows: usize,
    volume: usize,
    coarse: usize,
) {
    let r = ABSOLUTE_POS;
    if r >= rows {
        terminate!();
    }
    let k = offset_of_row[r] as usize;
    let o = number_of_slot[slot_of_row[r] as usize];
    if (o as usize) < coarse {
        backward[r * volume + k] = o;
        forward[o as usize * volume + k] = r as u32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::device_maps::tests::{client, read_u32, scene};
    use crate::geometry::kernel_map::KernelMap;
    use crate::kernels::cube::upload;

    /// The device's coarse coordinates, count and both tables equal the host's, for negative
    /// coordinates, strides 1–4 and scenes spanning several blocks.
    #[test]
    fn device_down_maps_are_the_hosts() {
        let Some(client) = client() else { return };
        let mut several_blocks = 0;
        for (n, stride, kernel) in [(1, 1, 2), (900, 1, 2), (2500, 2, 2), (700, 4, 2), (12000, 1, 2), (3000, 1, 3)] {
            let coords = scene(n, stride, n as u64 + 11);
            let (host, host_coarse) = KernelMap::down(&coords, kernel, stride).unwrap();
            let flat: Vec<i32> = coords.iter().flatten().copied().collect();
            // Counted on the device (read back), and given as the host counts it.
            let device = DeviceDown::build(&client, &upload(&client, &flat), coords.len(), kernel, stride, None);
            let given = DeviceDown::build(&client, &upload(&client, &flat), coords.len(), kernel, stride, Some(host_coarse.len()));
            let what_given = format!("{} rows, stride {stride}, kernel {kernel}, count given", coords.len());
            assert_eq!(read_u32(&client, &given.map.forward, given.coarse * host.volume()), host.out_table().as_slice(), "forward table, {what_given}");
            let what = format!("{} rows, stride {stride}, kernel {kernel}", coords.len());
            assert_eq!(device.coarse, host_coarse.len(), "coarse voxels, {what}");
            let bytes = client.read_one(device.coarse_coords.clone()).unwrap();
            let got: Vec<i32> = i32::from_bytes(&bytes)[..4 * device.coarse].to_vec();
            assert_eq!(got, host_coarse.iter().flatten().copied().collect::<Vec<_>>(), "coarse coordinates, {what}");
            let volume = host.volume();
            assert_eq!(read_u32(&client, &device.map.forward, device.coarse * volume), host.out_table().as_slice(), "forward table, {what}");
            assert_eq!(read_u32(&client, &device.map.backward, coords.len() * volume), host.in_table().as_slice(), "backward table, {what}");
            several_blocks += (coords.len() > 2 * BLOCK_ROWS) as usize;
        }
        assert!(several_blocks >= 2, "the scenes must number over several blocks");
    }
}
