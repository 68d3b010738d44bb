//! Host tests of the core; see `tests/`.
