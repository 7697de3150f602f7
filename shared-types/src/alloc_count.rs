//! A counting global allocator for the hot-path allocation tests: a test binary
//! installs it (`#[global_allocator] static A: CountingAllocator = CountingAllocator;`)
//! and counts the allocations one closure makes on the calling thread with
//! [`count_allocations`]. Other threads (the refresh thread, rayon's pool) are not
//! counted; allocations inside C++ (OpenCV) never pass through Rust's allocator.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// Allocations (and reallocations) counted on one thread, with their bytes and the
/// largest one.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Allocations {
    pub count: u64,
    pub bytes: u64,
    pub largest: u64,
}

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static SEEN: Cell<Allocations> = const {
        Cell::new(Allocations { count: 0, bytes: 0, largest: 0 })
    };
}

fn note(size: usize) {
    // `try_with`: the allocator runs during thread teardown too.
    let _ = COUNTING.try_with(|on| {
        if on.get() {
            let _ = SEEN.try_with(|s| {
                let mut a = s.get();
                a.count += 1;
                a.bytes += size as u64;
                a.largest = a.largest.max(size as u64);
                s.set(a);
            });
        }
    });
}

/// The system allocator, counting on threads inside [`count_allocations`].
pub struct CountingAllocator;

// SAFETY: every call is forwarded unchanged to the system allocator.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        System.alloc(layout)
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        System.alloc_zeroed(layout)
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(new_size);
        System.realloc(ptr, layout, new_size)
    }
}

/// Runs `f` and returns what it allocated on this thread (zero unless the binary
/// installed [`CountingAllocator`]).
pub fn count_allocations<R>(f: impl FnOnce() -> R) -> (R, Allocations) {
    SEEN.with(|s| s.set(Allocations::default()));
    COUNTING.with(|on| on.set(true));
    let r = f();
    COUNTING.with(|on| on.set(false));
    (r, SEEN.with(Cell::get))
}
