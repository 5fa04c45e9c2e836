//! A global allocator that asks the kernel for transparent huge pages
//! (2 MiB) for large blocks: [`HugePageAlloc`].
//!
//! Building the BVH of a million triangles allocates a few hundred
//! megabytes of fresh memory (obvhs's binary tree and its reinsertion
//! buffers, the 8-wide nodes, the triangle blocks). On a Linux system
//! whose transparent huge pages are enabled only on request
//! (`/sys/kernel/mm/transparent_hugepage/enabled` = `madvise`, a common
//! default), every 4 KiB page of it costs a page fault: on a 2-core AMD
//! EPYC VM, 42% of a 1M-triangle build's samples were in the kernel
//! (`perf record`). Embree asks for huge pages for its own structures;
//! this allocator does the same for every block of at least
//! [`HUGE_MIN_BYTES`], with `madvise(MADV_HUGEPAGE)` on the whole 2 MiB
//! pages inside the block before it is first written. Everything else is
//! [`std::alloc::System`]'s.
//!
//! The `prism` binary uses it; a program embedding Prism opts in with
//!
//! ```no_run
//! #[global_allocator]
//! static ALLOC: prism::core::alloc::HugePageAlloc = prism::core::alloc::HugePageAlloc;
//! ```
//!
//! On other systems, or where the kernel refuses the advice, it is the
//! system allocator: the advice is a hint, and nothing depends on it.

use std::alloc::{GlobalAlloc, Layout, System};

/// Blocks of at least this many bytes are advised to use huge pages.
pub const HUGE_MIN_BYTES: usize = 4 << 20;

/// Size of a transparent huge page on x86-64 and most aarch64 kernels.
const HUGE_PAGE: usize = 2 << 20;

/// [`System`], with `madvise(MADV_HUGEPAGE)` on blocks of at least
/// [`HUGE_MIN_BYTES`] (Linux only; elsewhere exactly [`System`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct HugePageAlloc;

/// Advises the whole huge pages inside `[p, p + size)` to be backed by
/// huge pages.
#[inline]
fn advise(p: *mut u8, size: usize) {
    #[cfg(target_os = "linux")]
    if size >= HUGE_MIN_BYTES && !p.is_null() {
        let start = (p as usize).next_multiple_of(HUGE_PAGE);
        let end = (p as usize + size) / HUGE_PAGE * HUGE_PAGE;
        if end > start {
            // SAFETY: `[start, end)` lies inside the block just allocated
            // to us; `madvise` with `MADV_HUGEPAGE` changes only how the
            // kernel backs those pages, never their contents, and fails
            // harmlessly (its result is ignored) where unsupported.
            #[allow(unsafe_code)]
            unsafe {
                libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (p, size);
}

// SAFETY: every call is forwarded to `System` with the same arguments; the
// advice afterwards only touches memory of the block being returned.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for HugePageAlloc {
    #[inline]
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded with the caller's guarantees.
        let p = unsafe { System.alloc(layout) };
        advise(p, layout.size());
        p
    }

    #[inline]
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded with the caller's guarantees.
        let p = unsafe { System.alloc_zeroed(layout) };
        advise(p, layout.size());
        p
    }

    #[inline]
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.dealloc(ptr, layout) }
    }

    #[inline]
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: forwarded with the caller's guarantees.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        advise(p, new_size);
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Large and small blocks come back usable, aligned as asked, and keep
    /// their contents through a reallocation across the threshold.
    #[test]
    fn blocks_of_every_size_work() {
        let a = HugePageAlloc;
        for (size, align) in [
            (16, 8),
            (4096, 64),
            (HUGE_MIN_BYTES, 32),
            (3 * HUGE_PAGE + 5, 4096),
        ] {
            let layout = Layout::from_size_align(size, align).unwrap();
            #[allow(unsafe_code)]
            // SAFETY: a non-zero-sized layout; the block is written within
            // its size and freed with the same layout.
            unsafe {
                let p = a.alloc_zeroed(layout);
                assert!(!p.is_null());
                assert_eq!(p as usize % align, 0);
                assert!(std::slice::from_raw_parts(p, size).iter().all(|&b| b == 0));
                p.write_bytes(7, size);
                let q = a.realloc(p, layout, size * 3);
                assert!(!q.is_null());
                assert!(std::slice::from_raw_parts(q, size).iter().all(|&b| b == 7));
                a.dealloc(q, Layout::from_size_align(size * 3, align).unwrap());
            }
        }
    }
}
