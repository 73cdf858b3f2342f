//! The field's large tables (hash-grid entries, their gradient accumulators, Adam's moments)
//! on 2 MB pages where the operating system allows it.
//!
//! How it works. Every sample of a UniCal step reads and writes about a hundred random entries
//! of tables tens of megabytes large. On 4 KB pages nearly each of those accesses also misses
//! the TLB and waits for a page walk; on 2 MB pages the same tables need a few dozen TLB
//! entries. Linux gives an allocation transparent huge pages by default only in its `always`
//! mode; the common `madvise` mode gives them to memory the program asks for with
//! `madvise(MADV_HUGEPAGE)`. [`zeroed`] allocates a zeroed table (untouched pages, so the
//! advice takes effect as they are first written) and gives that advice. It is advice only:
//! where it is refused, or on another OS, the table is the same, on ordinary pages.

/// Tables smaller than this stay as they are (a huge page is 2 MB).
const MIN_BYTES: usize = 4 << 20;

/// A zeroed table of `len` values, on huge pages where the OS allows.
pub fn zeroed(len: usize) -> Vec<f32> {
    let table = vec![0f32; len];
    advise_huge_pages(&table);
    table
}

#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn advise_huge_pages(table: &[f32]) {
    let bytes = std::mem::size_of_val(table);
    if bytes < MIN_BYTES {
        return;
    }
    // madvise wants a page-aligned start: the first whole 4 KB page of the table onwards.
    let page = 4096usize;
    let start = table.as_ptr() as usize;
    let aligned = start.next_multiple_of(page);
    let len = (start + bytes).saturating_sub(aligned) / page * page;
    // SAFETY: MADV_HUGEPAGE is advice about how to back the range; it changes neither the
    // memory's contents nor its validity, and the range lies within the table's allocation.
    // A refusal (an error return) leaves the table on ordinary pages, which is fine.
    unsafe {
        libc::madvise(aligned as *mut libc::c_void, len, libc::MADV_HUGEPAGE);
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages(_table: &[f32]) {}

#[cfg(test)]
mod tests {
    use super::*;

    /// A large table is zeroed and fully usable whether or not the advice was taken.
    #[test]
    fn a_large_table_is_zeroed_and_writable() {
        let mut table = zeroed(3 << 20);
        assert!(table.iter().all(|v| *v == 0.0));
        for (i, v) in table.iter_mut().enumerate().step_by(1021) {
            *v = i as f32;
        }
        assert_eq!(table[1021 * 5], (1021 * 5) as f32);
        assert!(zeroed(0).is_empty());
    }
}
