//! The task runner: the state a task carries (repository root, thumb toolchain, extra PATH),
//! numbered steps with their wall times, and the summary at the end.

use std::env;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::toolchain::Toolchain;

pub(crate) type Result<T = ()> = std::result::Result<T, String>;

/// A step of a task.
pub(crate) type StepFn = fn(&mut Xtask) -> Result;

pub(crate) struct Xtask {
    pub(crate) root: PathBuf,
    pub(crate) toolchain: Option<Toolchain>,
    /// Prepended to PATH for children (where `cargo install` put defmt-print).
    pub(crate) extra_path: Option<PathBuf>,
    pub(crate) passed: Vec<(String, Duration)>,
}

impl Xtask {
    pub(crate) fn new() -> Self {
        let manifest_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
        let root = manifest_dir.parent().unwrap_or(manifest_dir).to_path_buf();
        Xtask { root, toolchain: None, extra_path: None, passed: Vec::new() }
    }

    /// Runs one step with a header and its wall time; false if it failed.
    pub(crate) fn step(&mut self, n: usize, name: &str, f: StepFn) -> bool {
        println!("\n==> [{n}] {name}");
        let t = Instant::now();
        let r = f(self);
        let dt = t.elapsed();
        match r {
            Ok(()) => {
                println!("<== [{n}] {name}: ok ({:.1} s)", dt.as_secs_f64());
                self.passed.push((name.to_string(), dt));
                true
            }
            Err(e) => {
                eprintln!("<== [{n}] {name}: FAILED after {:.1} s\nerror: step '{name}' failed: {e}", dt.as_secs_f64());
                false
            }
        }
    }

    pub(crate) fn summary(&self, started: Instant) {
        println!("\nstep times:");
        for (name, dt) in &self.passed {
            println!("  {:>7.1} s  {name}", dt.as_secs_f64());
        }
        println!("  {:>7.1} s  total", started.elapsed().as_secs_f64());
    }
}
