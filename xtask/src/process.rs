//! Child processes: commands run from the repository root and echoed, their output, time
//! limits, process groups, apt and PATH look-ups.

use std::env;
use std::ffi::{OsStr, OsString};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::task::{Result, Xtask};

/// A file's bytes, or an error naming it.
pub(crate) fn read(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))
}

pub(crate) fn cmd<I: IntoIterator<Item = S>, S: AsRef<OsStr>>(program: &str, args: I) -> Command {
    let mut c = Command::new(program);
    c.args(args);
    c
}

/// True if the command starts and succeeds (output discarded).
pub(crate) fn probe(c: &mut Command) -> bool {
    c.stdout(Stdio::null()).stderr(Stdio::null()).status().is_ok_and(|s| s.success())
}

/// The command's stdout, or an error naming it.
pub(crate) fn output(c: &mut Command) -> Result<String> {
    let o = c.stderr(Stdio::inherit()).output().map_err(|e| format!("cannot start `{}`: {e}", show(c)))?;
    if !o.status.success() {
        return Err(format!("`{}` exited with {}", show(c), o.status));
    }
    Ok(String::from_utf8_lossy(&o.stdout).into_owned())
}

pub(crate) fn on_path(program: &str) -> bool {
    env::var_os("PATH").is_some_and(|p| env::split_paths(&p).any(|d| d.join(program).is_file()))
}

pub(crate) fn cargo_home() -> Option<PathBuf> {
    env::var_os("CARGO_HOME").map(PathBuf::from).or_else(|| env::var_os("HOME").map(|h| Path::new(&h).join(".cargo")))
}

pub(crate) fn dpkg_installed(package: &str) -> bool {
    Command::new("dpkg").args(["-s", package]).stderr(Stdio::null()).output().is_ok_and(|o| {
        o.status.success() && String::from_utf8_lossy(&o.stdout).contains("Status: install ok installed")
    })
}

/// `apt-get update` + `apt-get install`, through sudo unless running as root.
pub(crate) fn apt_install(packages: &[&str]) -> Result {
    if !on_path("apt-get") {
        return Err(format!("missing {} and no apt-get to install them: install them by hand", packages.join(" ")));
    }
    let root = output(Command::new("id").arg("-u")).is_ok_and(|u| u.trim() == "0");
    let apt = |args: &[&str]| -> Result {
        let mut c = if root { Command::new("apt-get") } else { cmd("sudo", ["apt-get"]) };
        c.env("DEBIAN_FRONTEND", "noninteractive").args(args);
        println!("$ {}", show(&c));
        let status = c.status().map_err(|e| format!("cannot start `{}`: {e}", show(&c)))?;
        if status.success() { Ok(()) } else { Err(format!("`{}` exited with {status}", show(&c))) }
    };
    apt(&["update"])?;
    let mut args = vec!["install", "-y", "--no-install-recommends"];
    args.extend_from_slice(packages);
    apt(&args)
}

/// Runs the command in its own process group, killing the group after `limit`.
pub(crate) fn run_with_timeout(mut c: Command, limit: Duration) -> Result {
    use std::os::unix::process::CommandExt;
    println!("$ {}", show(&c));
    c.process_group(0);
    let mut child = c.spawn().map_err(|e| format!("cannot start `{}`: {e}", show(&c)))?;
    let deadline = Instant::now() + limit;
    loop {
        match child.try_wait().map_err(|e| e.to_string())? {
            Some(status) if status.success() => return Ok(()),
            Some(status) => return Err(format!("`{}` exited with {status}", show(&c))),
            None if Instant::now() >= deadline => {
                let group = format!("-{}", child.id());
                let _ = Command::new("kill").args(["-KILL", "--", &group]).status();
                let _ = child.wait();
                return Err(format!("`{}` timed out after {} s (XTASK_QEMU_TIMEOUT)", show(&c), limit.as_secs()));
            }
            None => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}

/// Runs a program that does not exit by itself (the flight image in QEMU) for `duration`, in
/// its own process group, then kills the group; an error if it exited before.
pub(crate) fn run_for(mut c: Command, duration: Duration) -> Result {
    use std::os::unix::process::CommandExt;
    println!("$ {}", show(&c));
    c.process_group(0);
    let mut child = c.spawn().map_err(|e| format!("cannot start `{}`: {e}", show(&c)))?;
    let deadline = Instant::now() + duration;
    while Instant::now() < deadline {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            return Err(format!("`{}` exited with {status} before {} s", show(&c), duration.as_secs_f64()));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let group = format!("-{}", child.id());
    let _ = Command::new("kill").args(["-KILL", "--", &group]).status();
    let _ = child.wait();
    Ok(())
}

/// A shell-like rendering of a command with the variables it sets.
pub(crate) fn show(c: &Command) -> String {
    let mut parts: Vec<String> = c
        .get_envs()
        .filter_map(|(k, v)| v.map(|v| (k, v)))
        .filter(|(k, _)| *k != "PATH")
        .map(|(k, v)| format!("{}={}", k.to_string_lossy(), v.to_string_lossy()))
        .collect();
    parts.push(relative(c.get_program()));
    parts.extend(c.get_args().map(relative));
    parts.join(" ")
}

pub(crate) fn relative(s: &OsStr) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().map(Path::to_path_buf).unwrap_or_default();
    let p = Path::new(s);
    let s: OsString = p.strip_prefix(&root).map(|r| r.as_os_str().to_owned()).unwrap_or_else(|_| s.to_owned());
    s.to_string_lossy().into_owned()
}

impl Xtask {
    /// A command run from the repository root, with the extra PATH entry.
    pub(crate) fn command(&self, program: impl AsRef<OsStr>) -> Command {
        let mut c = Command::new(program);
        c.current_dir(&self.root);
        if let Some(p) = &self.extra_path {
            let mut paths = vec![p.clone()];
            paths.extend(env::split_paths(&env::var_os("PATH").unwrap_or_default()));
            if let Ok(joined) = env::join_paths(paths) {
                c.env("PATH", joined);
            }
        }
        c
    }

    /// Echoes and runs a command; an error names it and its exit status.
    pub(crate) fn run(&self, mut c: Command) -> Result {
        println!("$ {}", show(&c));
        let status = c.status().map_err(|e| format!("cannot start `{}`: {e}", show(&c)))?;
        if status.success() { Ok(()) } else { Err(format!("`{}` exited with {status}", show(&c))) }
    }
}
