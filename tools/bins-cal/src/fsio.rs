//! Writing outputs so that nothing is ever half-written: the data goes to a temporary file in
//! the destination's directory, is flushed to disk, and is renamed over the destination.

use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes `data` to `path` atomically (temporary sibling file, fsync, rename). Errors name
/// the file.
pub fn write_atomic(path: &Path, data: &[u8]) -> anyhow::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path.file_name().with_context(|| format!("{}: not a file name", path.display()))?;
    let tmp = dir.join(format!(".{}.tmp-{}", name.to_string_lossy(), std::process::id()));
    let result = (|| -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(data)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
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
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let name = path.file_name().with_context(|| format!("{}: not a file name", path.display()))?;
        let tmp = dir.join(format!(".{}.tmp-{}", name.to_string_lossy(), std::process::id()));
        let f = std::fs::File::create(&tmp).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
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
            std::fs::rename(&self.tmp, &self.path)
        })();
        result.map_err(|e| anyhow::anyhow!("{}: {e}", self.path.display()))
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.out.is_some() {
            self.out = None;
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}
