//! Stable-Rust stand-in for the cargo-fuzz targets in fuzz/: deterministic random mutations of
//! the committed corpus seeds (fuzz/corpus/<target>/) fed to the .vdb, .vol and .npy readers.
//! Every input must give an error or a result — a panic fails the test and prints a
//! reproducer; an unbounded allocation would abort it. Bounded iterations (a few seconds in
//! release on 2 cores), fixed seed, so CI runs it every time.

use crate::medium::loaders::{parse_npy, parse_vol};
use crate::medium::vdb::{read_vdb_dense_bytes, read_vdb_info_bytes};
use std::path::PathBuf;

struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        // xorshift64*
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Values that tend to break size and offset handling.
const INTERESTING: [i64; 10] = [0, 1, -1, 7, 255, 4096, i32::MAX as i64, i32::MIN as i64, 1 << 40, i64::MAX];

/// One random structural mutation, like libFuzzer's default mutators.
fn mutate(rng: &mut Rng, b: &mut Vec<u8>) {
    if b.is_empty() {
        b.push(rng.next() as u8);
        return;
    }
    let i = rng.below(b.len());
    match rng.below(7) {
        0 => b[i] ^= 1 << rng.below(8),
        1 => b[i] = rng.next() as u8,
        2 => {
            // Overwrite 4 or 8 bytes with an interesting integer.
            let v = INTERESTING[rng.below(INTERESTING.len())];
            let w = if rng.below(2) == 0 { 4 } else { 8 };
            let bytes = v.to_le_bytes();
            let n = w.min(b.len() - i);
            b[i..i + n].copy_from_slice(&bytes[..n]);
        }
        3 => b.truncate(i),
        4 => {
            // Delete a run.
            let n = rng.below(64).min(b.len() - i);
            b.drain(i..i + n);
        }
        5 => {
            // Duplicate a run elsewhere.
            let n = rng.below(64).min(b.len() - i);
            let run: Vec<u8> = b[i..i + n].to_vec();
            let at = rng.below(b.len());
            b.splice(at..at, run);
        }
        _ => {
            let n = rng.below(16);
            for _ in 0..n {
                let j = rng.below(b.len());
                b[j] = rng.next() as u8;
            }
        }
    }
}

fn seeds(target: &str) -> Vec<(String, Vec<u8>)> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut out = Vec::new();
    for dir in [
        root.join("fuzz/corpus").join(target),
        root.join("tests/data/fuzz_regressions").join(target),
    ] {
        let Ok(rd) = std::fs::read_dir(&dir) else { continue };
        let mut files: Vec<_> = rd.map(|e| e.unwrap().path()).collect();
        files.sort();
        for f in files {
            out.push((f.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(&f).unwrap()));
        }
    }
    assert!(!out.is_empty(), "no seeds for {target}");
    out
}

fn run(target: &str, iterations: usize, parse: impl Fn(&[u8]) + std::panic::RefUnwindSafe) {
    let seeds = seeds(target);
    // Seeds themselves (and their regressions) first.
    for (_, s) in &seeds {
        parse(s);
    }
    // CLOUDGI_FUZZ_SCALE=N runs N times as many mutations (longer local runs, new seed stream).
    let scale: usize = std::env::var("CLOUDGI_FUZZ_SCALE").ok().and_then(|s| s.parse().ok()).unwrap_or(1);
    let mut rng = Rng(0x5eed_0000_0000_0001 ^ target.len() as u64 ^ (scale as u64) << 32);
    for it in 0..iterations * scale {
        let (name, seed) = &seeds[it % seeds.len()];
        let mut b = seed.clone();
        for _ in 0..1 + rng.below(4) {
            mutate(&mut rng, &mut b);
        }
        if std::panic::catch_unwind(|| parse(&b)).is_err() {
            let path = std::env::temp_dir().join(format!("cloudgi-fuzz-{target}-{it}.bin"));
            std::fs::write(&path, &b).unwrap();
            panic!("{target}: mutation {it} of seed {name} panicked; input saved to {}", path.display());
        }
    }
}

#[test]
fn vdb_reader_survives_mutations() {
    run("vdb", 3000, |b| {
        let _ = read_vdb_info_bytes(b, "fuzz.vdb");
        let _ = read_vdb_dense_bytes(b, "fuzz.vdb", None, 1 << 20, 1);
        let _ = read_vdb_dense_bytes(b, "fuzz.vdb", None, 1 << 20, 4);
    });
}

#[test]
fn vol_reader_survives_mutations() {
    run("vol", 20_000, |b| {
        let _ = parse_vol(b, "fuzz.vol");
    });
}

#[test]
fn npy_reader_survives_mutations() {
    run("npy", 20_000, |b| {
        let _ = parse_npy(b, "fuzz.npy");
    });
}
