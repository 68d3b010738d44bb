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
use std::ffi::{OsStr, OsString};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

/// The temporary files this process has created and not yet renamed or removed.
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The output directories this process has created for a set of outputs not yet committed
/// ([`OutputDir`]): a signal removes them (when empty) with the temporary files.
static DIRS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn dirs() -> MutexGuard<'static, Vec<PathBuf>> {
    DIRS.lock().unwrap_or_else(|e| e.into_inner())
}

/// An output directory (a plot directory) created for outputs that are written all or nothing:
/// [`OutputDir::create`] makes it (and its missing parents) when it does not exist; dropped
/// without [`keep`](OutputDir::keep) — an error, or a signal
/// ([`remove_temporaries_on_signals`]) — the directories it created are removed again when
/// empty, so that a set of outputs leaves no trace when it does not appear.
pub struct OutputDir {
    created: Vec<PathBuf>,
}

impl OutputDir {
    /// Creates `dir` and its missing parents. Errors name the directory.
    pub fn create(dir: &Path) -> anyhow::Result<Self> {
        let mut missing = Vec::new();
        let mut d = Some(dir);
        while let Some(p) = d.filter(|p| !p.as_os_str().is_empty() && !p.exists()) {
            missing.push(p.to_path_buf());
            d = p.parent();
        }
        let mut out = OutputDir { created: Vec::new() };
        for p in missing.into_iter().rev() {
            let mut registry = dirs();
            match std::fs::create_dir(&p) {
                Ok(()) => {
                    registry.push(p.clone());
                    out.created.push(p);
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => anyhow::bail!("{}: {e}", p.display()),
            }
        }
        Ok(out)
    }

    /// The outputs are in place: the directories stay.
    pub fn keep(mut self) {
        let mut registry = dirs();
        for p in self.created.drain(..) {
            registry.retain(|r| *r != p);
        }
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        let mut registry = dirs();
        for p in self.created.drain(..).rev() {
            let _ = std::fs::remove_dir(&p);
            registry.retain(|r| *r != p);
        }
    }
}

fn live() -> MutexGuard<'static, Vec<PathBuf>> {
    // A panic while the list was held leaves it consistent (pushes and removals only).
    LIVE.lock().unwrap_or_else(|e| e.into_inner())
}

/// The directory and file name of an output.
fn split(path: &Path) -> anyhow::Result<(PathBuf, OsString)> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path.file_name().with_context(|| format!("{}: not a file name", path.display()))?;
    Ok((dir, name.to_os_string()))
}

/// The longest file name the temporary files are given (POSIX `NAME_MAX` of the usual file
/// systems).
const NAME_MAX: usize = 255;

/// The common start `.NAME.tmp-` of the temporary siblings of an output named `name`. A name
/// too long for the suffix is cut (at a character), so that `.NAME.tmp-PID-K` fits in
/// [`NAME_MAX`] bytes.
fn temp_prefix(name: &OsStr) -> OsString {
    // ".", ".tmp-", a PID of up to 10 digits, "-" and a retry count of up to 3.
    let room = NAME_MAX - 1 - 5 - 10 - 4;
    let mut p = OsString::from(".");
    if name.len() <= room {
        p.push(name);
    } else {
        let lossy = name.to_string_lossy();
        let mut end = room.min(lossy.len());
        while !lossy.is_char_boundary(end) {
            end -= 1;
        }
        p.push(&lossy[..end]);
    }
    p.push(".tmp-");
    p
}

/// Removes `dir/.NAME.tmp-PID` and `dir/.NAME.tmp-PID-K` for every PID (not this process's)
/// that is not a running process. Errors are ignored: a file that cannot be listed or removed
/// is left as it was.
fn remove_stale(dir: &Path, name: &OsStr) {
    let prefix = temp_prefix(name);
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let file = entry.file_name();
        let Some(rest) = file.as_encoded_bytes().strip_prefix(prefix.as_encoded_bytes()) else { continue };
        let pid = rest.split(|b| *b == b'-').next().unwrap_or_default();
        let retry = &rest[pid.len()..];
        let digits = |b: &[u8]| !b.is_empty() && b.iter().all(u8::is_ascii_digit);
        if !digits(pid) || !(retry.is_empty() || digits(&retry[1..])) {
            continue;
        }
        let Some(pid) = std::str::from_utf8(pid).ok().and_then(|p| p.parse::<u32>().ok()) else { continue };
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

/// How many names a temporary file tries before giving up (each taken by another file).
const TEMP_ATTEMPTS: u32 = 100;

/// Creates a temporary sibling of `dest` exclusively (`O_CREAT|O_EXCL`, so never through a
/// symbolic link or over another file planted at its name; the next name on a collision),
/// with `mode` (the permissions of the file it will replace) when given, and registers it
/// under the registry's lock (a signal handled meanwhile waits and then removes it).
fn create_temp(dest: &Path, mode: Option<u32>) -> std::io::Result<(PathBuf, std::fs::File)> {
    let (dir, name) = split(dest).map_err(std::io::Error::other)?;
    remove_stale(&dir, &name);
    let prefix = temp_prefix(&name);
    let pid = std::process::id();
    for k in 0..TEMP_ATTEMPTS {
        let mut file = prefix.clone();
        file.push(if k == 0 { pid.to_string() } else { format!("{pid}-{k}") });
        let tmp = dir.join(file);
        let mut live = live();
        let mut opts = std::fs::OpenOptions::new();
        opts.write(true).create_new(true);
        #[cfg(unix)]
        {
            use std::os::unix::fs::OpenOptionsExt;
            opts.custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC).mode(0o666);
        }
        match opts.open(&tmp) {
            Ok(f) => {
                live.push(tmp.clone());
                drop(live);
                #[cfg(unix)]
                if let Some(mode) = mode {
                    use std::os::unix::fs::PermissionsExt;
                    if let Err(e) = f.set_permissions(std::fs::Permissions::from_mode(mode)) {
                        let _ = finish_registered(&tmp, None);
                        return Err(e);
                    }
                }
                #[cfg(not(unix))]
                let _ = mode;
                return Ok((tmp, f));
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::AlreadyExists,
        format!("{TEMP_ATTEMPTS} temporary names beside it are all taken"),
    ))
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

/// Where the bytes of an output go.
enum Dest {
    /// A temporary file renamed over `target` on commit (`target`: the output, or the
    /// regular file a symbolic link given as the output points to).
    Replace { target: PathBuf, tmp: PathBuf },
    /// A character device (`/dev/null`, a terminal) or a FIFO with a reader: written in place,
    /// there is no file to replace.
    InPlace,
}

/// What kind of file a non-regular, non-directory output is, for the error message.
#[cfg(unix)]
fn special_kind(m: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = m.file_type();
    if t.is_block_device() {
        "a block device"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_fifo() {
        "a FIFO"
    } else {
        "not a regular file"
    }
}

/// Opens the output `path`: a temporary sibling for a new or regular file (with the previous
/// file's permissions), the device or FIFO itself in place; refuses `-`, a directory, a
/// socket, a block device, a FIFO without a reader and a symbolic link to nothing. Errors
/// name `path`.
fn open_output(path: &Path) -> anyhow::Result<(Dest, std::fs::File)> {
    let named = |e: &dyn std::fmt::Display| anyhow::anyhow!("{}: {e}", path.display());
    if path.as_os_str() == "-" {
        anyhow::bail!(
            "-: `-` is not standard output here (the commands print their tables there); give a file name, or /dev/stdout"
        );
    }
    let (target, mode) = match std::fs::metadata(path) {
        Ok(m) if m.is_file() => {
            let is_link = std::fs::symlink_metadata(path).is_ok_and(|l| l.file_type().is_symlink());
            let target = if is_link { std::fs::canonicalize(path).map_err(|e| named(&e))? } else { path.to_path_buf() };
            #[cfg(unix)]
            let mode = {
                use std::os::unix::fs::PermissionsExt;
                Some(m.permissions().mode() & 0o7777)
            };
            #[cfg(not(unix))]
            let mode = None;
            (target, mode)
        }
        Ok(m) if m.is_dir() => anyhow::bail!("{}: is a directory; give a file name", path.display()),
        #[cfg(unix)]
        Ok(m) => {
            use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
            let t = m.file_type();
            if t.is_char_device() {
                let f = std::fs::OpenOptions::new().write(true).open(path).map_err(|e| named(&e))?;
                return Ok((Dest::InPlace, f));
            }
            if t.is_fifo() {
                // Non-blocking, so that a FIFO nobody reads is refused instead of a hang.
                let f =
                    std::fs::OpenOptions::new().write(true).custom_flags(libc::O_NONBLOCK).open(path).map_err(|e| {
                        match e.raw_os_error() {
                            Some(libc::ENXIO) => anyhow::anyhow!("{}: a FIFO that nobody reads", path.display()),
                            _ => named(&e),
                        }
                    })?;
                use std::os::fd::AsRawFd;
                // SAFETY: F_GETFL/F_SETFL on a file descriptor this function owns.
                unsafe {
                    let fl = libc::fcntl(f.as_raw_fd(), libc::F_GETFL);
                    libc::fcntl(f.as_raw_fd(), libc::F_SETFL, fl & !libc::O_NONBLOCK);
                }
                return Ok((Dest::InPlace, f));
            }
            anyhow::bail!("{}: {}, not a regular file; refusing to replace it", path.display(), special_kind(&m))
        }
        #[cfg(not(unix))]
        Ok(_) => anyhow::bail!("{}: not a regular file; refusing to replace it", path.display()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            if std::fs::symlink_metadata(path).is_ok() {
                anyhow::bail!("{}: a symbolic link to a file that does not exist", path.display());
            }
            (path.to_path_buf(), None)
        }
        Err(e) => return Err(named(&e)),
    };
    let (tmp, f) = create_temp(&target, mode).map_err(|e| named(&e))?;
    Ok((Dest::Replace { target, tmp }, f))
}

/// Writes `data` to `path` atomically (temporary sibling file, fsync, rename). Errors name
/// the file.
pub fn write_atomic(path: &Path, data: &[u8]) -> anyhow::Result<()> {
    write_all_or_nothing(&[(path, data)])
}

/// Writes several outputs all or nothing: each to its temporary file, synced, and only when
/// every one is ready are they renamed into place. On an error every temporary file is
/// removed and no output is written (in-place outputs, a device or a FIFO, excepted: those
/// have nothing to roll back). Errors name the output.
pub fn write_all_or_nothing(outputs: &[(&Path, &[u8])]) -> anyhow::Result<()> {
    let mut files = Vec::with_capacity(outputs.len());
    for (path, data) in outputs {
        let mut f = AtomicFile::create(path)?;
        f.writer().write_all(data).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        files.push(f);
    }
    commit_all(files)
}

/// Commits several [`AtomicFile`]s all or nothing: every one flushed and synced first (an
/// error removes them all), then all renamed into place under the registry's lock, so that a
/// signal handled meanwhile ([`remove_temporaries_on_signals`]) waits for the last rename:
/// the set appears whole, or (the signal handled before the first rename) not at all.
pub fn commit_all(mut files: Vec<AtomicFile>) -> anyhow::Result<()> {
    for f in &mut files {
        f.prepare()?;
    }
    let mut live = live();
    let mut result = Ok(());
    for mut f in files {
        f.out = None;
        if let Dest::Replace { target, tmp } = &f.dest {
            let renamed = if result.is_ok() { std::fs::rename(tmp, target) } else { Err(std::io::Error::other("")) };
            if let Err(e) = renamed {
                let _ = std::fs::remove_file(tmp);
                if result.is_ok() {
                    result = Err(anyhow::anyhow!("{}: {e}", f.path.display()));
                }
            }
            if let Some(i) = live.iter().position(|p| p == tmp) {
                live.swap_remove(i);
            }
        }
    }
    result
}

/// A file written in a stream and put in place only on success: the data goes to a temporary
/// sibling file, [`commit`](AtomicFile::commit) flushes, fsyncs and renames it over the
/// destination. Dropped without a commit (an error on the way), the temporary file is
/// removed, so the destination is never half-written. A character device or a FIFO given as
/// the output is written in place.
pub struct AtomicFile {
    path: PathBuf,
    dest: Dest,
    out: Option<std::io::BufWriter<std::fs::File>>,
}

impl AtomicFile {
    /// Creates the temporary file beside `path`. Errors name the file.
    pub fn create(path: &Path) -> anyhow::Result<Self> {
        let (dest, f) = open_output(path)?;
        Ok(AtomicFile { path: path.to_path_buf(), dest, out: Some(std::io::BufWriter::with_capacity(1 << 20, f)) })
    }

    /// The output as given (for messages).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The stream to write to.
    pub fn writer(&mut self) -> &mut std::io::BufWriter<std::fs::File> {
        self.out.as_mut().unwrap_or_else(|| unreachable!("taken only by commit"))
    }

    /// Flushes and syncs what was written (the rename is [`commit`](Self::commit)'s). Errors
    /// name the output.
    fn prepare(&mut self) -> anyhow::Result<()> {
        let replace = matches!(self.dest, Dest::Replace { .. });
        let out = self.writer();
        let r = out.flush().and_then(|_| if replace { out.get_ref().sync_all() } else { Ok(()) });
        r.map_err(|e| anyhow::anyhow!("{}: {e}", self.path.display()))
    }

    /// Flushes, syncs and renames the temporary file over the destination.
    pub fn commit(mut self) -> anyhow::Result<()> {
        self.prepare()?;
        self.out = None;
        match &self.dest {
            Dest::Replace { target, tmp } => {
                let r = finish_registered(tmp, Some(target));
                if r.is_err() {
                    let _ = finish_registered(tmp, None);
                }
                r.map_err(|e| anyhow::anyhow!("{}: {e}", self.path.display()))
            }
            Dest::InPlace => Ok(()),
        }
    }
}

/// Writes go to the temporary file (or the device or FIFO given as the output), so that a
/// streaming writer can own the file until it is committed.
impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.writer().write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.writer().flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.out.is_some() {
            self.out = None;
            if let Dest::Replace { tmp, .. } = &self.dest {
                let _ = finish_registered(tmp, None);
            }
        }
    }
}

/// A private scratch directory (created exclusively, mode 0700, under the system's temporary
/// directory) for a library that writes only to a path (the PNG encoder); removed on drop.
pub struct ScratchDir(PathBuf);

impl ScratchDir {
    /// Creates it; errors name the directory.
    pub fn new(what: &str) -> anyhow::Result<Self> {
        let base = std::env::temp_dir();
        for k in 0..TEMP_ATTEMPTS {
            let d = base.join(format!("bins-cal-{what}-{}-{k}", std::process::id()));
            let mut b = std::fs::DirBuilder::new();
            #[cfg(unix)]
            {
                use std::os::unix::fs::DirBuilderExt;
                b.mode(0o700);
            }
            match b.create(&d) {
                Ok(()) => return Ok(ScratchDir(d)),
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                Err(e) => anyhow::bail!("{}: {e}", d.display()),
            }
        }
        anyhow::bail!("{}: no free scratch directory name", base.display())
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
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
        // The directories created for outputs that did not appear, innermost first (only
        // when empty: a file someone else put there stays).
        for d in dirs().iter().rev() {
            let _ = std::fs::remove_dir(d);
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

/// The largest text input a command reads whole (a calibration file, a scenario, a linker
/// script, an environment or constants table) \[bytes\].
pub const MAX_TEXT_INPUT_BYTES: u64 = 16 << 20;

/// Reads a file whole, refusing one longer than `max_bytes` before it is read further (so
/// `/dev/zero` or a huge file given by mistake is an error, not an exhausted memory). Errors
/// name the file.
pub fn read_capped(path: &Path, max_bytes: u64) -> anyhow::Result<Vec<u8>> {
    use std::io::Read;
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(max_bytes + 1).read_to_end(&mut bytes))
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    if bytes.len() as u64 > max_bytes {
        anyhow::bail!("{}: longer than {max_bytes} bytes; not an input of this kind", path.display());
    }
    Ok(bytes)
}

/// [`read_capped`] at [`MAX_TEXT_INPUT_BYTES`], as UTF-8 text (not UTF-8 is said so with the
/// byte offset).
pub fn read_text(path: &Path) -> anyhow::Result<String> {
    let bytes = read_capped(path, MAX_TEXT_INPUT_BYTES)?;
    String::from_utf8(bytes).map_err(|e| {
        anyhow::anyhow!("{}: not UTF-8 text (byte {} is not UTF-8)", path.display(), e.utf8_error().valid_up_to())
    })
}
