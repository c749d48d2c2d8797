//! The process's heap policy for tensor-sized buffers.
//!
//! glibc's malloc serves a large block with its own `mmap` (above a threshold that starts at
//! 128 KiB) and gives it back to the kernel when freed, and trims the heap's free top above
//! 128 KiB. A training step allocates and frees feature maps of megabytes hundreds of times, so
//! every step would fault each of them in again, page by page, zeroed by the kernel: a large
//! share of a step's time (`crates/sparse-conv/README.md` gives the measurement). Peak RSS is
//! unchanged: the step's peak is the heap's peak either way.
//!
//! The same holds for rayon's worker threads: glibc gives each its own arena, whose heaps are
//! separate mappings of at most 64 MiB, made for a large block and unmapped when emptied (the
//! trim threshold does not keep them). One arena for the process keeps every freed block reusable;
//! the kernels allocate a few scratch tiles per task, so two threads do not contend for it.

/// Largest block glibc lets `mallopt` keep in the heap (`DEFAULT_MMAP_THRESHOLD_MAX` on 64-bit).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const MMAP_THRESHOLD: libc::c_int = 32 << 20;

/// Keeps freed tensor memory in the process for reuse instead of returning it to the kernel.
/// Binaries call it first thing in `main`; a no-op off glibc. Returns whether glibc took it.
pub fn retain_freed_memory() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt only sets malloc's parameters (under its own lock); it returns 1 when
        // it accepted the value.
        unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
                && libc::mallopt(libc::M_TRIM_THRESHOLD, libc::c_int::MAX) == 1
                && libc::mallopt(libc::M_ARENA_MAX, 1) == 1
        }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}
