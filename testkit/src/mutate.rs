//! The seeded mutation harness: thousands of damaged copies of one valid file, each
//! handed to a reader, which must return an error naming the file (or a valid result),
//! never panic, and never allocate more than a bound tied to the file's size.
//!
//! ```ignore
//! let report = testkit::fuzz_reader(&path, &valid_bytes, 7, |p| read_evs(p, &opts));
//! report.assert_clean();
//! ```
//!
//! The damage (one [`Mutation`] per copy, drawn from a seeded generator, so a run is
//! reproducible and a failure names the exact mutation): bit flips, byte overwrites,
//! aligned 4- and 8-byte words set to hostile values (huge, negative, zero; at the
//! format's declared length fields and at random places), decimal numbers replaced by
//! hostile ones (for text formats: counts, sizes, `1e309`, `NaN`), truncation at any
//! point, extension with hostile bytes, insertion and deletion of bytes, one byte
//! repeated thousands of times (deep nesting in JSON/TOML) and a chunk duplicated.
//! Formats protected by a checksum give a [`Plan::fixup`] that recomputes it, applied to
//! every other copy, so the damage also reaches the parser behind the checksum.

use super::alloc;
use std::fmt::{self, Display};
use std::path::Path;

/// One way of damaging a file; [`Mutation::apply`] reproduces it.
#[derive(Clone, Debug, PartialEq)]
pub enum Mutation {
    FlipBit {
        at: usize,
        bit: u8,
    },
    SetByte {
        at: usize,
        value: u8,
    },
    /// A little-endian word of `width` (4 or 8) bytes at `at` set to `value`.
    SetWord {
        at: usize,
        width: usize,
        value: u64,
    },
    /// The decimal number starting at `at` (`len` bytes) replaced by `text`.
    SetNumber {
        at: usize,
        len: usize,
        text: String,
    },
    Truncate {
        len: usize,
    },
    Extend {
        tail: Vec<u8>,
    },
    Insert {
        at: usize,
        bytes: Vec<u8>,
    },
    Delete {
        at: usize,
        len: usize,
    },
    /// The byte at `at` repeated `count` more times.
    RepeatByte {
        at: usize,
        count: usize,
    },
    /// The `len` bytes at `at` inserted again right after themselves.
    Duplicate {
        at: usize,
        len: usize,
    },
}

impl Mutation {
    /// The damaged copy of `original`.
    pub fn apply(&self, original: &[u8]) -> Vec<u8> {
        let mut b = original.to_vec();
        let n = b.len();
        match self {
            Mutation::FlipBit { at, bit } if *at < n => b[*at] ^= 1 << (bit % 8),
            Mutation::SetByte { at, value } if *at < n => b[*at] = *value,
            Mutation::SetWord { at, width, value } if at + width <= n => {
                b[*at..at + width].copy_from_slice(&value.to_le_bytes()[..*width]);
            }
            Mutation::SetNumber { at, len, text } if at + len <= n => {
                b.splice(*at..at + len, text.bytes());
            }
            Mutation::Truncate { len } => b.truncate(*len),
            Mutation::Extend { tail } => b.extend_from_slice(tail),
            Mutation::Insert { at, bytes } if *at <= n => {
                b.splice(*at..*at, bytes.iter().copied());
            }
            Mutation::Delete { at, len } if at + len <= n => {
                b.drain(*at..at + len);
            }
            Mutation::RepeatByte { at, count } if *at < n => {
                let v = b[*at];
                b.splice(*at..*at, std::iter::repeat_n(v, *count));
            }
            Mutation::Duplicate { at, len } if at + len <= n => {
                let chunk = b[*at..at + len].to_vec();
                b.splice(at + len..at + len, chunk);
            }
            _ => {}
        }
        b
    }
}

/// Recomputes a format's checksum in a damaged copy.
pub(crate) type Fixup = dyn Fn(&mut [u8]);

/// How to fuzz one file.
pub struct Plan<'a> {
    /// Damaged copies to try.
    pub mutations: usize,
    pub seed: u64,
    /// `(offset, width)` of the format's little-endian length/count/offset fields
    /// (width 4 or 8): the hostile-word mutations aim at them half of the time.
    pub length_fields: Vec<(usize, usize)>,
    /// Recomputes a checksum after the damage; applied to every other copy.
    pub fixup: Option<&'a Fixup>,
    /// A reader may allocate at most `alloc_per_byte × file size + alloc_slack` bytes.
    pub alloc_per_byte: usize,
    pub alloc_slack: usize,
}

impl Plan<'_> {
    /// 2000 mutations; 16 bytes per file byte + 16 MiB of allocation allowed.
    pub fn new(seed: u64) -> Self {
        Plan {
            mutations: 2000,
            seed,
            length_fields: Vec::new(),
            fixup: None,
            alloc_per_byte: 16,
            alloc_slack: 16 << 20,
        }
    }

    fn alloc_bound(&self, file_len: usize) -> usize {
        self.alloc_per_byte
            .saturating_mul(file_len)
            .saturating_add(self.alloc_slack)
    }
}

/// What went wrong with one damaged copy.
#[derive(Clone, Debug, PartialEq)]
pub enum Problem {
    /// The reader panicked (message).
    Panic(String),
    /// The error does not name the file (the error's text).
    Unnamed(String),
    /// The reader allocated `peak` bytes, more than `bound`.
    Alloc { peak: usize, bound: usize },
}

/// A damaged copy the reader mishandled: `mutation.apply(original)` (then the fixup,
/// when `fixed_up`) reproduces it.
#[derive(Clone, Debug, PartialEq)]
pub struct Failure {
    pub mutation: Mutation,
    pub fixed_up: bool,
    pub problem: Problem,
}

/// The outcome of [`fuzz`].
#[derive(Clone, Debug, Default)]
pub struct Report {
    /// File name, for messages.
    pub file: String,
    pub file_bytes: usize,
    pub mutations: usize,
    /// Copies the reader refused with an error naming the file.
    pub rejected: usize,
    /// Copies the reader accepted (the damage left a valid file).
    pub accepted: usize,
    /// Largest allocation peak over all copies, bytes.
    pub max_alloc: usize,
    /// Wall time of the whole run (for the record, never asserted).
    pub seconds: f64,
    pub failures: Vec<Failure>,
}

impl Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(
            f,
            "{} ({} bytes): {} mutations, {} rejected, {} accepted, peak allocation {} KiB, \
             {:.1} s, {} failures",
            self.file,
            self.file_bytes,
            self.mutations,
            self.rejected,
            self.accepted,
            self.max_alloc / 1024,
            self.seconds,
            self.failures.len()
        )
    }
}

impl Report {
    /// Panic listing the first failures (each with the mutation that reproduces it)
    /// unless every copy was handled; also checks that most copies were refused.
    pub fn assert_clean(&self) {
        if !self.failures.is_empty() {
            let list: Vec<String> = self
                .failures
                .iter()
                .take(8)
                .map(|f| {
                    let mut m = format!("{:?}", f.mutation);
                    if m.len() > 160 {
                        let cut = (0..=160)
                            .rev()
                            .find(|&i| m.is_char_boundary(i))
                            .unwrap_or(0);
                        m = format!("{}… ({} characters)", &m[..cut], m.len());
                    }
                    format!("  {m} (fixed up: {}): {:?}", f.fixed_up, f.problem)
                })
                .collect();
            panic!("{self}\n{}", list.join("\n"));
        }
        assert_eq!(self.rejected + self.accepted, self.mutations, "{self}");
        println!("{self}");
    }
}

/// SplitMix64: small, seeded, good enough to pick mutations.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `0..n` (`n > 0`).
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
    fn pick<T: Clone>(&mut self, items: &[T]) -> T {
        items[self.below(items.len())].clone()
    }
    fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.next() as u8).collect()
    }
}

/// Values that break readers which trust a length, count or offset.
const HOSTILE_WORDS: [u64; 10] = [
    0,
    1,
    0x7FFF_FFFF,
    0x8000_0000,
    0xFFFF_FFFF,
    0xFFFF_FFFF_FFFF_FFFF,
    0x7FFF_FFFF_FFFF_FFFF,
    1 << 40,
    1 << 32,
    0x0100_0000,
];

/// Decimal replacements for numbers in text formats.
const HOSTILE_NUMBERS: [&str; 12] = [
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "99999999999999999999999",
    "2147483648",
    "1000000000",
    "-1",
    "0",
    "1e309",
    "NaN",
    "-0",
    "65536",
];

/// Byte strings appended to a file.
fn hostile_tail(rng: &mut Rng, original: &[u8]) -> Vec<u8> {
    match rng.below(5) {
        0 => {
            let n = 1 + rng.below(64);
            rng.bytes(n)
        }
        1 => vec![0xFF; 1 + rng.below(4096)],
        2 => original[..original.len().min(128)].to_vec(),
        3 => b"]]]}}}\n[[x]]\n\"\x00".to_vec(),
        _ => b" 99999999999999999999 -1 1e309 nan\n".to_vec(),
    }
}

/// Start and length of every run of ASCII digits.
fn digit_runs(b: &[u8]) -> Vec<(usize, usize)> {
    let mut runs = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i].is_ascii_digit() {
            let s = i;
            while i < b.len() && b[i].is_ascii_digit() {
                i += 1;
            }
            runs.push((s, i - s));
        } else {
            i += 1;
        }
    }
    runs
}

/// Draw one mutation of a file of these bytes.
fn draw(rng: &mut Rng, original: &[u8], plan: &Plan, digits: &[(usize, usize)]) -> Mutation {
    let n = original.len().max(1);
    let at = rng.below(n);
    match rng.below(100) {
        0..25 => Mutation::FlipBit {
            at,
            bit: rng.below(8) as u8,
        },
        25..38 => {
            let random = rng.next() as u8;
            Mutation::SetByte {
                at,
                value: rng.pick(&[0x00, 0xFF, 0x7F, 0x80, random]),
            }
        }
        38..53 => {
            let (at, width) = if !plan.length_fields.is_empty() && rng.below(2) == 0 {
                rng.pick(&plan.length_fields)
            } else {
                let width = rng.pick(&[4usize, 8]);
                (at / width * width, width)
            };
            Mutation::SetWord {
                at,
                width,
                value: rng.pick(&HOSTILE_WORDS),
            }
        }
        53..63 if !digits.is_empty() => {
            let (at, len) = rng.pick(digits);
            Mutation::SetNumber {
                at,
                len,
                text: rng.pick(&HOSTILE_NUMBERS).to_string(),
            }
        }
        53..73 => Mutation::Truncate { len: at },
        73..81 => Mutation::Extend {
            tail: hostile_tail(rng, original),
        },
        81..86 => {
            let len = 1 + rng.below(8);
            Mutation::Insert {
                at,
                bytes: rng.bytes(len),
            }
        }
        86..91 => Mutation::Delete {
            at,
            len: 1 + rng.below((n - at).min(64)),
        },
        91..96 => Mutation::RepeatByte {
            at,
            count: rng.pick(&[1usize, 7, 100, 5000]),
        },
        _ => Mutation::Duplicate {
            at,
            len: 1 + rng.below((n - at).min(256)),
        },
    }
}

/// Fuzz a reader with [`Plan::new`]`(seed)`: `file` is where the damaged copies are
/// written (the reader may read the directory around it), `original` the valid bytes
/// (written back at the end), `read` the reader under test.
pub fn fuzz_reader<T, E: Display>(
    file: &Path,
    original: &[u8],
    seed: u64,
    read: impl Fn(&Path) -> Result<T, E>,
) -> Report {
    fuzz(file, original, &Plan::new(seed), read)
}

/// Fuzz a reader (see the module documentation). Panics when the reader refuses the
/// valid `original` (the test would prove nothing) or when the binary lacks the
/// [`alloc::TrackingAlloc`] global allocator.
pub fn fuzz<T, E: Display>(
    file: &Path,
    original: &[u8],
    plan: &Plan,
    read: impl Fn(&Path) -> Result<T, E>,
) -> Report {
    // Harness runs and measurements are serialised: the counters are process-wide.
    let _guard = alloc::exclusive();
    assert!(
        alloc::installed(),
        "declare `#[global_allocator] static A: testkit::TrackingAlloc = \
         testkit::TrackingAlloc;` in this test binary"
    );
    // A new file each time: on ext4, truncating and rewriting a file forces its data to
    // disk on close (auto_da_alloc), 40x slower than unlinking it first.
    let write = |bytes: &[u8]| {
        let _ = std::fs::remove_file(file);
        std::fs::write(file, bytes).unwrap_or_else(|e| panic!("{}: {e}", file.display()))
    };
    write(original);
    if let Err(e) = read(file) {
        panic!(
            "the reader refuses the valid original {}: {e:#}",
            file.display()
        );
    }
    let name = file.display().to_string();
    let mut report = Report {
        file: file
            .file_name()
            .map_or(name.clone(), |n| n.to_string_lossy().into_owned()),
        file_bytes: original.len(),
        mutations: plan.mutations,
        ..Report::default()
    };
    let digits = digit_runs(original);
    let mut rng = Rng(plan.seed ^ 0x6D75_7461_7465);
    let clock = std::time::Instant::now();
    quiet_panics(true);
    for k in 0..plan.mutations {
        let mutation = draw(&mut rng, original, plan, &digits);
        let mut bytes = mutation.apply(original);
        let fixed_up = match plan.fixup {
            Some(fix) if k % 2 == 1 => {
                fix(&mut bytes);
                true
            }
            _ => false,
        };
        write(&bytes);
        let bound = plan.alloc_bound(bytes.len().max(original.len()));
        let (outcome, peak) = alloc::peak_while_exclusive(|| {
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                read(file).map(drop).map_err(|e| format!("{e:#}"))
            }))
        });
        report.max_alloc = report.max_alloc.max(peak);
        let problem = match outcome {
            Err(payload) => Some(Problem::Panic(panic_text(payload.as_ref()))),
            Ok(Err(msg)) if !msg.contains(&name) => Some(Problem::Unnamed(msg)),
            _ if peak > bound => Some(Problem::Alloc { peak, bound }),
            Ok(Err(_)) => {
                report.rejected += 1;
                None
            }
            Ok(Ok(())) => {
                report.accepted += 1;
                None
            }
        };
        if let Some(problem) = problem {
            report.failures.push(Failure {
                mutation,
                fixed_up,
                problem,
            });
        }
    }
    quiet_panics(false);
    write(original);
    report.seconds = clock.elapsed().as_secs_f64();
    report
}

thread_local! {
    static QUIET: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Silence the panic messages of this thread (the harness expects and reports them);
/// other threads' panics are printed as usual.
fn quiet_panics(on: bool) {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(|q| q.get()) {
                previous(info);
            }
        }));
    });
    QUIET.with(|q| q.set(on));
}

fn panic_text(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<String>()
        .cloned()
        .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_else(|| "(non-text panic payload)".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutations_apply_as_described() {
        let b = b"ab12cd".to_vec();
        assert_eq!(Mutation::FlipBit { at: 0, bit: 1 }.apply(&b), b"cb12cd");
        assert_eq!(Mutation::Truncate { len: 2 }.apply(&b), b"ab");
        assert_eq!(
            Mutation::SetNumber {
                at: 2,
                len: 2,
                text: "-1".into()
            }
            .apply(&b),
            b"ab-1cd"
        );
        assert_eq!(
            Mutation::SetWord {
                at: 0,
                width: 4,
                value: 0x3132_3334
            }
            .apply(&b),
            b"4321cd"
        );
        assert_eq!(
            Mutation::RepeatByte { at: 1, count: 2 }.apply(&b),
            b"abbb12cd"
        );
        assert_eq!(Mutation::Duplicate { at: 0, len: 2 }.apply(&b), b"abab12cd");
        assert_eq!(Mutation::Delete { at: 1, len: 3 }.apply(&b), b"acd");
        // Out of range: the copy is unchanged.
        assert_eq!(Mutation::SetByte { at: 9, value: 0 }.apply(&b), b);
        assert_eq!(digit_runs(&b), vec![(2, 2)]);
    }

    #[test]
    fn draws_are_seeded_and_cover_every_kind() {
        let original: Vec<u8> = (0..200u8).chain(*b"x 123 y 45").collect();
        let plan = Plan::new(3);
        let digits = digit_runs(&original);
        let run = |seed| {
            let mut rng = Rng(seed);
            (0..500)
                .map(|_| draw(&mut rng, &original, &plan, &digits))
                .collect::<Vec<_>>()
        };
        let a = run(1);
        assert_eq!(a, run(1));
        assert_ne!(a, run(2));
        let kind = |m: &Mutation| {
            format!("{m:?}")
                .split([' ', '{'])
                .next()
                .unwrap()
                .to_string()
        };
        let mut kinds: Vec<String> = a.iter().map(kind).collect();
        kinds.sort();
        kinds.dedup();
        assert_eq!(kinds.len(), 10, "{kinds:?}");
    }
}
