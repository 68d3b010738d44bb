//! Output safety (`docs/output-safety.md`): writing outputs so that nothing is ever
//! half-written, nothing is left behind and no input is ever written over.
#![allow(unsafe_code, reason = "libc: `kill(pid, 0)` to find dead runs, the signals' dispositions")]
//!
//! - The data goes to a temporary file `.NAME.tmp-PID` in the destination's directory, is
//!   flushed to disk, and is renamed over the destination ([`write_atomic`], [`AtomicFile`]).
//! - The temporary files alive in the process are registered; after
//!   [`remove_temporaries_on_signals`], SIGINT, SIGTERM and SIGHUP remove them before the
//!   process ends by that signal. A process killed outright (SIGKILL, power loss) cannot do
//!   that: the next write of the same output removes the `.NAME.tmp-PID` files whose process
//!   is gone.
//! - [`refuse_overwriting_inputs`]: a command refuses to start when one of its outputs is one
//!   of its inputs, by name or through a link.
//! - [`restore_sigpipe`]: writing into a closed pipe ends the process quietly, as it does any
//!   Unix filter, instead of a panic of `println!`.

use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

/// The temporary files this process has created and not yet renamed or removed.
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn live() -> MutexGuard<'static, Vec<PathBuf>> {
    // A panic while the list was held leaves it consistent (pushes and removals only).
    LIVE.lock().unwrap_or_else(|e| e.into_inner())
}

/// The directory and file name of an output.
fn split(path: &Path) -> anyhow::Result<(PathBuf, String)> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path.file_name().with_context(|| format!("{}: not a file name", path.display()))?;
    Ok((dir, name.to_string_lossy().into_owned()))
}

/// The temporary sibling of `path` for this process, after removing the temporary siblings
/// of `path` left by processes that no longer exist.
fn temp_path(path: &Path) -> anyhow::Result<PathBuf> {
    let (dir, name) = split(path)?;
    remove_stale(&dir, &name);
    Ok(dir.join(format!(".{name}.tmp-{}", std::process::id())))
}

/// Removes `dir/.NAME.tmp-PID` for every PID (not this process's) that is not a running
/// process. Errors are ignored: a file that cannot be listed or removed is left as it was.
fn remove_stale(dir: &Path, name: &str) {
    let prefix = format!(".{name}.tmp-");
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let file = entry.file_name();
        let Some(pid) = file.to_str().and_then(|f| f.strip_prefix(&prefix)) else { continue };
        if !pid.bytes().all(|b| b.is_ascii_digit()) {
            continue;
        }
        let Ok(pid) = pid.parse::<u32>() else { continue };
        if pid != std::process::id() && !process_exists(pid) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// True when a process `pid` exists (or may: when it cannot be told, true).
#[cfg(unix)]
fn process_exists(pid: u32) -> bool {
    // PID 0 and negative values address process groups, not a process.
    let Ok(pid) = libc::pid_t::try_from(pid) else { return true };
    if pid <= 0 {
        return true;
    }
    // SAFETY: signal 0 performs only the existence and permission checks; nothing is sent.
    let r = unsafe { libc::kill(pid, 0) };
    r == 0 || std::io::Error::last_os_error().raw_os_error() != Some(libc::ESRCH)
}

#[cfg(not(unix))]
fn process_exists(_pid: u32) -> bool {
    true
}

/// Creates the temporary file `tmp` and registers it, under the registry's lock (a signal
/// handled meanwhile waits and then removes it).
fn create_registered(tmp: &Path) -> std::io::Result<std::fs::File> {
    let mut live = live();
    let f = std::fs::File::create(tmp)?;
    live.push(tmp.to_path_buf());
    Ok(f)
}

/// Renames (`Some(dest)`) or removes (`None`) the registered temporary file `tmp`, and
/// unregisters it, under the registry's lock.
fn finish_registered(tmp: &Path, dest: Option<&Path>) -> std::io::Result<()> {
    let mut live = live();
    let r = match dest {
        Some(d) => std::fs::rename(tmp, d),
        None => std::fs::remove_file(tmp),
    };
    if let Some(i) = live.iter().position(|p| p == tmp) {
        live.swap_remove(i);
    }
    r
}

/// Writes `data` to `path` atomically (temporary sibling file, fsync, rename). Errors name
/// the file.
pub fn write_atomic(path: &Path, data: &[u8]) -> anyhow::Result<()> {
    let tmp = temp_path(path)?;
    let result = (|| -> std::io::Result<()> {
        let mut f = create_registered(&tmp)?;
        f.write_all(data)?;
        f.sync_all()?;
        finish_registered(&tmp, Some(path))
    })();
    if let Err(e) = result {
        let _ = finish_registered(&tmp, None);
        return Err(anyhow::anyhow!("{}: {e}", path.display()));
    }
    Ok(())
}

/// A file written in a stream and put in place only on success: the data goes to a temporary
/// sibling file, [`commit`](AtomicFile::commit) flushes, fsyncs and renames it over the
/// destination. Dropped without a commit (an error on the way), the temporary file is
/// removed, so the destination is never half-written.
pub struct AtomicFile {
    path: PathBuf,
    tmp: PathBuf,
    out: Option<std::io::BufWriter<std::fs::File>>,
}

impl AtomicFile {
    /// Creates the temporary file beside `path`. Errors name the file.
    pub fn create(path: &Path) -> anyhow::Result<Self> {
        let tmp = temp_path(path)?;
        let f = create_registered(&tmp).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        Ok(AtomicFile { path: path.to_path_buf(), tmp, out: Some(std::io::BufWriter::with_capacity(1 << 20, f)) })
    }

    /// The stream to write to.
    pub fn writer(&mut self) -> &mut std::io::BufWriter<std::fs::File> {
        self.out.as_mut().unwrap_or_else(|| unreachable!("taken only by commit"))
    }

    /// Flushes, syncs and renames the temporary file over the destination.
    pub fn commit(mut self) -> anyhow::Result<()> {
        let out = self.out.take().unwrap_or_else(|| unreachable!("taken only here"));
        let result = (|| -> std::io::Result<()> {
            let f = out.into_inner().map_err(|e| e.into_error())?;
            f.sync_all()?;
            finish_registered(&self.tmp, Some(&self.path))
        })();
        if result.is_err() {
            let _ = finish_registered(&self.tmp, None);
        }
        result.map_err(|e| anyhow::anyhow!("{}: {e}", self.path.display()))
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.out.is_some() {
            self.out = None;
            let _ = finish_registered(&self.tmp, None);
        }
    }
}

/// Removes the registered temporary files when the process receives SIGINT, SIGTERM or SIGHUP,
/// then ends it by that signal (its parent sees the usual status, 130 for SIGINT, 143 for
/// SIGTERM). The signals are taken by `signal-hook` (its handler only writes to a pipe) and
/// read by a thread of their own, which holds the list of temporary files from then on, so no
/// temporary file is created or renamed after the signal is handled. Call it first in `main`:
/// the signals are registered when it returns. A signal the process was started with ignored
/// (`nohup`) stays ignored.
#[cfg(unix)]
pub fn remove_temporaries_on_signals() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let taken: Vec<libc::c_int> = [SIGINT, SIGTERM, SIGHUP].into_iter().filter(|&s| !ignored(s)).collect();
    if taken.is_empty() {
        return;
    }
    // The thread registers the signals and says so before it waits: without a thread nothing
    // is registered, and the signals keep their default action.
    let (registered, wait) = std::sync::mpsc::sync_channel(1);
    let spawned = std::thread::Builder::new().name("signals".into()).spawn(move || {
        let signals = signal_hook::iterator::Signals::new(&taken);
        let _ = registered.send(());
        let Ok(mut signals) = signals else { return };
        let Some(sig) = signals.forever().next() else { return };
        // Held to the end: no temporary file is created or renamed from here on.
        let live = live();
        for p in live.iter() {
            let _ = std::fs::remove_file(p);
        }
        // The default action of `sig`: the process ends by it as if it had not been handled.
        let _ = signal_hook::low_level::emulate_default_handler(sig);
        std::process::exit(128 + sig);
    });
    if spawned.is_ok() {
        let _ = wait.recv();
    }
}

/// True when signal `sig` is ignored (`SIG_IGN`, as `nohup` leaves SIGHUP).
#[cfg(unix)]
fn ignored(sig: libc::c_int) -> bool {
    // SAFETY: `sigaction` with a null new action only reads the current disposition into
    // `old`, a plain-data struct it fully writes on success.
    unsafe {
        let mut old: libc::sigaction = std::mem::zeroed();
        libc::sigaction(sig, std::ptr::null(), &mut old) == 0 && old.sa_sigaction == libc::SIG_IGN
    }
}

/// Without Unix signals there is nothing to install.
#[cfg(not(unix))]
pub fn remove_temporaries_on_signals() {}

/// Restores the default action of SIGPIPE (Rust ignores it, so that a write into a closed
/// pipe fails and `println!` panics): the process then ends quietly when its reader goes
/// away, as `bins-cal verify … | head -1` expects. Call it first in `main`.
#[cfg(unix)]
pub fn restore_sigpipe() {
    // SAFETY: changes the disposition of one signal before any other thread runs.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// Without Unix signals there is nothing to restore.
#[cfg(not(unix))]
pub fn restore_sigpipe() {}

/// The identity of a path for comparing an output with the inputs: the file it resolves to
/// (device and inode, when it exists) and its canonical path (the canonical directory and the
/// name, when only the directory exists).
struct Identity {
    #[cfg(unix)]
    file: Option<(u64, u64)>,
    path: Option<PathBuf>,
}

impl Identity {
    fn of(p: &Path) -> Identity {
        #[cfg(unix)]
        let file = {
            use std::os::unix::fs::MetadataExt;
            std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()))
        };
        let path = std::fs::canonicalize(p).ok().or_else(|| {
            let (dir, name) = split(p).ok()?;
            Some(std::fs::canonicalize(dir).ok()?.join(name))
        });
        Identity {
            #[cfg(unix)]
            file,
            path,
        }
    }

    fn same(&self, other: &Identity) -> bool {
        #[cfg(unix)]
        if let (Some(a), Some(b)) = (self.file, other.file)
            && a == b
        {
            return true;
        }
        matches!((&self.path, &other.path), (Some(a), Some(b)) if a == b)
    }
}

/// Refuses (an error naming both) an output that is one of the inputs — the same name, or
/// the same file through a symbolic or hard link, or a symbolic link to it — and two outputs
/// that are the same file. Call it first in a command's `run`, before anything is read or
/// written.
pub fn refuse_overwriting_inputs<I, O>(inputs: I, outputs: O) -> anyhow::Result<()>
where
    I: IntoIterator,
    I::Item: AsRef<Path>,
    O: IntoIterator,
    O::Item: AsRef<Path>,
{
    let inputs: Vec<(PathBuf, Identity)> =
        inputs.into_iter().map(|p| (p.as_ref().to_path_buf(), Identity::of(p.as_ref()))).collect();
    let mut seen: Vec<(PathBuf, Identity)> = Vec::new();
    for o in outputs {
        let o = o.as_ref();
        let id = Identity::of(o);
        let same_name = |p: &Path| if p == o { String::new() } else { " (the same file)".to_string() };
        if let Some((i, _)) = inputs.iter().find(|(i, iid)| i == o || id.same(iid)) {
            anyhow::bail!(
                "{}: refusing to write the output over the input {}{}",
                o.display(),
                i.display(),
                same_name(i)
            );
        }
        if let Some((p, _)) = seen.iter().find(|(p, pid)| p == o || id.same(pid)) {
            let also = if p == o { String::new() } else { format!(" (also as {})", p.display()) };
            anyhow::bail!("{}: given for two outputs{also}; give each output its own file", o.display());
        }
        seen.push((o.to_path_buf(), id));
    }
    Ok(())
}
