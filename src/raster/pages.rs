//! Room for large outputs (a 4K plan's 66 MB of taps, a rig warp's maps), its pages mapped
//! before the parallel loop that fills it.
//!
//! A page's first write traps into the kernel, which zeroes and maps it. Taken one 4 KiB page at
//! a time inside a filling loop, those traps cost a 4K plan build about 40 % more than the same
//! build into mapped memory (measured with the plan's own rows; a separate pass over the pages
//! costs a quarter of that, and with transparent huge pages, where the kernel allows them on
//! request, half of it again).

use rayon::prelude::*;

const PAGE: usize = 4096;
const HUGE_PAGE: usize = 2 << 20;

/// An empty vector with room for `n` elements, every page of that room already written once
/// (with `touch`, overwritten by the caller).
pub(crate) fn mapped<T: Copy + Send + Sync>(n: usize, touch: T) -> Vec<T> {
    let mut v: Vec<T> = Vec::with_capacity(n);
    let bytes = n * size_of::<T>();
    if bytes >= 2 * HUGE_PAGE {
        advise_huge_pages(v.as_mut_ptr().cast(), bytes);
    }
    let per_page = (PAGE / size_of::<T>().max(1)).max(1);
    v.spare_capacity_mut()[..n]
        .par_chunks_mut(per_page)
        .with_min_len(64)
        .for_each(|page| {
            page[0].write(touch);
        });
    v
}

/// Asks Linux for transparent huge pages over the whole 2 MiB pages within `len` bytes from
/// `start`: one trap and one zeroing each instead of 512. Only a request: where huge pages are
/// off (or not Linux), nothing changes.
#[cfg(target_os = "linux")]
fn advise_huge_pages(start: *mut u8, len: usize) {
    let first = (start as usize).next_multiple_of(HUGE_PAGE);
    let end = (start as usize + len) / HUGE_PAGE * HUGE_PAGE;
    if end > first {
        // SAFETY: madvise only changes how the kernel backs these pages, which lie inside
        // this allocation; it reads or writes no memory. Its failure (huge pages disabled)
        // leaves the mapping as it was.
        unsafe {
            libc::madvise(first as *mut libc::c_void, end - first, libc::MADV_HUGEPAGE);
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages(_: *mut u8, _: usize) {}
