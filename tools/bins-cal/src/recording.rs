//! Recording format v1 (`shared` spec `recording-format.md`, summarised in
//! `docs/recording-format.md`): a streaming reader and a streaming writer.
//!
//! A recording is a UTF-8 CSV file: `#` comment lines, one header row, then one row per logged
//! sample. Columns are found by header name; their order is free and unknown columns are kept
//! (as text) and otherwise ignored. An empty cell in an optional column is "not known".
//! Numbers must lie within their column's physical range ([`limit_of`]); a UTF-8 byte order
//! mark is skipped; a last line cut off (no line break, fewer cells than the header) is an
//! error; [`Reader::require_rows`] refuses a file with a header and no row.
//!
//! The cells are split and unquoted by the `csv` crate (RFC 4180 quoting, `""` for a quote),
//! fed one physical line at a time by `Lines`, which holds what this format says beyond
//! plain CSV: the caps ([`MAX_LINE_BYTES`], [`MAX_COLUMNS`]) refused before a line is held
//! whole or split, UTF-8 checked per line, spaces and tabs around an unquoted cell dropped, a
//! quoted cell ending on its own line, the line number of every row and error. Recordings
//! ([`Reader`]) and the host's small tables ([`Table`]) are read by this one path.
//!
//! The reader holds one line in memory at a time: [`Reader::read_row`] refills a caller-owned
//! [`Row`] without allocating (the fast path for the 8.6-million-row day file), and the reader
//! is also an [`Iterator`] of owned rows. Every error names the file, the line (1-based) and,
//! where there is one, the column (1-based position and header name). A streaming reader
//! cannot make "nothing is half-read" true by itself: a consumer must not act on the rows of a
//! file before it has seen the end without an error (every tool here either accumulates first
//! or writes its output atomically).
//!
//! The writer formats floats as the shortest decimal that parses back to the same `f64`
//! (`ryu`), so write → read is exact; it refuses non-finite numbers, numbers outside their
//! column's range and a time that does not increase, so it cannot produce a file the reader
//! rejects.

use bins_comp::vibration::Vibration;
use std::fmt;
use std::fs::File;
use std::io::{self, BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};

/// Longest line the reader accepts \[B\], line break excluded. A recording's row is a few
/// hundred bytes; a longer line is not a recording (a binary file, `/dev/zero`, a file without
/// line breaks) and is refused when this many bytes have been read, before it fills memory.
pub const MAX_LINE_BYTES: usize = 1 << 20;
/// Most cells a line may have. The format defines 17 columns; a header or row with more cells
/// than this is refused as soon as the count is passed.
pub const MAX_COLUMNS: usize = 4096;

/// Header names of the columns the format defines, in the order the writer puts them.
pub mod col {
    /// Time since the start of the recording \[s\].
    pub const T_S: &str = "t_s";
    /// Output signal of the x accelerometer \[V\].
    pub const UX_V: &str = "ux_V";
    /// Output signal of the y accelerometer \[V\].
    pub const UY_V: &str = "uy_V";
    /// Output signal of the z accelerometer \[V\].
    pub const UZ_V: &str = "uz_V";
    /// The unit's temperature sensor [°C].
    pub const TEMP_C: &str = "temp_C";
    /// Static specific force along x \[g\].
    pub const FX_G: &str = "fx_g";
    /// Static specific force along y \[g\].
    pub const FY_G: &str = "fy_g";
    /// Static specific force along z \[g\].
    pub const FZ_G: &str = "fz_g";
    /// `none`, `sine` or `random`.
    pub const VIB_KIND: &str = "vib_kind";
    /// Vibration along x \[g\]: peak (sine) or RMS (random).
    pub const VIB_X_G: &str = "vib_x_g";
    /// Vibration along y \[g\].
    pub const VIB_Y_G: &str = "vib_y_g";
    /// Vibration along z \[g\].
    pub const VIB_Z_G: &str = "vib_z_g";
    /// Sine frequency, or the centre of the random band \[Hz\].
    pub const VIB_HZ: &str = "vib_hz";
    /// Random bandwidth Δf \[Hz\].
    pub const VIB_BW_HZ: &str = "vib_bw_hz";
    /// Chamber air temperature or set point [°C].
    pub const CHAMBER_C: &str = "chamber_C";
    /// Rig position label.
    pub const POS: &str = "pos";
    /// Time since power-on \[s\].
    pub const POWER_S: &str = "power_s";
}

/// The physical range of a column's values: the reader refuses a value outside it (naming
/// file, line and column) and the writer does not write one. A value outside is a fault of
/// the logger or of a file's edit, never a measurement: a temperature no chamber reaches, a
/// signal no analogue front end delivers (the ADC's full scale is ±1.2 V, the supply rails
/// ±15 V), a force or vibration no rig applies. One such value would otherwise pass through
/// every statistic (an `f64` holds 1e308 without complaint) and cost minutes or a wrong
/// result downstream.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limit {
    /// Smallest value accepted.
    pub min: f64,
    /// Largest value accepted.
    pub max: f64,
    /// The unit, for messages.
    pub unit: &'static str,
}

impl Limit {
    /// True when `v` lies within the range.
    pub fn contains(&self, v: f64) -> bool {
        (self.min..=self.max).contains(&v)
    }
}

/// Temperatures (`temp_C`, `chamber_C`): −100 … +200 °C.
pub const TEMP_LIMIT: Limit = Limit { min: -100.0, max: 200.0, unit: "°C" };
/// Accelerometer signals (`ux_V`, `uy_V`, `uz_V`): ±100 V.
pub const SIGNAL_LIMIT: Limit = Limit { min: -100.0, max: 100.0, unit: "V" };
/// Specific forces and vibration amplitudes (`fx_g` … `fz_g`, `vib_x_g` … `vib_z_g`): ±1000 g.
pub const ACCEL_LIMIT: Limit = Limit { min: -1000.0, max: 1000.0, unit: "g" };

/// The physical range of column `name`, if the format gives it one (time, frequencies and
/// power-on time have none beyond being finite; `t_s` must increase).
pub fn limit_of(name: &str) -> Option<Limit> {
    column(name).and_then(|c| COLUMNS[c].limit)
}

/// Which columns a writer puts in a file together ([`Columns`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Group {
    /// Always present: time, the three signals, the temperature.
    Required,
    /// What the rig applied: static force and vibration.
    Reference,
    /// `chamber_C`.
    Chamber,
    /// `pos`.
    Pos,
    /// `power_s`.
    Power,
}

/// One column the format defines: its header name, its group, its physical range and where
/// its cells go in a [`Row`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColumnDef {
    /// The header name.
    pub name: &'static str,
    /// Required, reference or one of the optional columns.
    pub group: Group,
    /// The physical range of its numbers, if it has one.
    pub limit: Option<Limit>,
    field: Field,
}

const fn def(name: &'static str, group: Group, limit: Option<Limit>, field: Field) -> ColumnDef {
    ColumnDef { name, group, limit, field }
}

/// Every column the format defines, in the order the writer puts them: the one table the
/// reader, the writer, [`limit_of`] and [`Columns`] read.
pub const COLUMNS: [ColumnDef; 17] = [
    def(col::T_S, Group::Required, None, Field::T),
    def(col::UX_V, Group::Required, Some(SIGNAL_LIMIT), Field::U(0)),
    def(col::UY_V, Group::Required, Some(SIGNAL_LIMIT), Field::U(1)),
    def(col::UZ_V, Group::Required, Some(SIGNAL_LIMIT), Field::U(2)),
    def(col::TEMP_C, Group::Required, Some(TEMP_LIMIT), Field::Temp),
    def(col::FX_G, Group::Reference, Some(ACCEL_LIMIT), Field::F(0)),
    def(col::FY_G, Group::Reference, Some(ACCEL_LIMIT), Field::F(1)),
    def(col::FZ_G, Group::Reference, Some(ACCEL_LIMIT), Field::F(2)),
    def(col::VIB_KIND, Group::Reference, None, Field::VibKind),
    def(col::VIB_X_G, Group::Reference, Some(ACCEL_LIMIT), Field::Vib(0)),
    def(col::VIB_Y_G, Group::Reference, Some(ACCEL_LIMIT), Field::Vib(1)),
    def(col::VIB_Z_G, Group::Reference, Some(ACCEL_LIMIT), Field::Vib(2)),
    def(col::VIB_HZ, Group::Reference, None, Field::VibHz),
    def(col::VIB_BW_HZ, Group::Reference, None, Field::VibBw),
    def(col::CHAMBER_C, Group::Chamber, Some(TEMP_LIMIT), Field::Chamber),
    def(col::POS, Group::Pos, None, Field::Pos),
    def(col::POWER_S, Group::Power, None, Field::Power),
];

/// The position in [`COLUMNS`] of the column named `name`.
fn column(name: &str) -> Option<usize> {
    COLUMNS.iter().position(|c| c.name == name)
}

/// The names of the columns of `group`, in [`COLUMNS`] order.
pub fn names_of(group: Group) -> impl Iterator<Item = &'static str> {
    COLUMNS.iter().filter(move |c| c.group == group).map(|c| c.name)
}

/// `vib_kind`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VibKind {
    /// No vibration.
    None,
    /// Harmonic: `vib_*_g` are peak amplitudes, `vib_hz` the frequency.
    Sine,
    /// Broadband random, fully correlated axes: `vib_*_g` are σ, `vib_hz` the band centre,
    /// `vib_bw_hz` the bandwidth.
    Random,
}

impl VibKind {
    /// The cell text.
    pub fn as_str(self) -> &'static str {
        match self {
            VibKind::None => "none",
            VibKind::Sine => "sine",
            VibKind::Random => "random",
        }
    }

    fn parse(s: &str) -> Option<Self> {
        match s {
            "none" => Some(VibKind::None),
            "sine" => Some(VibKind::Sine),
            "random" => Some(VibKind::Random),
            _ => None,
        }
    }
}

/// One row of a recording. Optional cells are `None` when empty or when the file has no
/// such column.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Row {
    /// Line number in the file (1-based); 0 for a row not read from a file.
    pub line: u64,
    /// `t_s` \[s\].
    pub t_s: f64,
    /// `ux_V`, `uy_V`, `uz_V` \[V\].
    pub u_v: [f64; 3],
    /// `temp_C` [°C].
    pub temp_c: f64,
    /// `fx_g`, `fy_g`, `fz_g` \[g\].
    pub f_g: [Option<f64>; 3],
    /// `vib_kind`.
    pub vib_kind: Option<VibKind>,
    /// `vib_x_g`, `vib_y_g`, `vib_z_g` \[g\].
    pub vib_g: [Option<f64>; 3],
    /// `vib_hz` \[Hz\].
    pub vib_hz: Option<f64>,
    /// `vib_bw_hz` \[Hz\].
    pub vib_bw_hz: Option<f64>,
    /// `chamber_C` [°C].
    pub chamber_c: Option<f64>,
    /// `pos`.
    pub pos: Option<String>,
    /// `power_s` \[s\].
    pub power_s: Option<f64>,
    /// Cells of the columns the format does not define, in the order of
    /// [`Reader::extra_columns`] (empty cells as empty strings).
    pub extra: Vec<String>,
}

impl Row {
    /// The static specific force \[g\] when all three components are known.
    pub fn reference_f_g(&self) -> Option<[f64; 3]> {
        match self.f_g {
            [Some(x), Some(y), Some(z)] => Some([x, y, z]),
            _ => None,
        }
    }

    /// The vibration the rig applied, when known: `vib_kind` and the cells that kind needs
    /// (`none`: nothing else; `sine`: amplitudes and `vib_hz`; `random`: σ, `vib_hz` and
    /// `vib_bw_hz`, band = centre ± bw/2).
    pub fn vibration(&self) -> Option<Vibration<f64>> {
        match self.vib_kind? {
            VibKind::None => Some(Vibration::None),
            VibKind::Sine => {
                let [Some(x), Some(y), Some(z)] = self.vib_g else { return None };
                Some(Vibration::Harmonic { amp_g: [x, y, z], freq_hz: self.vib_hz? })
            }
            VibKind::Random => {
                let [Some(x), Some(y), Some(z)] = self.vib_g else { return None };
                let (c, bw) = (self.vib_hz?, self.vib_bw_hz?);
                Some(Vibration::Random { sigma_g: [x, y, z], band_hz: (c - 0.5 * bw, c + 0.5 * bw) })
            }
        }
    }

    /// Sets the vibration reference cells from a core [`Vibration`] (the inverse of
    /// [`vibration`](Self::vibration)).
    pub fn set_vibration(&mut self, v: &Vibration<f64>) {
        match v {
            Vibration::None => {
                self.vib_kind = Some(VibKind::None);
                self.vib_g = [Some(0.0); 3];
                self.vib_hz = None;
                self.vib_bw_hz = None;
            }
            Vibration::Harmonic { amp_g, freq_hz } => {
                self.vib_kind = Some(VibKind::Sine);
                self.vib_g = amp_g.map(Some);
                self.vib_hz = Some(*freq_hz);
                self.vib_bw_hz = None;
            }
            Vibration::Random { sigma_g, band_hz } => {
                self.vib_kind = Some(VibKind::Random);
                self.vib_g = sigma_g.map(Some);
                self.vib_hz = Some(0.5 * (band_hz.0 + band_hz.1));
                self.vib_bw_hz = Some(band_hz.1 - band_hz.0);
            }
        }
    }

    /// Clears every reference cell (rig state not known).
    pub fn clear_reference(&mut self) {
        self.f_g = [None; 3];
        self.vib_kind = None;
        self.vib_g = [None; 3];
        self.vib_hz = None;
        self.vib_bw_hz = None;
    }
}

/// What is wrong in a recording.
#[derive(Clone, Debug, PartialEq)]
pub enum ErrorKind {
    /// The file could not be opened, read or written.
    Io(String),
    /// No header row before the end of the file.
    NoHeader,
    /// A required column is not in the header.
    MissingColumn(&'static str),
    /// A column a table needs is not in its header.
    NoColumn(String),
    /// A header name appears twice.
    DuplicateColumn(String),
    /// An empty header name.
    EmptyColumnName,
    /// A data row with a different number of cells than the header.
    CellCount {
        /// Cells in the header.
        expected: usize,
        /// Cells in the row.
        got: usize,
    },
    /// A cell of a numeric column that is not a finite decimal number.
    NotANumber(String),
    /// A number outside its column's physical range ([`limit_of`]).
    OutOfRange {
        /// The cell's text (reader) or the value (writer).
        value: String,
        /// The column's range.
        limit: Limit,
    },
    /// The last line ends without a line break and has fewer cells than the header: the file
    /// was cut off while being written or copied.
    CutOff {
        /// Cells in the header.
        expected: usize,
        /// Cells in the line.
        got: usize,
    },
    /// A header and no data row where the output needs rows.
    NoRows,
    /// An empty cell in a required column.
    EmptyRequired,
    /// `vib_kind` other than `none`, `sine`, `random`.
    BadVibKind(String),
    /// `t_s` not greater than the previous row's.
    TimeNotIncreasing {
        /// The previous row's time \[s\].
        previous: f64,
        /// This row's time \[s\].
        this: f64,
    },
    /// A line that is not UTF-8.
    NotUtf8,
    /// A line longer than [`MAX_LINE_BYTES`].
    LineTooLong,
    /// A line with more cells than [`MAX_COLUMNS`].
    TooManyCells,
    /// A quoted cell without its closing quote.
    UnterminatedQuote,
    /// The writer was given a value it cannot write (non-finite number, a comment or a cell
    /// with a line break).
    Unwritable(String),
}

/// An error in a recording: the file, the line (0 = not tied to a line), the column (position
/// 1-based and header name) where there is one, and what is wrong.
#[derive(Clone, Debug, PartialEq)]
pub struct Error {
    /// The file (or stream name).
    pub file: PathBuf,
    /// Line number, 1-based; 0 when the error is not tied to a line.
    pub line: u64,
    /// Column position (1-based) and header name.
    pub column: Option<(usize, String)>,
    /// What is wrong.
    pub kind: ErrorKind,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if self.line > 0 {
            write!(f, ":{}", self.line)?;
        }
        if let Some((pos, name)) = &self.column {
            write!(f, ": column {pos} `{name}`")?;
        }
        write!(f, ": ")?;
        match &self.kind {
            ErrorKind::Io(e) => write!(f, "{e}"),
            ErrorKind::NoHeader => write!(f, "no header row (recording format v1 needs one)"),
            ErrorKind::MissingColumn(c) => write!(f, "required column `{c}` missing from the header"),
            ErrorKind::NoColumn(c) => write!(f, "missing column `{c}` in the header"),
            ErrorKind::DuplicateColumn(c) => write!(f, "column `{c}` appears twice in the header"),
            ErrorKind::EmptyColumnName => write!(f, "empty column name in the header"),
            ErrorKind::CellCount { expected, got } => write!(f, "{got} cells, the header has {expected}"),
            ErrorKind::NotANumber(s) => write!(f, "`{s}` is not a finite number"),
            ErrorKind::OutOfRange { value, limit } => write!(
                f,
                "`{value}` is outside the physical range {} … {} {} (a logger fault or a bad edit)",
                limit.min, limit.max, limit.unit
            ),
            ErrorKind::CutOff { expected, got } => write!(
                f,
                "last line cut off: {got} cells, the header has {expected}, and no line break at the end (truncated file?)"
            ),
            ErrorKind::NoRows => write!(f, "no data row after the header"),
            ErrorKind::EmptyRequired => write!(f, "empty cell in a required column"),
            ErrorKind::BadVibKind(s) => write!(f, "`{s}` is not a vibration kind (none, sine, random)"),
            ErrorKind::TimeNotIncreasing { previous, this } => {
                write!(f, "time {this} s does not increase (previous row {previous} s)")
            }
            ErrorKind::NotUtf8 => write!(f, "line is not UTF-8"),
            ErrorKind::LineTooLong => {
                write!(f, "line longer than {MAX_LINE_BYTES} bytes (not a recording: no line breaks, or binary data)")
            }
            ErrorKind::TooManyCells => write!(f, "more than {MAX_COLUMNS} cells in the line"),
            ErrorKind::UnterminatedQuote => write!(f, "quoted cell without a closing quote"),
            ErrorKind::Unwritable(s) => write!(f, "cannot write {s}"),
        }
    }
}

impl std::error::Error for Error {}

/// Where a defined column's cells go in a [`Row`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Field {
    T,
    U(usize),
    Temp,
    F(usize),
    VibKind,
    Vib(usize),
    VibHz,
    VibBw,
    Chamber,
    Pos,
    Power,
}

/// What a header position holds: a column of [`COLUMNS`] (by its position there) or the n-th
/// extra column.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Slot {
    Defined(usize),
    Extra(usize),
}

/// Reads the next physical line of `src` into `raw`, line break included (empty at the end of
/// `src`). A line longer than [`MAX_LINE_BYTES`] is an error as soon as that many bytes are read.
fn read_line(src: &mut impl BufRead, raw: &mut Vec<u8>) -> Result<(), ErrorKind> {
    raw.clear();
    loop {
        let buf = match src.fill_buf() {
            Ok(buf) => buf,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(ErrorKind::Io(e.to_string())),
        };
        if buf.is_empty() {
            return Ok(());
        }
        let (take, ended) = match memchr::memchr(b'\n', buf) {
            Some(i) => (i + 1, true),
            None => (buf.len(), false),
        };
        // The line break and a carriage return before it are not counted.
        if raw.len() + take > MAX_LINE_BYTES + 2 {
            return Err(ErrorKind::LineTooLong);
        }
        raw.extend_from_slice(&buf[..take]);
        src.consume(take);
        if ended {
            return Ok(());
        }
    }
}

/// Brings one line into the form the `csv` crate reads as this format means it: spaces and
/// tabs around a cell are not part of it (unless quoted), nothing after a quoted cell's closing
/// quote is (up to the next comma), a quoted cell ends on its own line. Writes the line to
/// `out` (without a line break); more than [`MAX_COLUMNS`] cells is an error. The `csv` crate
/// then splits the cells and unquotes them. For lines with a quote, a space or a tab; the
/// others need no cleaning.
fn clean_line(line: &[u8], out: &mut Vec<u8>) -> Result<(), ErrorKind> {
    out.clear();
    let pad = |b: &u8| *b == b' ' || *b == b'\t';
    let (mut i, mut cells) = (0, 0);
    loop {
        cells += 1;
        if cells > MAX_COLUMNS {
            return Err(ErrorKind::TooManyCells);
        }
        while i < line.len() && pad(&line[i]) {
            i += 1;
        }
        if line.get(i) == Some(&b'"') {
            // The closing quote is the first one not doubled.
            let mut q = i + 1;
            loop {
                let Some(at) = memchr::memchr(b'"', &line[q..]) else { return Err(ErrorKind::UnterminatedQuote) };
                q += at + 1;
                if line.get(q) == Some(&b'"') {
                    q += 1;
                } else {
                    break;
                }
            }
            out.extend_from_slice(&line[i..q]);
            i = memchr::memchr(b',', &line[q..]).map_or(line.len(), |c| q + c);
        } else {
            let end = memchr::memchr(b',', &line[i..]).map_or(line.len(), |c| i + c);
            let cell = &line[i..end];
            let kept = cell.len() - cell.iter().rev().take_while(|b| pad(b)).count();
            out.extend_from_slice(&cell[..kept]);
            i = end;
        }
        if i >= line.len() {
            return Ok(());
        }
        out.push(b',');
        i += 1;
    }
}

/// What a line that is blank, or a comment, means to a [`Lines`] source.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Blank {
    /// A recording's data: a blank line is a row of one empty cell (an error of its cell
    /// count), a `#` line a row like any other.
    Row,
    /// A table: blank lines and lines starting with `#` are skipped.
    Skip,
}

/// The physical lines of a CSV source, handed to the `csv` crate one at a time (each
/// [`Read::read`] gives at most one line, so that the line being parsed is the one this source
/// read last and errors name it). Enforces the caps ([`MAX_LINE_BYTES`], [`MAX_COLUMNS`]) before
/// a line is buffered whole or split, checks UTF-8, skips a byte order mark on line 1, takes
/// `\r\n` as a line break and cleans each line ([`clean_line`]). An error is kept with its line
/// for the reader and given to the `csv` crate as an I/O error that ends its reading.
struct Lines<R> {
    src: R,
    blank: Blank,
    /// Number of the last line read (1-based).
    line_no: u64,
    /// The last line read ended with a line break.
    ended: bool,
    raw: Vec<u8>,
    out: Vec<u8>,
    /// Bytes of `out` already handed to the `csv` crate.
    at: usize,
    error: Option<(u64, ErrorKind)>,
    /// No line handed to the `csv` crate yet.
    first: bool,
}

impl<R: BufRead> Lines<R> {
    fn new(src: R, blank: Blank) -> Self {
        Lines { src, blank, line_no: 0, ended: true, raw: Vec::new(), out: Vec::new(), at: 0, error: None, first: true }
    }

    /// Reads the next physical line into `raw` without its line break; false at the end.
    fn next_raw(&mut self) -> Result<bool, (u64, ErrorKind)> {
        read_line(&mut self.src, &mut self.raw).map_err(|k| (self.line_no + 1, k))?;
        if self.raw.is_empty() {
            return Ok(false);
        }
        self.line_no += 1;
        // A UTF-8 byte order mark (spreadsheet exports) is not part of the first cell (a
        // table's lines may each start with one: tables are pasted together).
        if (self.line_no == 1 || self.blank == Blank::Skip) && self.raw.starts_with(b"\xEF\xBB\xBF") {
            self.raw.drain(..3);
        }
        self.ended = self.raw.last() == Some(&b'\n');
        if self.ended {
            self.raw.pop();
        }
        // A recording's line loses one carriage return, a table's every one at its end.
        while self.raw.last() == Some(&b'\r') {
            self.raw.pop();
            if self.blank == Blank::Row {
                break;
            }
        }
        if std::str::from_utf8(&self.raw).is_err() {
            return Err((self.line_no, ErrorKind::NotUtf8));
        }
        Ok(true)
    }

    /// The last line read, as text (checked by [`next_raw`](Self::next_raw)).
    fn text(&self) -> &str {
        std::str::from_utf8(&self.raw).unwrap_or_default()
    }

    /// Makes the last line read the next one handed to the `csv` crate.
    fn hand_on(&mut self) -> Result<(), (u64, ErrorKind)> {
        if memchr::memchr3(b'"', b' ', b'\t', &self.raw).is_none() {
            // The common case: no quote, no padding, nothing to clean; the cells are the commas
            // plus one (fewer than the bytes).
            if self.raw.len() >= MAX_COLUMNS && memchr::memchr_iter(b',', &self.raw).count() >= MAX_COLUMNS {
                return Err((self.line_no, ErrorKind::TooManyCells));
            }
            std::mem::swap(&mut self.raw, &mut self.out);
        } else {
            clean_line(&self.raw, &mut self.out).map_err(|k| (self.line_no, k))?;
        }
        if self.out.is_empty() && self.blank == Blank::Row {
            self.out.extend_from_slice(b"\"\"");
        }
        if self.ended {
            self.out.push(b'\n');
        }
        // The `csv` crate drops a byte order mark at the start of its input; one left here (not
        // at the start of the file) is part of the cell: a blank line first keeps it.
        if self.first && self.out.starts_with(b"\xEF\xBB\xBF") {
            self.out.insert(0, b'\n');
        }
        self.first = false;
        self.at = 0;
        Ok(())
    }

    /// The next line for the `csv` crate; false at the end.
    fn next_line(&mut self) -> Result<bool, (u64, ErrorKind)> {
        loop {
            if !self.next_raw()? {
                return Ok(false);
            }
            if self.blank == Blank::Skip {
                let text = self.text();
                if text.trim_start().starts_with('#') || text.trim().is_empty() {
                    continue;
                }
            }
            self.hand_on()?;
            return Ok(true);
        }
    }
}

impl<R: BufRead> Read for Lines<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.at == self.out.len() {
            if self.error.is_some() {
                return Err(io::Error::other("error in a line"));
            }
            match self.next_line() {
                Ok(true) => {}
                Ok(false) => return Ok(0),
                Err(e) => {
                    self.error = Some(e);
                    return Err(io::Error::other("error in a line"));
                }
            }
        }
        let n = buf.len().min(self.out.len() - self.at);
        buf[..n].copy_from_slice(&self.out[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

/// A `csv` crate reader over `lines`: comma-separated, `"` quotes with `""` for a quote, a
/// line break ends a row, rows of any length (the caller checks the count).
fn csv_reader<R: BufRead>(lines: Lines<R>) -> csv::Reader<Lines<R>> {
    csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .terminator(csv::Terminator::Any(b'\n'))
        .buffer_capacity(1 << 16)
        .from_reader(lines)
}

/// Reads the next row of `csv` into `record`; false at the end. An error names the line.
fn read_record<R: BufRead>(
    csv: &mut csv::Reader<Lines<R>>,
    record: &mut csv::ByteRecord,
) -> Result<bool, (u64, ErrorKind)> {
    csv.read_byte_record(record).map_err(|e| {
        let lines = csv.get_ref();
        lines.error.clone().unwrap_or_else(|| (lines.line_no, ErrorKind::Io(e.to_string())))
    })
}

/// Cell `i` of `record` as text (every line was checked to be UTF-8).
fn cell_text(record: &csv::ByteRecord, i: usize) -> &str {
    record.get(i).and_then(|c| std::str::from_utf8(c).ok()).unwrap_or_default()
}

/// A streaming reader of recording format v1.
pub struct Reader<R> {
    csv: csv::Reader<Lines<R>>,
    record: csv::ByteRecord,
    file: PathBuf,
    /// Number of the line being read (1-based).
    line_no: u64,
    comments: Vec<String>,
    header: Vec<String>,
    slots: Vec<Slot>,
    extra: Vec<String>,
    /// Which of [`COLUMNS`] the header has.
    present: [bool; COLUMNS.len()],
    prev_t: Option<f64>,
    failed: bool,
    /// Data rows read without an error.
    rows: u64,
}

impl Reader<BufReader<File>> {
    /// Opens a file and reads its comments and header.
    pub fn open(path: &Path) -> Result<Self, Error> {
        let f = File::open(path).map_err(|e| Error {
            file: path.to_path_buf(),
            line: 0,
            column: None,
            kind: ErrorKind::Io(e.to_string()),
        })?;
        Reader::new(BufReader::with_capacity(1 << 16, f), path)
    }
}

impl<R: BufRead> Reader<R> {
    /// Reads the comment lines and the header from `src`; `name` is the file named in errors.
    pub fn new(src: R, name: impl AsRef<Path>) -> Result<Self, Error> {
        let file = name.as_ref().to_path_buf();
        let at = |(line, kind)| Error { file: file.clone(), line, column: None, kind };
        // The comments and blank lines before the header are read here; the header and the
        // rows by the `csv` crate.
        let mut lines = Lines::new(src, Blank::Row);
        let mut comments = Vec::new();
        loop {
            if !lines.next_raw().map_err(at)? {
                return Err(at((lines.line_no, ErrorKind::NoHeader)));
            }
            let line = lines.text();
            if let Some(c) = line.strip_prefix('#') {
                comments.push(c.strip_prefix(' ').unwrap_or(c).to_string());
                continue;
            }
            if line.trim().is_empty() {
                continue;
            }
            break;
        }
        lines.hand_on().map_err(at)?;
        let line_no = lines.line_no;
        let mut r = Reader {
            csv: csv_reader(lines),
            record: csv::ByteRecord::new(),
            file,
            line_no,
            comments,
            header: Vec::new(),
            slots: Vec::new(),
            extra: Vec::new(),
            present: [false; COLUMNS.len()],
            prev_t: None,
            failed: false,
            rows: 0,
        };
        if !read_record(&mut r.csv, &mut r.record).map_err(|e| r.at(e))? {
            return Err(r.err(None, ErrorKind::NoHeader));
        }
        for pos in 0..r.record.len() {
            let name = cell_text(&r.record, pos).to_string();
            if name.is_empty() {
                return Err(r.err(Some(pos), ErrorKind::EmptyColumnName));
            }
            if r.header.contains(&name) {
                r.header.push(name.clone());
                return Err(r.err(Some(pos), ErrorKind::DuplicateColumn(name)));
            }
            let slot = match column(&name) {
                Some(c) => {
                    r.present[c] = true;
                    Slot::Defined(c)
                }
                None => {
                    r.extra.push(name.clone());
                    Slot::Extra(r.extra.len() - 1)
                }
            };
            r.slots.push(slot);
            r.header.push(name);
        }
        if let Some(c) = COLUMNS.iter().zip(r.present).find(|(c, here)| c.group == Group::Required && !here) {
            return Err(r.err(None, ErrorKind::MissingColumn(c.0.name)));
        }
        Ok(r)
    }

    /// The comment lines before the header, without the `#` (and one following space).
    pub fn comments(&self) -> &[String] {
        &self.comments
    }

    /// The header names in file order.
    pub fn header(&self) -> &[String] {
        &self.header
    }

    /// The names of the columns the format does not define, in file order.
    pub fn extra_columns(&self) -> &[String] {
        &self.extra
    }

    /// True when the header has column `name`.
    pub fn has_column(&self, name: &str) -> bool {
        self.header.iter().any(|h| h == name)
    }

    /// True when the header has every reference column.
    pub fn has_reference(&self) -> bool {
        COLUMNS.iter().zip(self.present).all(|(c, here)| here || c.group != Group::Reference)
    }

    /// The file named in errors.
    pub fn file(&self) -> &Path {
        &self.file
    }

    /// The line number of the last line read (1-based).
    pub fn line(&self) -> u64 {
        self.line_no
    }

    fn err(&self, pos: Option<usize>, kind: ErrorKind) -> Error {
        Error {
            file: self.file.clone(),
            line: self.line_no,
            column: pos.map(|p| (p + 1, self.header.get(p).cloned().unwrap_or_default())),
            kind,
        }
    }

    /// An error of the line source, at its line.
    fn at(&self, (line, kind): (u64, ErrorKind)) -> Error {
        Error { file: self.file.clone(), line, column: None, kind }
    }

    /// Reads the next data row into `row` (reusing its storage); `Ok(false)` at the end of the
    /// file. After an error the reader stays at the end.
    pub fn read_row(&mut self, row: &mut Row) -> Result<bool, Error> {
        if self.failed {
            return Ok(false);
        }
        let r = self.read_row_inner(row);
        if r.is_err() {
            self.failed = true;
        }
        r
    }

    fn read_row_inner(&mut self, row: &mut Row) -> Result<bool, Error> {
        if !read_record(&mut self.csv, &mut self.record).map_err(|e| self.at(e))? {
            return Ok(false);
        }
        // The `csv` crate is given one line at a time: the line the source read last is the
        // row's.
        self.line_no = self.csv.get_ref().line_no;
        let line_ended = self.csv.get_ref().ended;
        // `fill` borrows the reader: move the record out for the call.
        let record = std::mem::take(&mut self.record);
        let result = self.fill(row, &record, line_ended);
        self.record = record;
        result?;
        self.rows += 1;
        Ok(true)
    }

    /// Data rows read so far without an error.
    pub fn rows_read(&self) -> u64 {
        self.rows
    }

    /// An error ([`ErrorKind::NoRows`], naming the file) when no data row has been read: for
    /// the consumers whose output needs rows, called at the end of the file.
    pub fn require_rows(&self) -> Result<(), Error> {
        if self.rows == 0 {
            return Err(Error { file: self.file.clone(), line: 0, column: None, kind: ErrorKind::NoRows });
        }
        Ok(())
    }

    fn fill(&mut self, row: &mut Row, record: &csv::ByteRecord, line_ended: bool) -> Result<(), Error> {
        // Trailing empty cells of optional columns may be left out (CSV writers drop them;
        // the real recording in `data/real/` does): they read as empty. Anything else with a
        // cell count other than the header's is an error.
        let (expected, got) = (self.slots.len(), record.len());
        if got < expected && !line_ended {
            return Err(self.err(None, ErrorKind::CutOff { expected, got }));
        }
        let required = |s: &Slot| matches!(s, Slot::Defined(c) if COLUMNS[*c].group == Group::Required);
        let short_ok = got < expected && !self.slots[got..].iter().any(required);
        if got != expected && !short_ok {
            return Err(self.err(None, ErrorKind::CellCount { expected, got }));
        }
        row.line = self.line_no;
        row.clear_reference();
        row.chamber_c = None;
        row.power_s = None;
        let mut pos_buf = row.pos.take();
        row.extra.resize(self.extra.len(), String::new());
        for slot in &self.slots[got.min(expected)..] {
            if let Slot::Extra(i) = slot {
                row.extra[*i].clear();
            }
        }
        let mut pos_set = false;
        for (p, &slot) in self.slots.iter().enumerate().take(got) {
            let cell = cell_text(record, p);
            let c = match slot {
                Slot::Defined(c) => &COLUMNS[c],
                Slot::Extra(i) => {
                    row.extra[i].clear();
                    row.extra[i].push_str(cell);
                    continue;
                }
            };
            let num = |required: bool| -> Result<Option<f64>, Error> {
                if cell.is_empty() {
                    return if required { Err(self.err(Some(p), ErrorKind::EmptyRequired)) } else { Ok(None) };
                }
                match cell.parse::<f64>() {
                    Ok(v) if v.is_finite() => match c.limit {
                        Some(limit) if !limit.contains(v) => {
                            Err(self.err(Some(p), ErrorKind::OutOfRange { value: cell.to_string(), limit }))
                        }
                        _ => Ok(Some(v)),
                    },
                    _ => Err(self.err(Some(p), ErrorKind::NotANumber(cell.to_string()))),
                }
            };
            match c.field {
                Field::T => row.t_s = num(true)?.unwrap_or_default(),
                Field::U(i) => row.u_v[i] = num(true)?.unwrap_or_default(),
                Field::Temp => row.temp_c = num(true)?.unwrap_or_default(),
                Field::F(i) => row.f_g[i] = num(false)?,
                Field::VibKind => {
                    row.vib_kind = if cell.is_empty() {
                        None
                    } else {
                        Some(
                            VibKind::parse(cell)
                                .ok_or_else(|| self.err(Some(p), ErrorKind::BadVibKind(cell.to_string())))?,
                        )
                    }
                }
                Field::Vib(i) => row.vib_g[i] = num(false)?,
                Field::VibHz => row.vib_hz = num(false)?,
                Field::VibBw => row.vib_bw_hz = num(false)?,
                Field::Chamber => row.chamber_c = num(false)?,
                Field::Power => row.power_s = num(false)?,
                Field::Pos => {
                    if !cell.is_empty() {
                        let mut s = pos_buf.take().unwrap_or_default();
                        s.clear();
                        s.push_str(cell);
                        row.pos = Some(s);
                        pos_set = true;
                    }
                }
            }
        }
        if !pos_set {
            row.pos = None;
        }
        if let Some(prev) = self.prev_t
            && !(row.t_s > prev)
        {
            let p = self.slots.iter().position(|s| matches!(s, Slot::Defined(c) if COLUMNS[*c].field == Field::T));
            return Err(self.err(p, ErrorKind::TimeNotIncreasing { previous: prev, this: row.t_s }));
        }
        self.prev_t = Some(row.t_s);
        Ok(())
    }
}

impl<R: BufRead> Iterator for Reader<R> {
    type Item = Result<Row, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        let mut row = Row::default();
        match self.read_row(&mut row) {
            Ok(true) => Some(Ok(row)),
            Ok(false) => None,
            Err(e) => Some(Err(e)),
        }
    }
}

/// Which optional columns a writer puts in the file (the required ones always).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Columns {
    /// The nine reference columns.
    pub reference: bool,
    /// `chamber_C`.
    pub chamber: bool,
    /// `pos`.
    pub pos: bool,
    /// `power_s`.
    pub power: bool,
    /// Further columns, written from [`Row::extra`] in this order.
    pub extra: Vec<String>,
}

impl Columns {
    /// Every column the format defines, no extra ones.
    pub fn all() -> Self {
        Columns { reference: true, chamber: true, pos: true, power: true, extra: Vec::new() }
    }

    /// True when the columns of `group` are written.
    pub fn has(&self, group: Group) -> bool {
        match group {
            Group::Required => true,
            Group::Reference => self.reference,
            Group::Chamber => self.chamber,
            Group::Pos => self.pos,
            Group::Power => self.power,
        }
    }

    /// The defined columns written, in the order the writer uses.
    fn defined(&self) -> impl Iterator<Item = &'static ColumnDef> + '_ {
        COLUMNS.iter().filter(|c| self.has(c.group))
    }

    /// The header names in the order the writer uses.
    pub fn names(&self) -> Vec<String> {
        self.defined().map(|c| c.name.to_string()).chain(self.extra.iter().cloned()).collect()
    }

    /// The columns a reader's file has (for copying a recording).
    pub fn of_reader<R>(r: &Reader<R>) -> Self {
        let any = |g: Group| COLUMNS.iter().zip(r.present).any(|(c, here)| here && c.group == g);
        Columns {
            reference: any(Group::Reference),
            chamber: any(Group::Chamber),
            pos: any(Group::Pos),
            power: any(Group::Power),
            extra: r.extra.clone(),
        }
    }
}

/// A streaming writer of recording format v1.
pub struct Writer<W: Write> {
    out: W,
    file: PathBuf,
    columns: Columns,
    line: Vec<u8>,
    line_no: u64,
    prev_t: Option<f64>,
    rows: u64,
    ryu: ryu::Buffer,
}

impl<W: Write> Writer<W> {
    /// Writes the comment lines (each prefixed `# `) and the header; `name` is the file named
    /// in errors.
    pub fn new(out: W, name: impl AsRef<Path>, columns: Columns, comments: &[&str]) -> Result<Self, Error> {
        let mut w = Writer {
            out,
            file: name.as_ref().to_path_buf(),
            columns,
            line: Vec::with_capacity(512),
            line_no: 0,
            prev_t: None,
            rows: 0,
            ryu: ryu::Buffer::new(),
        };
        for c in comments {
            if c.contains(['\n', '\r']) {
                return Err(w.err(None, ErrorKind::Unwritable(format!("comment with a line break: {c:?}"))));
            }
            w.line.clear();
            w.line.extend_from_slice(b"# ");
            w.line.extend_from_slice(c.as_bytes());
            w.line.push(b'\n');
            w.flush_line()?;
        }
        for (i, n) in w.columns.extra.iter().enumerate() {
            if n.is_empty() || column(n).is_some() || w.columns.extra[..i].contains(n) || n.contains(['\n', '\r']) {
                return Err(w.err(None, ErrorKind::Unwritable(format!("extra column name {n:?}"))));
            }
        }
        let names = w.columns.names();
        w.line.clear();
        for (i, n) in names.iter().enumerate() {
            if i > 0 {
                w.line.push(b',');
            }
            push_text(&mut w.line, n);
        }
        w.line.push(b'\n');
        w.flush_line()?;
        Ok(w)
    }

    fn err(&self, column: Option<&str>, kind: ErrorKind) -> Error {
        let column = column.map(|c| {
            let pos = self.columns.names().iter().position(|n| n == c).map_or(0, |p| p + 1);
            (pos, c.to_string())
        });
        Error { file: self.file.clone(), line: self.line_no + 1, column, kind }
    }

    fn flush_line(&mut self) -> Result<(), Error> {
        if let Err(e) = self.out.write_all(&self.line) {
            return Err(self.err(None, ErrorKind::Io(e.to_string())));
        }
        self.line_no += 1;
        Ok(())
    }

    fn num(&mut self, c: &ColumnDef, v: f64) -> Result<(), Error> {
        if !v.is_finite() {
            return Err(self.err(Some(c.name), ErrorKind::Unwritable(format!("non-finite value {v}"))));
        }
        if let Some(limit) = c.limit
            && !limit.contains(v)
        {
            return Err(self.err(Some(c.name), ErrorKind::OutOfRange { value: v.to_string(), limit }));
        }
        self.line.extend_from_slice(self.ryu.format_finite(v).as_bytes());
        Ok(())
    }

    fn opt(&mut self, c: &ColumnDef, v: Option<f64>) -> Result<(), Error> {
        match v {
            Some(v) => self.num(c, v),
            None => Ok(()),
        }
    }

    /// Appends one row. Columns not in use are ignored; `None` is written as an empty cell.
    pub fn write_row(&mut self, row: &Row) -> Result<(), Error> {
        if !row.t_s.is_finite() {
            return Err(self.err(Some(col::T_S), ErrorKind::Unwritable(format!("non-finite time {}", row.t_s))));
        }
        if let Some(prev) = self.prev_t
            && !(row.t_s > prev)
        {
            return Err(self.err(Some(col::T_S), ErrorKind::TimeNotIncreasing { previous: prev, this: row.t_s }));
        }
        self.line.clear();
        for c in &COLUMNS {
            if !self.columns.has(c.group) {
                continue;
            }
            if c.field != Field::T {
                self.line.push(b',');
            }
            match c.field {
                Field::T => self.num(c, row.t_s)?,
                Field::U(i) => self.num(c, row.u_v[i])?,
                Field::Temp => self.num(c, row.temp_c)?,
                Field::F(i) => self.opt(c, row.f_g[i])?,
                Field::VibKind => {
                    if let Some(k) = row.vib_kind {
                        self.line.extend_from_slice(k.as_str().as_bytes());
                    }
                }
                Field::Vib(i) => self.opt(c, row.vib_g[i])?,
                Field::VibHz => self.opt(c, row.vib_hz)?,
                Field::VibBw => self.opt(c, row.vib_bw_hz)?,
                Field::Chamber => self.opt(c, row.chamber_c)?,
                Field::Pos => {
                    if let Some(p) = &row.pos {
                        if p.contains(['\n', '\r']) {
                            return Err(self
                                .err(Some(col::POS), ErrorKind::Unwritable(format!("cell with a line break: {p:?}"))));
                        }
                        push_text(&mut self.line, p);
                    }
                }
                Field::Power => self.opt(c, row.power_s)?,
            }
        }
        for i in 0..self.columns.extra.len() {
            self.line.push(b',');
            let cell = row.extra.get(i).map_or("", String::as_str);
            if cell.contains(['\n', '\r']) {
                let name = self.columns.extra[i].clone();
                let pos = self.columns.names().iter().position(|n| *n == name).map_or(0, |p| p + 1);
                return Err(Error {
                    file: self.file.clone(),
                    line: self.line_no + 1,
                    column: Some((pos, name)),
                    kind: ErrorKind::Unwritable(format!("cell with a line break: {cell:?}")),
                });
            }
            push_text(&mut self.line, cell);
        }
        self.line.push(b'\n');
        self.flush_line()?;
        self.prev_t = Some(row.t_s);
        self.rows += 1;
        Ok(())
    }

    /// Rows written so far.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Flushes and returns the underlying writer.
    pub fn finish(mut self) -> Result<W, Error> {
        if let Err(e) = self.out.flush() {
            return Err(self.err(None, ErrorKind::Io(e.to_string())));
        }
        Ok(self.out)
    }
}

/// A text cell, quoted when it holds a comma, a quote or surrounding spaces.
fn push_text(line: &mut Vec<u8>, s: &str) {
    if s.contains([',', '"']) || s.starts_with([' ', '\t']) || s.ends_with([' ', '\t']) {
        line.push(b'"');
        for b in s.bytes() {
            if b == b'"' {
                line.push(b'"');
            }
            line.push(b);
        }
        line.push(b'"');
    } else {
        line.extend_from_slice(s.as_bytes());
    }
}

/// A small CSV table that is not a recording (a constants table, a coefficient table, a
/// replay's output), read by the same path as recordings (the `csv` crate fed line by line,
/// the same caps): `#` comment lines and blank lines are skipped, the first other line is the
/// header, every further line a row with as many cells as the header. Columns are found by
/// header name; errors name the file, the line and the column.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// The file named in errors.
    pub file: PathBuf,
    /// The header names in file order.
    pub header: Vec<String>,
    /// The rows: line number (1-based) and cells (trimmed, unquoted).
    pub rows: Vec<(u64, Vec<String>)>,
}

impl Table {
    /// Reads the table in the file `path`.
    pub fn read(path: &Path) -> Result<Table, Error> {
        let f = File::open(path).map_err(|e| io_error(path, e))?;
        Table::from_reader(BufReader::new(f), path)
    }

    /// Reads a table from `src`; `name` is the file named in errors.
    pub fn from_reader(src: impl BufRead, name: impl AsRef<Path>) -> Result<Table, Error> {
        let mut rows = Vec::new();
        let mut t = Table::for_each_row(src, name, |_, line, cells| {
            rows.push((line, cells.iter().map(|c| c.to_string()).collect()));
            Ok::<(), Error>(())
        })?;
        t.rows = rows;
        Ok(t)
    }

    /// Reads a table from `src` one row at a time (for tables too long to hold as strings):
    /// `each(table, line, cells)` is called for every row with the table's header (and no
    /// rows); returns the table without rows. `name` is the file named in errors.
    pub fn for_each_row<E: From<Error>>(
        src: impl BufRead,
        name: impl AsRef<Path>,
        mut each: impl FnMut(&Table, u64, &[&str]) -> Result<(), E>,
    ) -> Result<Table, E> {
        let mut t = Table { file: name.as_ref().to_path_buf(), header: Vec::new(), rows: Vec::new() };
        let mut csv = csv_reader(Lines::new(src, Blank::Skip));
        let mut record = csv::ByteRecord::new();
        let mut header = true;
        loop {
            let more = read_record(&mut csv, &mut record).map_err(|(line, kind)| Error {
                file: t.file.clone(),
                line,
                column: None,
                kind,
            })?;
            if !more {
                break;
            }
            // The `csv` crate is given one line at a time: the line the source read last is
            // the row's.
            let line_no = csv.get_ref().line_no;
            let cells: Vec<&str> = (0..record.len()).map(|i| cell_text(&record, i)).collect();
            if header {
                t.header = cells.iter().map(|c| c.to_string()).collect();
                header = false;
            } else if cells.len() != t.header.len() {
                let kind = ErrorKind::CellCount { expected: t.header.len(), got: cells.len() };
                return Err(Error { file: t.file, line: line_no, column: None, kind }.into());
            } else {
                each(&t, line_no, &cells)?;
            }
        }
        if header {
            return Err(Error { file: t.file, line: 0, column: None, kind: ErrorKind::NoHeader }.into());
        }
        Ok(t)
    }

    /// The position of column `name` in the header.
    pub fn column(&self, name: &str) -> Result<usize, Error> {
        self.header.iter().position(|h| h == name).ok_or_else(|| Error {
            file: self.file.clone(),
            line: 0,
            column: None,
            kind: ErrorKind::NoColumn(name.to_string()),
        })
    }

    /// An error at `line` in column position `col`.
    pub fn error(&self, line: u64, col: usize, kind: ErrorKind) -> Error {
        let column = Some((col + 1, self.header.get(col).cloned().unwrap_or_default()));
        Error { file: self.file.clone(), line, column, kind }
    }

    /// The finite number in column `col` of the row at `line` with `cells`.
    pub fn number(&self, line: u64, cells: &[String], col: usize) -> Result<f64, Error> {
        let cell = cells.get(col).map_or("", String::as_str);
        match cell.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.error(line, col, ErrorKind::NotANumber(cell.to_string()))),
        }
    }
}

/// Reads a whole recording into memory (for small files and tests); errors as [`Reader`].
pub fn read_all(path: &Path) -> Result<(Vec<String>, Vec<Row>), Error> {
    let mut r = Reader::open(path)?;
    let comments = r.comments().to_vec();
    let rows = r.by_ref().collect::<Result<Vec<_>, _>>()?;
    Ok((comments, rows))
}

/// Converts an I/O error into a recording error naming `file`.
pub fn io_error(file: &Path, e: io::Error) -> Error {
    Error { file: file.to_path_buf(), line: 0, column: None, kind: ErrorKind::Io(e.to_string()) }
}
