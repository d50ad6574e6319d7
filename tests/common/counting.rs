//! A counting allocator for the io tests: bytes live and their peak, per thread (the loaders
//! are single-threaded and tests run on several threads at once). A test file that includes
//! this module (`#[path = "common/counting.rs"] mod counting;`) counts every allocation.
#![allow(dead_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    static LIVE: Cell<usize> = const { Cell::new(0) };
    static PEAK: Cell<usize> = const { Cell::new(0) };
    /// Allocations (and reallocations) made, ever: a measure of work that a loaded machine
    /// cannot change, where a clock can.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn note_alloc(size: usize) {
    let _ = ALLOCATIONS.try_with(|a| a.set(a.get().wrapping_add(1)));
    let _ = LIVE.try_with(|live| {
        let now = live.get().saturating_add(size);
        live.set(now);
        let _ = PEAK.try_with(|p| p.set(p.get().max(now)));
    });
}

fn note_free(size: usize) {
    let _ = LIVE.try_with(|live| live.set(live.get().saturating_sub(size)));
}

// Counting needs `unsafe impl GlobalAlloc`; it forwards to the system allocator unchanged.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_alloc(layout.size());
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_alloc(layout.size());
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        note_free(layout.size());
        // SAFETY: forwarded with the caller's pointer and layout.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_free(layout.size());
        note_alloc(new_size);
        // SAFETY: forwarded with the caller's pointer, layout and size.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Bytes allocated by this thread and not yet freed.
pub fn live() -> usize {
    LIVE.with(Cell::get)
}

/// Runs `f` and returns its result with the peak of bytes allocated by this thread above what
/// was live when it started.
pub fn peak_during<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let base = LIVE.with(Cell::get);
    PEAK.with(|p| p.set(base));
    let r = f();
    let peak = PEAK.with(Cell::get);
    (r, peak.saturating_sub(base))
}

/// Runs `f` and returns its result with the peak of bytes allocated by this thread above what
/// was live when it started, and how many allocations it made.
pub fn peak_and_allocations_during<R>(f: impl FnOnce() -> R) -> (R, usize, usize) {
    let before = ALLOCATIONS.with(Cell::get);
    let (r, peak) = peak_during(f);
    let allocations = ALLOCATIONS.with(Cell::get).wrapping_sub(before);
    (r, peak, allocations)
}
