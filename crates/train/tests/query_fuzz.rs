//! The service's query string, driven by seeded random strings built from its own keys and values,
//! percent-encodings and random bytes: every one parses to options or to a 400's message, never a
//! panic. A short run is a test; `fuzz/run.sh` runs it for as long as the AFL++ targets
//! (`PMUNET_FUZZ_SECONDS`, with `--ignored`).

use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use train::serve::DetectParams;

const PIECES: &[&str] = &[
    "format", "render", "score_threshold", "=", "&", "pcd", "bin", "npy", "kitti", "1", "0", "true", "false", "0.5", "nan", "inf", "-1",
    "1e309", "%", "%2", "%26", "%3D", "%00", "%ff", "+", "#", "?", "[]", "format[]", "=&=", "\u{e9}", "\u{1F600}", "frmat", ";", " ",
];

fn random_query(rng: &mut impl Rng) -> String {
    let mut q = String::new();
    for _ in 0..rng.random_range(0..12) {
        if rng.random_bool(0.85) {
            q.push_str(PIECES[rng.random_range(0..PIECES.len())]);
        } else {
            q.push(char::from_u32(rng.random_range(0..0x300)).unwrap_or('x'));
        }
    }
    q
}

fn run_for(budget: Duration, seed: u64) -> usize {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let started = Instant::now();
    let mut n = 0;
    while n < 1000 || started.elapsed() < budget {
        let q = random_query(&mut rng);
        match DetectParams::from_query(Some(&q), 0.5) {
            Ok(p) => assert!((0.0..=1.0).contains(&p.score_threshold), "{q:?} gave {p:?}"),
            Err(message) => assert!(!message.is_empty(), "{q:?}"),
        }
        n += 1;
    }
    n
}

#[test]
fn random_query_strings_give_options_or_a_message() {
    assert!(run_for(Duration::ZERO, 1) >= 1000);
    assert_eq!(DetectParams::from_query(Some("format=bin&render=1&score_threshold=0.3"), 0.5), Ok(DetectParams { format: Some("bin".into()), render: true, score_threshold: 0.3 }));
    assert!(DetectParams::from_query(Some("score_threshold=nan"), 0.5).is_err());
    assert!(DetectParams::from_query(Some("frmat=bin"), 0.5).unwrap_err().contains("frmat"));
}

#[test]
#[ignore = "long: fuzz/run.sh runs it"]
fn random_query_strings_for_a_while() {
    let secs: u64 = std::env::var("PMUNET_FUZZ_SECONDS").ok().and_then(|s| s.parse().ok()).unwrap_or(60);
    let started = Instant::now();
    let n = run_for(Duration::from_secs(secs), 2026);
    println!("query strings: {n} in {:.1} s", started.elapsed().as_secs_f64());
}
