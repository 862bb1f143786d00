//! The fuzz harness of `tests/fuzz_*.rs` (issue 21): each decoder is fed random bytes and
//! structured mutations of valid inputs through proptest's runner. For every case:
//!
//! - a panic is caught (`catch_unwind`) and reported with the input, then proptest shrinks
//!   the input and reports the smallest that still fails;
//! - the largest single allocation the decoder makes is measured (a counting global
//!   allocator, per thread) and must stay under the decoder's bound for that input;
//! - a rejection must carry a reason key, which is counted; the counts and the time are
//!   printed (and, with `HANDEYE_FUZZ_REPORT=FILE`, appended to FILE as one JSON line).
//!
//! The short run (`make test`) uses a fixed seed and a few thousand cases per decoder; the
//! long run (`make fuzz`, the `#[ignore]`d `*_long` tests) takes its case count from
//! `HANDEYE_FUZZ_CASES` (default 10⁶) and its seed from `HANDEYE_FUZZ_SEED` (default: the
//! clock, printed so that a failure can be replayed).
#![allow(dead_code)]

pub mod mutate;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::{Cell, RefCell};
use std::collections::BTreeMap;
use std::fmt::Debug;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::Instant;

use proptest::strategy::Strategy;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestError, TestRng, TestRunner};

/// Counts the largest single allocation of the current thread.
pub struct LargestAlloc;

thread_local! {
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

fn note(bytes: usize) {
    let _ = LARGEST.try_with(|c| {
        if bytes > c.get() {
            c.set(bytes)
        }
    });
}

// SAFETY: every call is forwarded to the system allocator unchanged; `note` only touches a
// const-initialised thread-local `Cell` and never allocates.
unsafe impl GlobalAlloc for LargestAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(new_size);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: LargestAlloc = LargestAlloc;

/// What a decoder made of one input: accepted, or rejected with the reason's counter key.
pub type Outcome = Result<(), String>;

/// Cases for a long run: `HANDEYE_FUZZ_CASES`, default 10⁶.
pub fn long_cases() -> u32 {
    match std::env::var("HANDEYE_FUZZ_CASES") {
        Ok(v) => v.trim().parse().unwrap_or_else(|_| panic!("HANDEYE_FUZZ_CASES={v:?}: expected a whole number of cases")),
        Err(_) => 1_000_000,
    }
}

fn long_seed() -> u64 {
    match std::env::var("HANDEYE_FUZZ_SEED") {
        Ok(v) => v.trim().parse().unwrap_or_else(|_| panic!("HANDEYE_FUZZ_SEED={v:?}: expected a whole number")),
        Err(_) => std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos() as u64).unwrap_or(1),
    }
}

/// One decoder's fuzz run.
pub struct Fuzz {
    pub name: &'static str,
    pub cases: u32,
    pub seed: u64,
}

impl Fuzz {
    /// The short run of `make test`: `cases`, a fixed seed.
    pub fn short(name: &'static str, cases: u32) -> Self {
        Self { name, cases, seed: 1 }
    }

    /// The long run of `make fuzz`.
    pub fn long(name: &'static str) -> Self {
        Self { name, cases: long_cases(), seed: long_seed() }
    }

    /// Runs `decode` on `cases` inputs drawn from `inputs`; `alloc_bound(input)` is the
    /// largest single allocation, bytes, the decoder may make for that input. Returns the
    /// rejection counts by key (and `accepted`).
    pub fn run<S>(&self, inputs: S, alloc_bound: impl Fn(&S::Value) -> usize, decode: impl Fn(&S::Value) -> Outcome) -> BTreeMap<String, u64>
    where
        S: Strategy,
        S::Value: Debug,
    {
        let config = Config { cases: self.cases, failure_persistence: None, max_shrink_iters: 2000, ..Config::default() };
        let mut seed = [0u8; 32];
        seed[..8].copy_from_slice(&self.seed.to_le_bytes());
        let mut runner = TestRunner::new_with_rng(config, TestRng::from_seed(RngAlgorithm::ChaCha, &seed));
        let counts: RefCell<BTreeMap<String, u64>> = RefCell::new(BTreeMap::new());
        let largest = Cell::new(0usize);
        let start = Instant::now();
        let result = runner.run(&inputs, |input| {
            LARGEST.with(|c| c.set(0));
            let outcome = catch_unwind(AssertUnwindSafe(|| decode(&input)));
            let peak = LARGEST.with(|c| c.get());
            let outcome = outcome.map_err(|p| {
                let msg = p.downcast_ref::<String>().cloned().or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string())).unwrap_or_default();
                TestCaseError::fail(format!("{}: the decoder panicked ({msg}) on {input:?}", self.name))
            })?;
            let bound = alloc_bound(&input);
            if peak > bound {
                return Err(TestCaseError::fail(format!("{}: an allocation of {peak} bytes (bound {bound}) on {input:?}", self.name)));
            }
            largest.set(largest.get().max(peak));
            let key = match outcome {
                Ok(()) => "accepted".to_string(),
                Err(key) if key.is_empty() => return Err(TestCaseError::fail(format!("{}: a rejection without a reason on {input:?}", self.name))),
                Err(key) => key,
            };
            *counts.borrow_mut().entry(key).or_insert(0) += 1;
            Ok(())
        });
        let secs = start.elapsed().as_secs_f64();
        if let Err(e) = result {
            match e {
                TestError::Fail(why, input) => panic!("fuzz {} (seed {}): {why}\nsmallest failing input: {input:?}", self.name, self.seed),
                TestError::Abort(why) => panic!("fuzz {} (seed {}): aborted: {why}", self.name, self.seed),
            }
        }
        let counts = counts.into_inner();
        let rejected: u64 = counts.iter().filter(|(k, _)| *k != "accepted").map(|(_, n)| n).sum();
        let detail: Vec<String> = counts.iter().filter(|(k, _)| *k != "accepted").map(|(k, n)| format!("{k} {n}")).collect();
        println!(
            "fuzz {}: {} cases in {secs:.1} s (seed {}), no panic; {} accepted, {rejected} rejected ({}); largest allocation {} bytes",
            self.name,
            self.cases,
            self.seed,
            counts.get("accepted").copied().unwrap_or(0),
            detail.join(", "),
            largest.get()
        );
        if let Ok(path) = std::env::var("HANDEYE_FUZZ_REPORT") {
            let line = serde_json::json!({
                "decoder": self.name, "cases": self.cases, "seed": self.seed, "seconds": (secs * 10.0).round() / 10.0,
                "outcomes": counts, "largest_alloc_bytes": largest.get(),
            });
            use std::io::Write;
            let mut f = std::fs::OpenOptions::new().create(true).append(true).open(&path).unwrap_or_else(|e| panic!("HANDEYE_FUZZ_REPORT={path}: {e}"));
            writeln!(f, "{line}").unwrap_or_else(|e| panic!("HANDEYE_FUZZ_REPORT={path}: {e}"));
        }
        counts
    }
}

/// Checks a run reached both sides of the decoder: some inputs accepted (the structured
/// mutations keep valid ones) and every reason in `expected_keys` seen, so that a strategy
/// that stopped reaching the decoder's deeper checks fails the test.
pub fn assert_coverage(name: &str, counts: &BTreeMap<String, u64>, expected_keys: &[&str]) {
    assert!(counts.get("accepted").copied().unwrap_or(0) > 0, "fuzz {name}: no input was accepted: {counts:?}");
    for k in expected_keys {
        assert!(counts.get(*k).copied().unwrap_or(0) > 0, "fuzz {name}: no input was rejected for `{k}`: {counts:?}");
    }
}
