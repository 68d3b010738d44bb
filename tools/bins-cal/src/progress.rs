//! A pass over a recording with a progress bar on standard error: the
//! [`recording::Reader`](crate::recording::Reader) of a file whose bytes read are counted, so
//! that the bar shows how much of the file a pass has read. Commands that read a large
//! recording more than once (`calibrate --free`, `calibrate --dynamics identify`,
//! `simulate --follow`) show one bar per pass. indicatif draws nothing when standard error is
//! not a terminal.

use crate::recording::{Error, Reader, Row, io_error};
use std::cell::Cell;
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;
use std::rc::Rc;

/// A reader that counts the bytes it hands out.
pub(crate) struct Counted<R> {
    inner: R,
    bytes: Rc<Cell<u64>>,
}

impl<R: Read> Read for Counted<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.bytes.set(self.bytes.get() + n as u64);
        Ok(n)
    }
}

/// A recording reader whose bytes read are counted.
pub(crate) type CountedReader = Reader<BufReader<Counted<File>>>;

/// Opens `path` (comments and header read) with its bytes read added to `bytes`; also returns
/// the file's size. Errors name the file.
pub(crate) fn open_counted(path: &Path, bytes: &Rc<Cell<u64>>) -> Result<(CountedReader, u64), Error> {
    let f = File::open(path).map_err(|e| io_error(path, e))?;
    let size = f.metadata().map(|m| m.len()).unwrap_or(0);
    let src = BufReader::with_capacity(1 << 16, Counted { inner: f, bytes: Rc::clone(bytes) });
    Ok((Reader::new(src, path)?, size))
}

/// Rows between two updates of the bar.
const UPDATE_ROWS: u64 = 1 << 16;

/// One pass over a recording: its rows one at a time, a progress bar by bytes read.
pub struct Pass {
    reader: CountedReader,
    bytes: Rc<Cell<u64>>,
    bar: indicatif::ProgressBar,
}

impl Pass {
    /// Opens `path` (comments and header read) for a pass named `what` on the bar. Errors name
    /// the file.
    pub fn open(path: &Path, what: &str) -> Result<Pass, Error> {
        let bytes = Rc::new(Cell::new(0u64));
        let (reader, size) = open_counted(path, &bytes)?;
        let bar = indicatif::ProgressBar::new(size);
        bar.set_style(
            indicatif::ProgressStyle::with_template(&format!(
                "{what} {{bar:30}} {{bytes}}/{{total_bytes}}, {{elapsed}}"
            ))
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        Ok(Pass { reader, bytes, bar })
    }

    /// Whether the header has the column `name`.
    pub fn has_column(&self, name: &str) -> bool {
        self.reader.has_column(name)
    }

    /// The next row into `row`; `false` at the end of the file (the bar is then cleared).
    pub fn read_row(&mut self, row: &mut Row) -> Result<bool, Error> {
        let more = self.reader.read_row(row);
        match more {
            Ok(true) => {
                if self.reader.rows_read().is_multiple_of(UPDATE_ROWS) {
                    self.bar.set_position(self.bytes.get());
                }
            }
            _ => self.bar.finish_and_clear(),
        }
        more
    }
}

impl Drop for Pass {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}
