//! What every fuzz target shares: an allocator that aborts (a crash AFL records) when the bytes
//! live at once exceed a bound set from the input's size, so a size read from the input and
//! trusted before it is checked shows up as a find, not only as a machine running out of memory.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The allocator every target installs.
pub struct Bounded;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static LIMIT: AtomicUsize = AtomicUsize::new(usize::MAX);

unsafe impl GlobalAlloc for Bounded {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let live = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
        if live > LIMIT.load(Ordering::Relaxed) {
            over(live);
        }
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > layout.size() {
            let live = LIVE.fetch_add(new_size - layout.size(), Ordering::Relaxed) + new_size - layout.size();
            if live > LIMIT.load(Ordering::Relaxed) {
                over(live);
            }
        } else {
            LIVE.fetch_sub(layout.size() - new_size, Ordering::Relaxed);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[cold]
fn over(live: usize) -> ! {
    // No allocation here: print with a fixed buffer through libc-free std::io::stderr is not
    // guaranteed allocation-free, so abort plainly; the crash input reproduces it.
    let _ = live;
    std::process::abort()
}

/// Bytes a parser may hold beyond its input's multiple: the parsers' fixed tables and messages.
pub const SLACK: usize = 1 << 20;

/// Runs `f` with at most `factor × input + SLACK` bytes live beyond what was live before.
pub fn bounded<T>(input_len: usize, factor: usize, f: impl FnOnce() -> T) -> T {
    let base = LIVE.load(Ordering::Relaxed);
    LIMIT.store(base + factor.saturating_mul(input_len).saturating_add(SLACK), Ordering::Relaxed);
    let out = f();
    LIMIT.store(usize::MAX, Ordering::Relaxed);
    out
}

/// The multiple of the input a cloud reader may hold: its points take at most four times their
/// bytes; a `binary_compressed` PCD's block may first decode to 88 times its size (LZF's largest
/// expansion), whose points again take at most four times that, beside it.
pub fn cloud_factor(data: &[u8]) -> usize {
    let compressed = data.windows(17).take(4096).any(|w| w.eq_ignore_ascii_case(b"binary_compressed"));
    if compressed { 5 * 88 + 4 } else { 4 + 1 }
}
