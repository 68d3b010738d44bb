//! What one child process used: its CPU time (user + system) and its peak resident set, from
//! `wait4` (the child's own `rusage`, not the sum over every child the task ran).
#![allow(unsafe_code, reason = "libc: `wait4` for one child's resource usage")]

use std::process::Command;

use crate::process::show;
use crate::task::Result;

/// A finished child's resource usage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Usage {
    /// User + system CPU time \[s\].
    pub(crate) cpu_s: f64,
    /// Peak resident set \[MB\] (10⁶ bytes).
    pub(crate) peak_rss_mb: f64,
    /// Wall time \[s\].
    pub(crate) wall_s: f64,
}

/// Runs `c` (its output inherited) to its end and returns what it used; an error names the
/// command when it cannot start, is killed or exits with a failure.
pub(crate) fn measured(mut c: Command) -> Result<Usage> {
    println!("$ {}", show(&c));
    let started = std::time::Instant::now();
    let child = c.spawn().map_err(|e| format!("{}: {e}", show(&c)))?;
    let pid = libc::pid_t::try_from(child.id()).map_err(|e| format!("{}: pid: {e}", show(&c)))?;
    let mut status: libc::c_int = 0;
    // SAFETY: `rusage` is plain data (integers and timevals), for which all zeros is valid.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    let waited = loop {
        // SAFETY: `pid` is our own child, not yet waited for (`child` is never waited on: it
        // is dropped after this call); `status` and `ru` are valid for writes.
        let r = unsafe { libc::wait4(pid, &mut status, 0, &mut ru) };
        if r == -1 && std::io::Error::last_os_error().kind() == std::io::ErrorKind::Interrupted {
            continue;
        }
        break r;
    };
    let wall_s = started.elapsed().as_secs_f64();
    drop(child);
    if waited != pid {
        return Err(format!("{}: wait4: {}", show(&c), std::io::Error::last_os_error()));
    }
    if !libc::WIFEXITED(status) || libc::WEXITSTATUS(status) != 0 {
        return Err(format!("{}: failed (wait status {status})", show(&c)));
    }
    let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    // ru_maxrss is in KiB on Linux.
    Ok(Usage { cpu_s: secs(ru.ru_utime) + secs(ru.ru_stime), peak_rss_mb: ru.ru_maxrss as f64 * 1024.0 / 1e6, wall_s })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A child that allocates and touches 64 MB and spins for a while: its own peak resident
    /// set is at least that, its CPU time more than zero; a failing child is an error.
    #[test]
    fn one_child_usage_is_measured() {
        let mut c = Command::new("python3");
        c.args([
            "-c",
            "b = bytearray(64 * 1000 * 1000)\nfor i in range(0, len(b), 4096): b[i] = 1\nx = sum(range(3000000))",
        ]);
        if Command::new("python3").arg("-V").output().is_err() {
            return;
        }
        let u = measured(c).unwrap();
        assert!(u.peak_rss_mb >= 64.0 && u.peak_rss_mb < 200.0, "{u:?}");
        assert!(u.cpu_s > 0.0 && u.cpu_s <= u.wall_s + 0.05, "{u:?}");
        let mut bad = Command::new("sh");
        bad.args(["-c", "exit 3"]);
        assert!(measured(bad).unwrap_err().contains("failed"));
    }
}
