//! Seeds from the environment: the tests use fixed seeds and must pass for
//! any other (VALIDATION.md §1).

/// `$var` as a whole number, or `default` where it is unset. Any other value
/// is an error: falling back to the committed seed would let a sweep over
/// seeds test one seed only.
pub fn from_env(var: &str, default: u64) -> u64 {
    std::env::var(var).map_or(default, |v| v.parse().unwrap_or_else(|_| panic!("{var}={v}: not a whole number")))
}
