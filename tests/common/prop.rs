//! The property tests' configuration: the same cases on every run.
//!
//! proptest draws fresh random cases on each run by default, so a CI run
//! could fail on a case no earlier run drew (it happened once, stop 57:
//! a far grazing ray past a thin ellipsoid, now a regression test). Here
//! the cases come from a fixed seed, so every run, CI's included, tests
//! the same cases and a failure reproduces. To search new cases, set
//! `PROPTEST_RNG_SEED` to any integer (for example
//! `PROPTEST_RNG_SEED=$RANDOM cargo test --release properties`); a case
//! that fails prints its minimal input, which then belongs in a fixed
//! regression test.

use proptest::test_runner::{Config, RngSeed};

/// Seed of the cases when `PROPTEST_RNG_SEED` is not set.
pub const SEED: u64 = 0x005e_ed0f_a11c_a5e5;

/// `cases` cases from [`SEED`] (or `PROPTEST_RNG_SEED`), with no failure
/// files written.
pub fn config(cases: u32) -> Config {
    let base = Config::default();
    let rng_seed = if std::env::var_os("PROPTEST_RNG_SEED").is_some() {
        base.rng_seed
    } else {
        RngSeed::Fixed(SEED)
    };
    Config {
        cases,
        failure_persistence: None,
        rng_seed,
        ..base
    }
}
