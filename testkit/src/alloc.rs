//! A global allocator that counts live bytes and their peak, so a test can check that a
//! reader never allocates more than a bound tied to its input's size.
//!
//! A test binary opts in with
//!
//! ```ignore
//! #[global_allocator]
//! static ALLOC: testkit::TrackingAlloc = testkit::TrackingAlloc;
//! ```
//!
//! The counters are process-wide (a reader's rayon workers count too), so measurements
//! are meaningful only while nothing else allocates much: the mutation harness runs one
//! measurement at a time, and its tests live in test files of their own.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
/// Bytes handed out since the start (grown reallocations count their new size).
static TOTAL: AtomicUsize = AtomicUsize::new(0);
static INSTALLED: AtomicBool = AtomicBool::new(false);

/// The system allocator, counting live bytes and their peak.
pub struct TrackingAlloc;

impl TrackingAlloc {
    fn grew(size: usize) {
        let live = LIVE.fetch_add(size, Ordering::Relaxed) + size;
        PEAK.fetch_max(live, Ordering::Relaxed);
    }
}

// SAFETY: every call is forwarded to `System` unchanged; the counters only observe.
unsafe impl GlobalAlloc for TrackingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        INSTALLED.store(true, Ordering::Relaxed);
        // SAFETY: the caller's contract is passed on unchanged.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            Self::grew(layout.size());
            TOTAL.fetch_add(layout.size(), Ordering::Relaxed);
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        INSTALLED.store(true, Ordering::Relaxed);
        // SAFETY: as `alloc`.
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            Self::grew(layout.size());
            TOTAL.fetch_add(layout.size(), Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as `alloc`.
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: as `alloc`.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            TOTAL.fetch_add(new_size, Ordering::Relaxed);
            if new_size >= layout.size() {
                Self::grew(new_size - layout.size());
            } else {
                LIVE.fetch_sub(layout.size() - new_size, Ordering::Relaxed);
            }
        }
        p
    }
}

/// Whether the running binary declared [`TrackingAlloc`] as its global allocator.
pub fn installed() -> bool {
    // Any allocation sets the flag; make one in case none happened yet.
    drop(std::hint::black_box(Box::new(0u8)));
    INSTALLED.load(Ordering::Relaxed)
}

/// Measurements are serialised: the counters are process-wide.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

thread_local! {
    /// How many [`Exclusive`] guards this thread holds (the lock is re-entrant per thread).
    static DEPTH: std::cell::Cell<u32> = const { std::cell::Cell::new(0) };
}

/// The process's measurement lock, held by this thread until dropped.
pub struct Exclusive {
    _guard: Option<MutexGuard<'static, ()>>,
}

impl Drop for Exclusive {
    fn drop(&mut self) {
        DEPTH.with(|d| d.set(d.get() - 1));
    }
}

/// Hold while measuring. The mutation harness holds it for a whole run, and every test of
/// a binary that installs [`TrackingAlloc`] should hold it for its whole body: a test's
/// set-up (writing a file through a buffer, say) allocates too, and must not land inside
/// another test's measurement. Re-entrant: a thread that holds it may take it again.
pub fn exclusive() -> Exclusive {
    let depth = DEPTH.with(|d| {
        let v = d.get();
        d.set(v + 1);
        v
    });
    Exclusive {
        _guard: (depth == 0).then(|| ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())),
    }
}

/// Run `f` and return its result with the peak of live bytes above the level at the
/// start (0 when the tracking allocator is not installed). Waits for any other
/// measurement of this process to end.
pub fn peak_during<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let _guard = exclusive();
    peak_while_exclusive(f)
}

/// [`peak_during`] for a caller that holds [`exclusive`].
pub(crate) fn peak_while_exclusive<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let r = f();
    let peak = PEAK.load(Ordering::Relaxed);
    (r, peak.saturating_sub(base))
}

/// Run `f` and return its result with the bytes allocated while it ran (every
/// allocation counted, freed or not; a reallocation counts its new size); 0 when the
/// tracking allocator is not installed. Waits for any other measurement to end.
pub fn allocated_during<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let _guard = exclusive();
    let before = TOTAL.load(Ordering::Relaxed);
    let r = f();
    (r, TOTAL.load(Ordering::Relaxed) - before)
}
